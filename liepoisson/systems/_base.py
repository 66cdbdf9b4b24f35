r"""Abstract Poisson systems: a state space with a Poisson tensor, a Hamiltonian, Casimirs and
the exact flows of linear test Hamiltonians $H = \langle\alpha, y\rangle$."""

from __future__ import annotations

import abc
import functools
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._algebra import LieAlgebra
from .._casimir_values import casimir_gradient_values, casimir_values
from .._groups import AbstractLieGroup, default_group
from .._inverse import checked_flow_parameters, gauss_newton_parameters
from .._namespace import HEYOKA, JAX
from .._polynomial import Polynomial
from .._validation import as_scalar_time, as_state, broadcast_batch, pinv_apply

if TYPE_CHECKING:
    from ._terms import CollectiveTerm


class AbstractPoissonSystem(abc.ABC):
    r"""A Poisson system $\dot y = \mathbb{B}(y)\,\nabla H(y)$ whose linear test Hamiltonians
    $H_\alpha = \langle\alpha, y\rangle$ have exact, explicitly computable flows.

    Subclasses define, once, the Hamiltonian and the Poisson tensor on the components of the
    state against a math namespace `xp` (numpy, JAX or heyoka), the Casimir polynomials, and
    `test_flow`. Everything else (vectorisation, gradients, the heyoka right-hand side) is
    derived here.
    """

    name: str
    dim: int

    # -- what a system defines ----------------------------------------------------------
    @property
    @abc.abstractmethod
    def params(self) -> dict[str, Any]:
        """Parameters as JSON-serialisable values (stored in data files)."""

    @abc.abstractmethod
    def hamiltonian_components(self, y: Sequence[Any], xp: Any) -> Any:
        """$H$ as an expression in the components `y[0], ..., y[dim-1]`."""

    @abc.abstractmethod
    def poisson_tensor_components(self, y: Sequence[Any]) -> list[list[Any]]:
        """$\\mathbb{B}(y)$ as nested lists of expressions in the components."""

    @property
    @abc.abstractmethod
    def casimir_polynomials(self) -> tuple[Polynomial, ...]:
        """A functionally independent set of (polynomial) Casimirs; may be empty."""

    @abc.abstractmethod
    def _test_flow(self, alpha: jax.Array, t: jax.Array, y: jax.Array) -> jax.Array:
        """Exact flow of $\\langle\\alpha, y\\rangle$; inputs validated and broadcast."""

    @abc.abstractmethod
    def hamiltonian_splitting(self) -> tuple[CollectiveTerm, ...]:
        """$H = \\sum_k H_k$ with exactly solvable pieces (used by classical splitting)."""

    # -- derived ------------------------------------------------------------------------
    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"y{i + 1}" for i in range(self.dim))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{type(self).__name__}({args})"

    def value_key(self) -> tuple[Any, ...] | None:
        """What the system is, as a hashable value (equal systems: `==`, same hash), or `None`:
        equal only to itself. `None` here, for a system of your own whose params may leave
        something out; a system its name and params define completely is an
        `AbstractDefinedByParams`."""
        return None

    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        if not isinstance(other, AbstractPoissonSystem):
            return NotImplemented
        key = self.value_key()
        return key is not None and key == other.value_key()

    def __hash__(self) -> int:
        key = self.value_key()
        return hash(key) if key is not None else id(self)

    def _components(self, y: jax.Array) -> list[jax.Array]:
        return [y[..., i] for i in range(self.dim)]

    def singular(self, y: jax.Array) -> jax.Array | None:
        """Where $H$ or $\\mathbb{B}$ is not defined (e.g. a potential $1/r$ at $r = 0$): a
        boolean array of shape `y.shape[:-1]`, or None for a system defined everywhere."""
        return None

    def check_regular(self, y: ArrayLike, name: str = "y") -> jax.Array:
        """`y` as a state, or a `ValueError` naming the first state of `y` in the singular set
        (only where `y` is concrete; inside `jit` nothing is checked)."""
        y = as_state(y, name, self.dim)
        if isinstance(y, jax.core.Tracer):
            return y
        bad = self.singular(y)
        if bad is not None and bool(np.any(np.asarray(bad))):
            index = tuple(int(i) for i in np.argwhere(np.atleast_1d(np.asarray(bad)))[0])[: y.ndim - 1]
            state = np.asarray(y)[index] if y.ndim > 1 else np.asarray(y)
            where = f"{name}[{', '.join(map(str, index))}]" if y.ndim > 1 else name
            raise ValueError(
                f"{where} = {state.tolist()} is a singular point of {self!r}: {self.singular_reason}; "
                "move it off that set"
            )
        return y

    #: What `singular` marks, for error messages.
    singular_reason: str = "the Hamiltonian or the Poisson tensor is not defined there"

    def hamiltonian(self, y: ArrayLike) -> jax.Array:
        """$H(y)$, shape `(...)` for `y` of shape `(..., dim)`."""
        y = self.check_regular(y)
        return jnp.broadcast_to(self.hamiltonian_components(self._components(y), JAX), y.shape[:-1])

    def hamiltonian_gradient(self, y: ArrayLike) -> jax.Array:
        """$\\nabla H(y)$, shape `(..., dim)` (JAX autodiff of the one formula)."""
        y = self.check_regular(y)
        return jax.grad(lambda z: jnp.sum(self.hamiltonian(z)))(y)

    def poisson_tensor(self, y: ArrayLike) -> jax.Array:
        """$\\mathbb{B}(y)$, shape `(..., dim, dim)`."""
        y = as_state(y, "y", self.dim)
        rows = self.poisson_tensor_components(self._components(y))
        batch = y.shape[:-1]
        return jnp.stack(
            [
                jnp.stack([jnp.broadcast_to(jnp.asarray(e, jnp.float64), batch) for e in r], -1)
                for r in rows
            ],
            -2,
        )

    def poisson_lstsq(self, y: ArrayLike, v: ArrayLike, rcond: float = 1e-15) -> np.ndarray:
        r"""The minimum-norm least-squares $\xi$ of $\mathbb B(y)\,\xi = v$, `(..., dim)`
        (NumPy; singular values below `rcond` times the largest dropped): the first-order
        estimate of a step's parameters (`learn`'s `params_estimate`)."""
        y = np.asarray(as_state(y, "y", self.dim))
        v = np.asarray(as_state(v, "v", self.dim))
        return pinv_apply(self.poisson_tensor(y), v, rcond)

    def vector_field(self, y: ArrayLike) -> jax.Array:
        """$\\dot y = \\mathbb{B}(y)\\,\\nabla H(y)$."""
        y = self.check_regular(y)
        return jnp.einsum("...ab,...b->...a", self.poisson_tensor(y), self.hamiltonian_gradient(y))

    def casimirs(self, y: ArrayLike) -> jax.Array:
        """Values of the Casimirs, shape `(..., k)` (`k` may be 0)."""
        return casimir_values(self.casimir_polynomials, as_state(y, "y", self.dim))

    def casimir_gradients(self, y: ArrayLike) -> jax.Array:
        """Gradients of the Casimirs, shape `(..., k, dim)`."""
        gradients = tuple(p.gradient() for p in self.casimir_polynomials)
        return casimir_gradient_values(gradients, as_state(y, "y", self.dim))

    @property
    def n_casimirs(self) -> int:
        return len(self.casimir_polynomials)

    def test_flow(self, alpha: ArrayLike, t: ArrayLike, y: ArrayLike) -> jax.Array:
        r"""Exact flow of the test Hamiltonian $H = \langle\alpha, y\rangle$ for time `t`.

        Batched over leading axes (broadcast), usable under `jit`, `vmap` and `grad`. For a
        fixed `alpha` this is a Poisson map and conserves every Casimir.
        """
        alpha = as_state(alpha, "alpha", self.dim)
        y = as_state(y, "y", self.dim)
        t = as_scalar_time(t)
        batch = broadcast_batch(self.dim, alpha=alpha.shape[:-1], y=y.shape[:-1], t=t.shape)
        return self._test_flow(
            jnp.broadcast_to(alpha, batch + (self.dim,)),
            jnp.broadcast_to(t, batch),
            jnp.broadcast_to(y, batch + (self.dim,)),
        )

    def test_flow_increment(self, alpha: ArrayLike, t: ArrayLike, y: ArrayLike) -> jax.Array:
        r"""`test_flow(alpha, t, y) - y`, the change the test flow makes, computed without
        the cancellation of that difference where the flow has a closed form (Lie-Poisson
        systems on so(3), se(3): `AbstractLieAlgebra.coadjoint_increment`); the difference
        itself otherwise. Arguments as `test_flow`. What a compensated composition
        (`integrators.splitting.Compensated`) adds to the state it carries in two parts."""
        alpha = as_state(alpha, "alpha", self.dim)
        y = as_state(y, "y", self.dim)
        t = as_scalar_time(t)
        batch = broadcast_batch(self.dim, alpha=alpha.shape[:-1], y=y.shape[:-1], t=t.shape)
        return self._test_flow_increment(
            jnp.broadcast_to(alpha, batch + (self.dim,)),
            jnp.broadcast_to(t, batch),
            jnp.broadcast_to(y, batch + (self.dim,)),
        )

    def _test_flow_increment(self, alpha: jax.Array, t: jax.Array, y: jax.Array) -> jax.Array:
        """`_test_flow(alpha, t, y) - y` (systems with a closed form override it)."""
        return self._test_flow(alpha, t, y) - y

    def test_flow_parameters(
        self, y0: ArrayLike, y1: ArrayLike, t: ArrayLike, *, rtol: float = 1e-10
    ) -> np.ndarray:
        r"""The parameters $\alpha$ with `test_flow(alpha, t, y0) == y1`, orthogonal to the
        Casimir gradients at `y0` ([the paper](https://arxiv.org/abs/2308.15349), Sec. 4,
        eqs. (25) and (26)).

        Gauss-Newton on `test_flow` (`liepoisson.gauss_newton_parameters`); Lie-Poisson
        systems use their algebra's exact flow and its closed forms instead.

        **Arguments:** `y0`, `y1` of shape `(..., dim)`; `t` a finite, non-zero scalar;
        `rtol`: the relative Casimir mismatch beyond which a pair is rejected, and (times 100,
        relative to the size of the states) the largest residual accepted.

        **Returns:** `alpha`, `(..., dim)`. Raises `ValueError` naming the pair (its index over
        the flattened leading axes) when a Casimir differs or no solution is found.
        """
        return checked_flow_parameters(
            y0,
            y1,
            t,
            rtol,
            dim=self.dim,
            names=("y0", "y1"),
            flow=self.test_flow,
            casimirs=self.casimirs,
            casimir_gradients=self.casimir_gradients,
            solve=functools.partial(gauss_newton_parameters, self.test_flow),
        )

    # -- heyoka ---------------------------------------------------------------------------
    def heyoka_system(self) -> list[tuple[Any, Any]]:
        """The ODE as heyoka `(variable, right-hand side)` pairs, $\\mathbb{B}(y)\\nabla H$,
        built symbolically from the same Hamiltonian and Poisson tensor."""
        import heyoka as hy

        names = [f"y{i}" for i in range(self.dim)]
        ys = list(hy.make_vars(*names)) if self.dim > 1 else [hy.make_vars(*names)]
        H = self.hamiltonian_components(ys, HEYOKA)
        grad = [hy.diff(H, v) for v in ys]
        return list(zip(ys, matvec(self.poisson_tensor_components(ys), grad)))


