r"""What every Lie algebra of the library is: the bracket, the Lie-Poisson structure on
$\mathfrak g^*$, Casimirs and the exact coadjoint flows of linear Hamiltonians.

Two kinds implement it: `LieAlgebra`, given by structure constants $C_{abd}$ (any small
algebra), and `MatrixLieAlgebra`, a matrix algebra whose operations are matrix products and
never form a structure-constant tensor (so(N), u(N), ... of any size). Conventions
([the conventions page][conventions]): $\mathbb{B}(\mu)\,\xi = -\mathrm{sign}\cdot
\mathrm{ad}^*_\xi\mu$, body systems `sign = -1`; the test flow of $\langle\alpha, \mu\rangle$ is
the coadjoint action of $\exp(t\alpha)$.
"""

from __future__ import annotations

import abc
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._inverse import checked_flow_parameters
from ._validation import as_scalar_time, as_state, broadcast_batch, pinv_apply


class AbstractLieAlgebra(abc.ABC):
    r"""A real Lie algebra $\mathfrak g$ of dimension `dim` with a basis $e_1, \dots, e_n$, and
    the Lie-Poisson structure on $\mathfrak g^*$ (states $\mu$ in the dual basis).

    Subclasses define the bracket, $\mathrm{ad}^*$, the Casimirs and the body-convention flow
    `_coadjoint_flow`; validation, the sign convention, the overflow check and the inverse
    of the flow are shared here.
    """

    name: str
    basis_names: tuple[str, ...]
    sign: int

    # -- what an algebra defines -------------------------------------------------------------
    @property
    @abc.abstractmethod
    def dim(self) -> int:
        """The dimension $n$ of $\\mathfrak g$."""

    @property
    @abc.abstractmethod
    def structure_constants(self) -> np.ndarray:
        """$C_{abd}$ with $[e_a, e_b] = C_{abd} e_d$ (read-only); a `ValueError` for an algebra
        too large to hold them."""

    @abc.abstractmethod
    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        r"""$[\xi, \eta]$, batched over leading axes."""

    @abc.abstractmethod
    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        r"""$(\mathrm{ad}^*_\xi\mu)_b = \langle \mu, [\xi, e_b]\rangle$, batched."""

    @abc.abstractmethod
    def poisson_tensor(self, mu: ArrayLike) -> jax.Array:
        r"""$\mathbb{B}(\mu)_{ab} = \mathrm{sign}\cdot\langle\mu, [e_a, e_b]\rangle$, `(..., n, n)`."""

    @abc.abstractmethod
    def casimirs(self, mu: ArrayLike) -> jax.Array:
        """Values of the independent Casimirs, shape `(..., k)`."""

    @abc.abstractmethod
    def casimir_gradients(self, mu: ArrayLike) -> jax.Array:
        """Gradients $\\partial C_j/\\partial\\mu$, shape `(..., k, n)`."""

    @property
    @abc.abstractmethod
    def n_casimirs(self) -> int:
        """The number $k$ of independent Casimirs."""

    @abc.abstractmethod
    def definition(self) -> dict[str, Any]:
        """Everything that defines the algebra, as JSON values (`liepoisson.algebra_from_definition`
        inverts it)."""

    @abc.abstractmethod
    def _coadjoint_flow(self, alpha: jax.Array, t: jax.Array, mu: jax.Array) -> jax.Array:
        r"""$\mu(t)$ with $\dot\mu = \mathrm{ad}^*_\alpha\mu$ (body convention), for inputs
        validated and broadcast: `alpha`, `mu` `(..., n)`, `t` `(...)`."""

    @abc.abstractmethod
    def _flow_parameters(self, mu0: jax.Array, mu1: jax.Array, t: jax.Array,
                         casimir_gradients: jax.Array) -> jax.Array:
        r"""The inverse of `_coadjoint_flow` (body convention) on validated pairs `(N, n)`,
        orthogonal to `casimir_gradients` `(N, k, n)`."""

    # -- derived -------------------------------------------------------------------------------
    def poisson_action(self, mu: ArrayLike, xi: ArrayLike) -> jax.Array:
        r"""$\mathbb B(\mu)\,\xi$, the Lie-Poisson velocity $\dot\mu$ for $\partial H/\partial\mu = \xi$."""
        mu = as_state(mu, "mu", self.dim)
        xi = as_state(xi, "xi", self.dim)
        return jnp.einsum("...ab,...b->...a", self.poisson_tensor(mu), xi)

    def poisson_lstsq(self, mu: ArrayLike, v: ArrayLike, rcond: float = 1e-15) -> np.ndarray:
        r"""The minimum-norm least-squares $\xi$ of $\mathbb B(\mu)\,\xi = v$, `(..., n)`
        (NumPy): $\mathbb B(\mu)^+ v$, singular values below `rcond` times the largest
        dropped. Here from the dense tensor; matrix algebras whose elements are normal
        matrices solve it in the eigenbasis of $\mu$ instead, without forming it."""
        mu = np.asarray(as_state(mu, "mu", self.dim))
        v = np.asarray(as_state(v, "v", self.dim))
        return pinv_apply(self.poisson_tensor(mu), v, rcond)

    def poisson_tensor_components(self, mu: Any) -> list[list[Any]]:
        r"""$\mathbb{B}$ as nested lists of expressions in the components (any backend: numbers,
        JAX arrays, heyoka expressions), from the structure constants."""
        C = self.structure_constants
        n = self.dim
        out: list[list[Any]] = [[0.0] * n for _ in range(n)]
        for a, b, d in zip(*np.nonzero(C)):
            out[a][b] = out[a][b] + float(self.sign * C[a, b, d]) * mu[d]
        return out

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, dim={self.dim}, n_casimirs={self.n_casimirs})"

    def coadjoint_flow(self, alpha: ArrayLike, t: ArrayLike, mu: ArrayLike) -> jax.Array:
        r"""$\exp(t\,\mathbb{M}(\alpha))\,\mu$: exact flow of $H = \langle \alpha, \mu\rangle$.

        `alpha` and `mu` of shape `(..., n)` and `t` a scalar or array, broadcast against each
        other. Usable inside `jax.jit`, `jax.vmap` and `jax.grad`. This is the coadjoint action
        of $\exp(t\alpha)$; it is a Poisson map and conserves every Casimir.
        """
        return self._checked_flow(self._coadjoint_flow, "coadjoint_flow", alpha, t, mu)

    def coadjoint_increment(self, alpha: ArrayLike, t: ArrayLike, mu: ArrayLike) -> jax.Array:
        r"""$\exp(t\,\mathbb{M}(\alpha))\,\mu - \mu$: the change `coadjoint_flow` makes,
        without the cancellation of that difference where the algebra's flow has a closed form
        (so(3), se(3) and their direct sums: a rounding error of order
        $\epsilon\,|t\alpha|\,|\mu|$ instead of $\epsilon|\mu|$). Arguments as
        `coadjoint_flow`; what a compensated composition (`integrators.splitting.Compensated`)
        adds to the state it carries in two parts."""
        return self._checked_flow(self._coadjoint_increment, "coadjoint_increment", alpha, t, mu)

    def _coadjoint_increment(self, alpha: jax.Array, t: jax.Array, mu: jax.Array) -> jax.Array:
        """`_coadjoint_flow(alpha, t, mu) - mu` (algebras with a closed form override it)."""
        return self._coadjoint_flow(alpha, t, mu) - mu

    def _checked_flow(self, flow: Any, name: str, alpha: ArrayLike, t: ArrayLike, mu: ArrayLike) -> jax.Array:
        """`flow(alpha, t, mu)` (body convention) on validated, broadcast input, its time
        reversed for `sign = +1`; `FloatingPointError` for a concrete non-finite result."""
        alpha = as_state(alpha, "alpha", self.dim)
        mu = as_state(mu, "mu", self.dim)
        t = as_scalar_time(t)
        batch = broadcast_batch(self.dim, alpha=alpha.shape[:-1], mu=mu.shape[:-1], t=t.shape)
        alpha = jnp.broadcast_to(alpha, batch + (self.dim,))
        mu = jnp.broadcast_to(mu, batch + (self.dim,))
        # The flows are written for sign = -1; sign = +1 reverses time.
        t = jnp.broadcast_to(-self.sign * t, batch)
        out = flow(alpha, t, mu)
        if not isinstance(out, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(out))):
            # Finite inputs (checked above), non-finite result: exp(t M(alpha)) overflowed, which
            # happens on non-compact algebras, where the flow grows like exp(|t alpha|).
            k = np.unravel_index(int(np.argmax(~np.isfinite(np.asarray(out)).any(axis=-1))), batch) if batch else ()
            size = float(np.abs(np.asarray(t)[k]) * np.linalg.norm(np.asarray(alpha)[k]))
            raise FloatingPointError(
                f"{name} overflowed at batch index {tuple(int(i) for i in k)}: |t| |alpha| = {size:.3g}; "
                f"exp(t M(alpha)) on {self.name} grows like exp(|t alpha|) and exceeds float64. "
                "Use smaller alpha or t (a learned map far outside its training data produces such alpha)"
            )
        return out

    def coadjoint_flow_parameters(
        self, mu0: ArrayLike, mu1: ArrayLike, t: ArrayLike, *, rtol: float = 1e-10, names: tuple[str, str] = ("mu0", "mu1")
    ) -> np.ndarray:
        r"""The parameters $\alpha$ with `coadjoint_flow(alpha, t, mu0) == mu1`, orthogonal to
        the Casimir gradients at `mu0` ([the paper](https://arxiv.org/abs/2308.15349), Sec. 4,
        eqs. (25) and (26)).

        The inverse of the exact flow is the algebra's own: the shortest rotation in closed
        form for so(3) (`RodriguesFlow`), Gauss-Newton otherwise.

        **Arguments:** `mu0`, `mu1` of shape `(..., n)`; `t` a finite, non-zero scalar;
        `rtol`: the relative Casimir mismatch beyond which a pair is rejected, and
        (times 100, relative to the size of the states) the largest residual accepted;
        `names`: how error messages call the two states.

        **Returns:** `alpha`, `(..., n)`. Raises `ValueError` naming the pair (its index over
        the flattened leading axes) when a Casimir differs between `mu0` and `mu1`, when the
        solution is not unique (antiparallel so(3) pair) or when no solution is found.
        """
        return checked_flow_parameters(
            mu0,
            mu1,
            t,
            rtol,
            dim=self.dim,
            names=names,
            flow=self.coadjoint_flow,
            casimirs=self.casimirs,
            casimir_gradients=self.casimir_gradients,
            # The exact flows are written for sign = -1; sign = +1 reverses time.
            solve=lambda a, b, t, G: self._flow_parameters(a, b, -self.sign * t, G),
        )

    def orbit_dimension(self, mu: ArrayLike, rtol: float = 1e-10) -> int | np.ndarray:
        r"""Dimension of the coadjoint orbit through $\mu$: $\operatorname{rank}\mathbb{B}(\mu)$."""
        B = np.asarray(self.poisson_tensor(mu))
        s = np.linalg.svd(B, compute_uv=False)
        scale = max(1.0, float(np.max(np.abs(np.asarray(mu)))))
        rank = np.sum(s > rtol * scale * self._bracket_scale(), axis=-1)
        return int(rank) if np.ndim(rank) == 0 else rank

    def _bracket_scale(self) -> float:
        """The size of the bracket on unit vectors (rank thresholds are relative to it)."""
        return 1.0
