r"""Exactly solvable pieces of a Hamiltonian: $H = \sum_k H_k$ where each flow
$\varphi^{[k]}_t$ is known in closed form (the pieces a splitting method composes)."""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_state
from ._base import AbstractPoissonSystem


class AbstractExactTerm(abc.ABC):
    r"""A piece $H_k$ of a splitting $H = \sum_k H_k$ whose flow $\varphi^{[k]}_t$ is known
    exactly: `value(system, y)` $= H_k(y)$ and `flow(system, t, y)` $= \varphi^{[k]}_t(y)$,
    both batched over leading axes and traceable. The flow must be the exact Hamiltonian flow
    of $H_k$ for the system's bracket (so it is Poisson and conserves the Casimirs).

    Final kinds: `CollectiveTerm` (functions of Poisson-commuting linear forms, solved by a
    frozen test flow) and `FreeRigidBodyTerm` (Euler's equations, solved by Jacobi elliptic
    functions).
    """

    name: str

    @abc.abstractmethod
    def value(self, system: AbstractPoissonSystem, y: ArrayLike) -> jax.Array:
        """$H_k(y)$, shape `(...)`."""

    @abc.abstractmethod
    def flow(self, system: AbstractPoissonSystem, t: ArrayLike, y: ArrayLike) -> jax.Array:
        """The exact flow of $H_k$ for time `t`, shape of `y`."""

    def lifted_flow(self, system: AbstractPoissonSystem, t: ArrayLike,
                    gy: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
        r"""The exact flow of $H_k$ on configuration and momentum, $(g, \mu)$ = `gy`
        (reconstruction $\dot g = g\,\nabla H_k$). Pieces whose body velocity changes along
        their flow have no such closed form here: `ValueError`."""
        raise ValueError(
            f"the piece {self!r} has no exact reconstruction of the configuration in this library (its body velocity "
            "changes along its flow); use pieces that are CollectiveTerms without Casimirs"
        )


class CollectiveTerm(AbstractExactTerm):
    r"""A piece $H_k(y) = \varphi(L y, C(y))$ of a Hamiltonian, with linear forms $L$ (rows)
    that Poisson-commute, $L_i^\top \mathbb{B}(y) L_j = 0$, and optionally the Casimirs $C$.

    Every $L_i y$ and every Casimir is conserved by the flow of $H_k$, so the flow is the test
    flow with the frozen parameter $\alpha = L^\top\partial_s\varphi(L y, C(y))$ (the Casimir
    gradients are in the kernel of $\mathbb{B}$): exact, Poisson, Casimir-preserving. This is
    also the structure of a G-LPNet module (a function of $\langle\alpha, y\rangle$).

    **Arguments:** `forms` `(m, dim)`; `function(s)` or, with `uses_casimirs=True`,
    `function(s, c)`, written on the lists of components `s[0..m-1]` and `c[0..k-1]`.
    """

    def __init__(
        self,
        forms: Any,
        function: Callable[..., Any],
        name: str = "",
        *,
        uses_casimirs: bool = False,
    ):
        forms = np.atleast_2d(np.asarray(forms, dtype=np.float64))
        if forms.ndim != 2:
            raise ValueError(f"forms must be a matrix (m, dim); got shape {forms.shape}")
        self.forms = forms
        self.function = function
        self.name = name
        self.uses_casimirs = bool(uses_casimirs)

    def __repr__(self) -> str:
        return f"CollectiveTerm({self.name or self.forms.tolist()})"

    def _call(self, s: jax.Array, c: jax.Array | None) -> jax.Array:
        sl = [s[..., i] for i in range(s.shape[-1])]
        if self.uses_casimirs:
            return self.function(sl, [c[..., j] for j in range(c.shape[-1])])
        return self.function(sl)

    def _arguments(self, system: AbstractPoissonSystem, y: jax.Array):
        s = jnp.einsum("md,...d->...m", jnp.asarray(self.forms), y)
        c = system.casimirs(y) if self.uses_casimirs else None
        return s, c

    def value(self, system: AbstractPoissonSystem, y: ArrayLike) -> jax.Array:
        """$H_k(y)$."""
        y = as_state(y, "y", system.dim)
        s, c = self._arguments(system, y)
        return jnp.broadcast_to(self._call(s, c), y.shape[:-1])

    def frozen_alpha(self, system: AbstractPoissonSystem, y: jax.Array) -> jax.Array:
        r"""$\alpha = L^\top\partial_s\varphi$, constant along the flow of this term."""
        s, c = self._arguments(system, y)
        g = jax.grad(lambda z: jnp.sum(self._call(z, c)))(s)
        return jnp.einsum("md,...m->...d", jnp.asarray(self.forms), g)

    def flow(self, system: AbstractPoissonSystem, t: ArrayLike, y: ArrayLike) -> jax.Array:
        """Exact flow of this term for time `t`."""
        y = as_state(y, "y", system.dim)
        return system.test_flow(self.frozen_alpha(system, y), t, y)

    def lifted_flow(self, system, t, gy):
        r"""$(g\exp(t\alpha), \mathrm{Ad}^*_{\exp(t\alpha)}\mu)$ with $\alpha$ frozen: the body
        velocity $\nabla H_k = L^\top\partial_s\varphi$ is constant along the flow, so the
        reconstruction is exact. A piece that uses the Casimirs is refused: its body velocity
        has a part along their gradients, which move."""
        if self.uses_casimirs:
            return super().lifted_flow(system, t, gy)
        g, y = gy
        y = as_state(y, "y", system.dim)
        return system.lifted_test_flow(self.frozen_alpha(system, y), t, g, y)