def matvec(B: list[list[Any]], v: list[Any]) -> list[Any]:
    """`B v` for a matrix of heyoka expressions (or numbers) and a vector of expressions,
    skipping the entries of `B` that are the number 0."""
    import heyoka as hy

    rhs = []
    for row in B:
        expr = 0.0
        for b, entry in enumerate(row):
            if isinstance(entry, (int, float)) and entry == 0:
                continue
            expr = expr + entry * v[b]
        rhs.append(hy.expression(0.0) if isinstance(expr, float) else expr)
    return rhs


def check_system(system: Any) -> AbstractPoissonSystem:
    """`system` if it is an `AbstractPoissonSystem`; `TypeError` naming what was given
    otherwise (defined here, beside the class, so that `liepoisson._validation`, which the
    systems import, does not import them back)."""
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(
            f"system must be a liepoisson.systems.AbstractPoissonSystem; got {type(system).__name__}"
        )
    return system


class AbstractDefinedByParams(AbstractPoissonSystem):
    """A system that its class, `name` and `params` define completely (the library's systems):
    two of the same class, name and params are equal (`==`, same hash), so that what was
    compiled for one (a JAX training loss, a heyoka integrator) serves the other, e.g. a copy
    unpickled on a Dask worker."""

    def value_key(self) -> tuple[Any, ...] | None:
        """`(class, name, params as JSON)`, computed once (a system does not change after
        construction)."""
        cached = self.__dict__.get("_value_key")
        if cached is None:
            cached = (type(self), self.name, json.dumps(self.params, sort_keys=True))
            self.__dict__["_value_key"] = cached
        return cached


