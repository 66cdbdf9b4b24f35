r"""A network plus a fixed affine map, $N(y) = c + By + \tilde N(y)$, the affine part the
least-squares fit of the data (`learn.PlusAffine`)."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._networks import AbstractNetwork, AbstractWrappedNetwork


def _affine_part(value: Any, shape: tuple[int, ...], name: str) -> tuple:
    """`value` as nested tuples of finite floats of `shape` (`None`: zeros)."""
    if value is None:
        value = np.zeros(shape)
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be numbers of shape {shape}; got {value!r}") from err
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}; got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite; got {value!r}")
    return tuple(map(tuple, array.tolist())) if len(shape) > 1 else tuple(array.tolist())


class PlusAffine(AbstractWrappedNetwork):
    r"""$N(y) = c + By + \tilde N(y)$: the network $\tilde N$ plus an affine map that is never
    trained (Python floats, compiled in as constants, like `learn.AffineMLP`'s scalings).

    `rescaled(inputs, outputs)` (what `learn.fit(normalise=True)` calls) sets $c, B$ to the
    least-squares affine fit of the samples' outputs on their inputs and scales $\tilde N$ to
    the residuals. Where the outputs are nearly affine in the inputs (an LPNet's
    $\alpha(y) \approx h\nabla H(y)$ for a quadratic $H$: E5's Kirchhoff equations), $\tilde N$
    then learns only the nonlinear rest; a deep sigmoid MLP fits an affine map itself only
    slowly (benchmarks,
    [E5: the affine part fixed][e5-the-affine-part-fixed-issue-29-benchmarksaffine_partpy]). The
    trained weights are $\tilde N$'s alone.

    **Arguments:** `network` $\tilde N$ (any `learn.AbstractNetwork` that is not averaged over
    a group: put `PlusAffine` inside `learn.GroupAveraged`, which then averages the sum);
    `shift` $c$ `(out_size,)` and `linear` $B$ `(out_size, in_size)` (`None`: zeros, the
    network unchanged until rescaled).
    """

    network: AbstractNetwork
    shift: tuple[float, ...]
    linear: tuple[tuple[float, ...], ...]

    def __init__(self, network: AbstractNetwork, shift: Any = None, linear: Any = None):
        if not isinstance(network, AbstractNetwork):
            raise TypeError(f"network must be a learn.AbstractNetwork (e.g. learn.AffineMLP); got {type(network).__name__}")
        if network.sign_groups():
            raise ValueError(
                "PlusAffine around a group-averaged network would break its equivariance (the affine part is not "
                "averaged); wrap the other way round: learn.GroupAveraged(learn.PlusAffine(network), group)"
            )
        self.network = network
        self.shift = _affine_part(shift, (network.out_size,), "PlusAffine.shift")
        self.linear = _affine_part(linear, (network.out_size, network.in_size), "PlusAffine.linear")

    def __call__(self, y: jax.Array) -> jax.Array:
        return jnp.asarray(self.shift) + jnp.asarray(self.linear) @ y + self.network(y)

    def spec(self) -> dict[str, Any]:
        return {"kind": "PlusAffine", "shift": list(self.shift), "linear": [list(r) for r in self.linear],
                "network": self.network.spec()}

    def reinitialised(self, key: int | jax.Array) -> PlusAffine:
        return PlusAffine(self.network.reinitialised(key), self.shift, self.linear)

    def rescaled(self, inputs: np.ndarray, outputs: np.ndarray) -> PlusAffine:
        r"""$c, B$ the least-squares fit of `outputs` on `inputs` (minimum norm where the inputs
        do not determine it, e.g. a constant component), and $\tilde N$ rescaled to the
        residuals."""
        x = np.asarray(inputs, dtype=np.float64).reshape(-1, self.in_size)
        t = np.asarray(outputs, dtype=np.float64).reshape(-1, self.out_size)
        if x.shape[0] != t.shape[0] or x.shape[0] == 0:
            raise ValueError(f"rescaled needs as many inputs as outputs, at least one; got {x.shape[0]} and {t.shape[0]}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(t))):
            raise ValueError("the training data give non-finite scalings")
        # centred, so that the shift does not compete with B in the conditioning
        mean_x, mean_t = x.mean(axis=0), t.mean(axis=0)
        coefficients = np.linalg.lstsq(x - mean_x, t - mean_t, rcond=None)[0]  # (in, out)
        linear = coefficients.T
        shift = mean_t - linear @ mean_x
        residuals = t - (shift + x @ coefficients)
        return eqx.tree_at(lambda n: (n.network, n.shift, n.linear), self,
                           (self.network.rescaled(x, residuals), tuple(shift.tolist()),
                            tuple(map(tuple, linear.tolist()))))
