r"""Networks: the learnable functions inside a learned map, $y \mapsto N(y)$ for one sample
(an LPNet's $\alpha(y)$, the baseline's increment). A wrapper changes the function, never a
flag (`learn.GroupAveraged` makes any network equivariant)."""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
import jax
import numpy as np


class AbstractNetwork(eqx.Module):
    """A network $N: \\mathbb R^{n_\\text{in}} \\to \\mathbb R^{n_\\text{out}}$ on one sample;
    batch with `jax.vmap`. Final kinds: `learn.AffineMLP` and the wrappers
    `learn.GroupAveraged` and `learn.PlusAffine`."""

    @property
    @abc.abstractmethod
    def in_size(self) -> int: ...

    @property
    @abc.abstractmethod
    def out_size(self) -> int: ...

    @abc.abstractmethod
    def __call__(self, y: jax.Array) -> jax.Array:
        """$N(y)$ for one sample `(in_size,)`; returns `(out_size,)`."""

    @abc.abstractmethod
    def spec(self) -> dict[str, Any]:
        """The architecture as JSON values, with its `kind`: `network_from_spec(spec, key)`
        rebuilds it with fresh weights (model files store this)."""

    @abc.abstractmethod
    def rescaled(self, inputs: np.ndarray, outputs: np.ndarray) -> AbstractNetwork:
        """The same weights with the fixed input/output scalings set to the mean/std of the
        samples `inputs` `(N, in_size)` and `outputs` `(N, out_size)`."""


    @abc.abstractmethod
    def reinitialised(self, key: int | jax.Array) -> AbstractNetwork:
        """The same architecture and fixed scalings with fresh weights from `key`."""

    def sign_groups(self) -> tuple[tuple[tuple[float, ...], ...], ...]:
        """The groups of sign flips this network is averaged over (by `learn.GroupAveraged`
        wrappers at any depth), which a map built on it must check; none by default."""
        return ()

    def output_scales(self) -> tuple[float, ...]:
        """The fixed scales of the outputs (units of an output-space loss); ones by default."""
        return (1.0,) * self.out_size


class AbstractWrappedNetwork(AbstractNetwork):
    """A network that wraps another, `network`, and changes its function (as diffrax's
    wrapped solvers do): sizes, output scales, rescaling and the sign groups to check are
    delegated to it; a final wrapper defines `__call__`, `spec` and `reinitialised`."""

    network: eqx.AbstractVar[AbstractNetwork]

    @property
    def in_size(self) -> int:
        return self.network.in_size

    @property
    def out_size(self) -> int:
        return self.network.out_size

    def output_scales(self) -> tuple[float, ...]:
        return self.network.output_scales()

    def sign_groups(self) -> tuple[tuple[tuple[float, ...], ...], ...]:
        return self.network.sign_groups()

    def rescaled(self, inputs: np.ndarray, outputs: np.ndarray) -> AbstractWrappedNetwork:
        return eqx.tree_at(lambda n: n.network, self, self.network.rescaled(inputs, outputs))


def network_or_default(network: Any, default: Any, name: str = "network", **arguments: Any) -> Any:
    """`network` if given, and then none of `arguments` (the default part's: hidden layers,
    activation, key, scalings) may be; else `default(**arguments)` with the unset ones left to
    its defaults. A combination that would ignore an argument is refused (`name` is the
    argument that gives the part whole: `network`, `terms`)."""
    given = {k: v for k, v in arguments.items() if v is not None}
    if network is None:
        return default(**given)
    if given:
        raise ValueError(f"{', '.join(sorted(given))}: these describe the default {name}; with {name}= given, "
                         f"set them on that {name} instead")
    return network


def check_network(network: Any, in_size: int, out_size: int, what: str) -> AbstractNetwork:
    """`network` if it is an `AbstractNetwork` from `in_size` to `out_size`; `TypeError` or
    `ValueError` saying what it must map (`what`) otherwise."""
    if not isinstance(network, AbstractNetwork):
        raise TypeError(f"network must be a learn.AbstractNetwork (AffineMLP, GroupAveraged, PlusAffine); got {network!r}")
    if (network.in_size, network.out_size) != (in_size, out_size):
        raise ValueError(f"network must map {what} ({in_size} to {out_size}); got in_size={network.in_size}, "
                         f"out_size={network.out_size}")
    return network