class AbstractLiePoissonSystem(AbstractPoissonSystem):
    """A system on the dual of a Lie algebra: the bracket, Casimirs and test flows come from
    the algebra (coadjoint flows)."""

    algebra: Any

    @property
    def dim(self) -> int:  # type: ignore[override]
        return self.algebra.dim

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.algebra.basis_names

    def poisson_tensor_components(self, y):
        return self.algebra.poisson_tensor_components(y)

    @property
    def casimir_polynomials(self):
        polynomials = getattr(self.algebra, "casimir_polynomials", None)
        if polynomials is None:
            raise ValueError(f"{self.algebra!r} has no Casimir polynomials (its Casimirs are traces of matrix powers); "
                             "use casimirs(y) and casimir_gradients(y)")
        return polynomials

    def casimirs(self, y: ArrayLike) -> jax.Array:
        """The algebra's Casimirs at `y`, shape `(..., k)`."""
        return self.algebra.casimirs(as_state(y, "y", self.dim))

    def casimir_gradients(self, y: ArrayLike) -> jax.Array:
        """The algebra's Casimir gradients at `y`, shape `(..., k, dim)`."""
        return self.algebra.casimir_gradients(as_state(y, "y", self.dim))

    @property
    def n_casimirs(self) -> int:
        return self.algebra.n_casimirs

    def poisson_tensor(self, y: ArrayLike) -> jax.Array:
        """$\\mathbb{B}(y)$, shape `(..., dim, dim)`: from structure constants, entry by entry
        (only the nonzero constants: the program XLA runs, and its flop count, are those of
        the entries); from a matrix algebra, the algebra's."""
        if isinstance(self.algebra, LieAlgebra):
            return AbstractPoissonSystem.poisson_tensor(self, y)
        return self.algebra.poisson_tensor(as_state(y, "y", self.dim))

    def poisson_lstsq(self, y: ArrayLike, v: ArrayLike, rcond: float = 1e-15) -> np.ndarray:
        """The algebra's `poisson_lstsq` (matrix algebras: without forming $\\mathbb B$)."""
        return self.algebra.poisson_lstsq(as_state(y, "y", self.dim), as_state(v, "v", self.dim), rcond)

    def _test_flow(self, alpha, t, y):
        return self.algebra.coadjoint_flow(alpha, t, y)

    def _test_flow_increment(self, alpha, t, y):
        return self.algebra.coadjoint_increment(alpha, t, y)

    def vector_field(self, y: ArrayLike) -> jax.Array:
        r"""$\dot\mu = \mathbb B(\mu)\,\xi(\mu)$, $\xi$ = `generator` ($\nabla H$ unless damped)."""
        y = self.check_regular(y)
        if isinstance(self.algebra, LieAlgebra):  # B(mu) entry by entry, as `poisson_tensor`
            return jnp.einsum("...ab,...b->...a", self.poisson_tensor(y), self.generator(y))
        return self.algebra.poisson_action(y, self.generator(y))  # matrix products, no n x n tensor

    def generator(self, y: ArrayLike) -> jax.Array:
        r"""The element $\xi(\mu)$ of $\mathfrak g$ with $\dot\mu = \mathbb B(\mu)\,\xi(\mu)$:
        the velocity is the coadjoint motion it generates (`test_flow(xi, t, mu)` moves along
        it). $\nabla H$ for a Hamiltonian system; Lie-group integrators
        (`integrators.LieEuler`, ...) step with it frozen per stage."""
        return self.hamiltonian_gradient(y)

    def test_flow_parameters(self, y0, y1, t, *, rtol=1e-10):
        return self.algebra.coadjoint_flow_parameters(y0, y1, t, rtol=rtol, names=("y0", "y1"))

    def velocity_matrix(self, W: jax.Array) -> jax.Array:
        r"""On a matrix algebra: $B(W)$ with $\dot W = [B(W), W]$ for the matrix $W$ of the state,
        $-\Xi$, $\Xi$ the matrix of `generator` (so(N), u(N): $\dot W = [W, \Xi]$). Systems
        with a cheaper formula override it (`Zeitlin`: the stream matrix over $\hbar$)."""
        algebra = self.algebra
        return -algebra.matrix(self.generator(algebra.coordinates(W)))

    # -- configurations ---------------------------------------------------------------------
    @property
    def group(self) -> AbstractLieGroup | None:
        r"""The configuration group $G$ (`liepoisson.Rotations` for so(3), `liepoisson.Poses`
        for se(3), by default), or `None` when the system does not say: then nothing
        reconstructs $g$ (pass `group=` to `LiePoissonSystem`)."""
        return default_group(self.algebra)

    def require_group(self) -> AbstractLieGroup:
        """`group`, or a `ValueError` saying how to give one."""
        group = self.group
        if group is None and isinstance(self, AbstractDissipativeSystem):
            raise ValueError(f"{self!r} is dissipative: reconstructing its configuration is not implemented (the "
                             "damped velocity is not grad H and no spatial momentum is conserved); reconstruct the "
                             "conservative part, system.conservative")
        if group is None:
            raise ValueError(
                f"{self!r} has no configuration group, so its configurations cannot be reconstructed: give one, "
                "e.g. LiePoissonSystem(algebra, H, group=liepoisson.MatrixGroup(basis)) with a matrix basis of the "
                "algebra"
            )
        if self.algebra.sign != -1:
            raise ValueError(
                f"{self!r} is a right-invariant (spatial, sign=+1) system: the reconstruction here is that of body "
                "systems, dg/dt = g xi (sign=-1)"
            )
        return group

    def body_velocity(self, y: ArrayLike) -> jax.Array:
        r"""$\xi = \partial H/\partial\mu$, the body velocity in $\mathfrak g$ with
        $\dot g = g\,\xi$ (`generator`: with dissipation, the velocity of the damped motion)."""
        return self.generator(y)

    def spatial_momentum(self, g: ArrayLike, y: ArrayLike) -> jax.Array:
        r"""$J = \mathrm{Ad}^*_{g^{-1}}\mu$ `(..., dim)`: conserved along every motion of a free
        (left-invariant) system (Noether), and by every step that reconstructs exactly."""
        group = self.require_group()
        g = group.check(g, "g")
        y = as_state(y, "y", self.dim)
        return group.spatial_momentum(g, y)

    def lifted_test_flow(self, alpha: ArrayLike, t: ArrayLike, g: ArrayLike,
                         y: ArrayLike) -> tuple[jax.Array, jax.Array]:
        r"""The test flow of $\langle\alpha, \mu\rangle$ lifted to the configuration:
        $(g\exp(t\alpha),\ \mathrm{Ad}^*_{\exp(t\alpha)}\mu)$, exact, for a fixed `alpha` (the
        body velocity is $\alpha$ throughout). Keeps the spatial momentum to round-off."""
        group = self.require_group()
        y1 = self.test_flow(alpha, t, y)
        alpha = as_state(alpha, "alpha", self.dim)
        t = as_scalar_time(t)
        g = group.check(g, "g")
        return group.right_exp(g, t[..., None] * alpha), y1

    def heyoka_configured_system(self) -> list[tuple[Any, Any]]:
        r"""$(\mu, g)$ as heyoka `(variable, right-hand side)` pairs: $\dot\mu = \mathbb B\nabla H$,
        $\dot g = g\,\nabla H$ (`group.velocity_components`); the state is `mu` then `g`."""
        import heyoka as hy

        group = self.require_group()
        pairs = self.heyoka_system()
        mus = [v for v, _ in pairs]
        H = self.hamiltonian_components(mus, HEYOKA)
        xi = [hy.diff(H, v) for v in mus]
        gs = list(hy.make_vars(*[f"g{i}" for i in range(group.size)]))
        rhs = group.velocity_components(gs, xi)
        return pairs + [(v, hy.expression(float(r)) if isinstance(r, (int, float)) else r) for v, r in zip(gs, rhs)]


class AbstractExactlySolvableSystem(AbstractPoissonSystem):
    r"""A Poisson system whose motion has a closed-form solution $y(t) = \varphi_t(y(0))$
    (`RigidBody`: Jacobi elliptic functions); `integrators.ExactFlow` steps with it."""

    @abc.abstractmethod
    def exact_flow(self, t: ArrayLike, y: ArrayLike) -> jax.Array:
        r"""$\varphi_t(y)$, the exact solution at time `t` from `y`, batched over `y` `(..., dim)`."""


class AbstractDissipativeSystem(AbstractLiePoissonSystem):
    r"""A Lie-Poisson system with dissipation on the coadjoint orbit: $\dot\mu = \mathbb B(\mu)\,\xi(\mu)$
    with $\xi = \nabla H + \eta(\mu)$, $\eta$ the `dissipative_generator` (`DoubleBracket`).

    The motion is not Hamiltonian: no composition of the exact flows of pieces of $H$
    integrates it, so the splitting methods refuse it (`integrators.DampedSplitting` and the
    Lie-group methods integrate it)."""

    @property
    def group(self) -> AbstractLieGroup | None:
        r"""`None`: the reconstruction of a damped motion (its velocity is not $\nabla H$, and
        the spatial momentum is not conserved) is not implemented."""
        return None

    @property
    @abc.abstractmethod
    def conservative(self) -> AbstractLiePoissonSystem:
        r"""The system without its dissipation ($\dot\mu = \mathbb B\nabla H$): its pieces
        are what `integrators.DampedSplitting` splits."""

    @abc.abstractmethod
    def dissipative_generator(self, y: ArrayLike) -> jax.Array:
        r"""$\eta(\mu)$: the dissipative part of the velocity is $\mathbb B(\mu)\,\eta(\mu)$."""
