r"""External forces and torques on a Lie-Poisson system, in the body frame:

$$\dot\mu = \mathbb B(\mu)\,\nabla H(\mu) + F(\xi), \qquad \xi = \nabla H(\mu),$$

$\xi$ the body velocity ($\Omega$ for a rigid body, $(\Omega, v)$ for a vehicle). A force need
not keep the Casimirs (air drag takes angular momentum away: $|\Pi|$ decays). The energy
changes at the rate $\dot H = \xi\cdot F(\xi)$: a *dissipative* force has $\xi\cdot F \le 0$
(`AbstractDissipativeForce`: linear drag $-D\xi$, quadratic drag $-|\xi|D\xi$ with $D$
symmetric positive semidefinite), a constant torque has no sign.

Each force acts on some components of $\xi$ (`indices`; all by default): for a vehicle on
se(3), drag on the rotation (`indices=(0, 1, 2)`) and on the translation (`(3, 4, 5)`), each
with its own $|\xi|$. Conventions: docs/conventions.md, "Forces in the body frame".
"""

from __future__ import annotations

import abc
import functools
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._namespace import HEYOKA, JAX
from .._validation import as_state
from ._base import AbstractLiePoissonSystem, AbstractPoissonSystem
from ._wrapped import AbstractWrappedSystem

#: Relative asymmetry of a drag matrix accepted as symmetric, and the relative size of a
#: negative eigenvalue accepted as round-off of a positive semidefinite one (a matrix typed or
#: computed in float64 is symmetric, and its zero eigenvalues zero, to a few roundings of its
#: largest entry).
_SYMMETRY_RTOL = 1e-12
_PSD_RTOL = 1e-12


def _indices(indices: Any, name: str = "indices") -> tuple[int, ...] | None:
    if indices is None:
        return None
    try:
        values = tuple(indices)
    except TypeError:
        raise TypeError(f"{name} must be a sequence of component indices (e.g. (0, 1, 2)) or None; "
                        f"got {type(indices).__name__} {indices!r}") from None
    if not values or not all(isinstance(i, (int, np.integer)) and not isinstance(i, bool) for i in values):
        raise TypeError(f"{name} must be a non-empty sequence of int component indices; got {indices!r}")
    values = tuple(int(i) for i in values)
    if min(values) < 0 or len(set(values)) != len(values):
        raise ValueError(f"{name} must be distinct indices >= 0; got {values}")
    return values


def check_drag_matrix(D: Any, name: str = "D") -> np.ndarray:
    r"""`D` as a symmetric positive semidefinite `(k, k)` float64 matrix; a scalar or a
    vector stands for a multiple of the identity or a diagonal matrix."""
    if isinstance(D, (str, bytes, bool)) or D is None:
        raise TypeError(f"{name} must be a symmetric positive semidefinite matrix (or a vector of its diagonal, or "
                        f"a number); got {type(D).__name__} {D!r}")
    try:
        arr = np.asarray(D)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a real matrix; got {D!r}") from err
    if np.iscomplexobj(arr) or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{name} must be a real matrix; got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.ndim == 1:
        arr = np.diag(arr)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        raise ValueError(f"{name} must be a square (k, k) matrix, a vector of its diagonal or a number; got shape "
                         f"{np.shape(D)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    scale = max(float(np.max(np.abs(arr))), np.finfo(float).tiny)
    asymmetry = float(np.max(np.abs(arr - arr.T)))
    if asymmetry > _SYMMETRY_RTOL * scale:
        raise ValueError(f"{name} must be symmetric; max |D - D^T| = {asymmetry:.3g}")
    arr = 0.5 * (arr + arr.T)
    low = float(np.linalg.eigvalsh(arr)[0])
    if low < -_PSD_RTOL * scale:
        raise ValueError(f"{name} must be positive semidefinite (a drag that only removes energy); its smallest "
                         f"eigenvalue is {low:.3g}")
    return arr


def _safe_norm(x: jax.Array) -> jax.Array:
    r"""$|x|$ over the last axis with a zero (not NaN) derivative at $x = 0$."""
    s = jnp.sum(x * x, axis=-1)
    positive = s > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, s, 1.0)), 0.0)


class AbstractForce(abc.ABC):
    r"""A force $F(\xi)$ in the body frame, a function of the body velocity $\xi = \nabla H$,
    acting on the components `indices` of $\xi$ and $\dot\mu$ (all when None)."""

    kind: str
    indices: tuple[int, ...] | None

    @abc.abstractmethod
    def _force(self, xi: jax.Array) -> jax.Array:
        """$F$ on the force's own components: `xi` `(..., k)` -> `(..., k)`."""

    @abc.abstractmethod
    def _heyoka_force(self, xi: list[Any]) -> list[Any]:
        """$F$ as heyoka expressions of the force's own components."""

    @property
    @abc.abstractmethod
    def size(self) -> int | None:
        """How many components the force acts on (`None`: any, a constant's length)."""

    @property
    @abc.abstractmethod
    def params(self) -> dict[str, Any]:
        """The force as JSON values (`force_from_params` rebuilds it)."""

    def components(self, dim: int) -> tuple[int, ...]:
        """The indices of $\\xi$ the force acts on in a system of dimension `dim`."""
        return tuple(range(dim)) if self.indices is None else self.indices

    def check_dim(self, dim: int, name: str = "forces") -> None:
        """`ValueError` unless the force fits a system of dimension `dim`."""
        comps = self.components(dim)
        if max(comps) >= dim:
            raise ValueError(f"{name}: {self!r} acts on components {comps}, beyond the system's {dim}")
        if self.size is not None and self.size != len(comps):
            raise ValueError(f"{name}: {self!r} is a ({self.size}, {self.size}) drag acting on {len(comps)} "
                             f"components {comps}; give indices= of length {self.size} or a ({len(comps)}, "
                             f"{len(comps)}) matrix")

    def force(self, xi: jax.Array) -> jax.Array:
        """$F(\\xi)$ on every component `(..., dim)` (zero off `indices`)."""
        dim = xi.shape[-1]
        comps = self.components(dim)
        local = self._force(xi[..., list(comps)])
        return jnp.zeros_like(xi).at[..., list(comps)].add(local)

    def heyoka_force(self, xi: list[Any]) -> list[Any]:
        """$F(\\xi)$ as heyoka expressions on every component (the number 0.0 off `indices`)."""
        comps = self.components(len(xi))
        local = self._heyoka_force([xi[i] for i in comps])
        out: list[Any] = [0.0] * len(xi)
        for i, f in zip(comps, local):
            out[i] = f
        return out

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items() if k != "kind" and v is not None)
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, AbstractForce) and self.params == other.params

    def __hash__(self) -> int:
        return hash(repr(self))


class AbstractDissipativeForce(AbstractForce):
    r"""A force that only removes energy: $\xi\cdot F(\xi) \le 0$ for every $\xi$. Written
    $F(\xi) = -w(\xi)\,D\,\xi$ with $D$ symmetric positive semidefinite and a weight
    $w(\xi) \ge 0$ (`weight`), the form `integrators.ForcedSplitting`'s energy-decreasing step uses."""

    D: np.ndarray

    def __init__(self, D: ArrayLike, indices: Sequence[int] | None = None):
        self.indices = _indices(indices)
        if np.ndim(D) == 0 and self.indices is not None:
            D = np.full(len(self.indices), D)
        self._scalar = np.ndim(D) == 0  # a multiple of the identity of the system's size
        self.D = check_drag_matrix(np.atleast_1d(D) if self._scalar else D)

    @property
    def size(self) -> int | None:
        return None if self._scalar else self.D.shape[0]

    def resized(self, dim: int) -> AbstractDissipativeForce:
        """A number given as `D` without `indices`: the multiple of the identity of size `dim`."""
        return type(self)(np.full(dim, float(self.D[0, 0]))) if self._scalar else self

    @property
    def params(self):
        return {"kind": self.kind, "D": float(self.D[0, 0]) if self._scalar else self.D.tolist(),
                "indices": None if self.indices is None else list(self.indices)}

    @abc.abstractmethod
    def weight(self, xi: jax.Array) -> jax.Array:
        """$w(\\xi) \\ge 0$ `(...)` from the force's own components `(..., k)`."""

    def _force(self, xi):
        return -self.weight(xi)[..., None] * jnp.einsum("ab,...b->...a", jnp.asarray(self.D), xi)

    def _heyoka_force(self, xi):
        import heyoka as hy

        w = self._heyoka_weight(xi)
        out = []
        for row in self.D:
            terms = [float(d) * x for d, x in zip(row, xi) if d != 0.0]
            out.append(-w * sum(terms[1:], terms[0]) if terms else hy.expression(0.0))
        return out

    @abc.abstractmethod
    def _heyoka_weight(self, xi: list[Any]) -> Any:
        """$w(\\xi)$ as a heyoka expression."""

    def embedded(self, dim: int) -> np.ndarray:
        """$D$ placed at `indices` in a `(dim, dim)` zero matrix."""
        comps = list(self.components(dim))
        out = np.zeros((dim, dim))
        out[np.ix_(comps, comps)] = self.D
        return out


class LinearDrag(AbstractDissipativeForce):
    r"""Linear (viscous) drag $F = -D\xi$: Rayleigh's dissipation function
    $R = \tfrac12\xi^\top D\xi$, $F = -\nabla_\xi R$, $\dot H = -\xi^\top D\xi \le 0$.

    **Arguments:** `D`, symmetric positive semidefinite `(k, k)` (a vector: its diagonal; a
    number: a multiple of the identity, then `k` is that of `indices` or the system's);
    `indices`, the `k` components of $\xi$ it acts on (default all)."""

    kind = "LinearDrag"


    def weight(self, xi):
        return jnp.ones(xi.shape[:-1], dtype=xi.dtype)

    def _heyoka_weight(self, xi):
        return 1.0


class QuadraticDrag(AbstractDissipativeForce):
    r"""Quadratic (aerodynamic) drag $F = -|\xi|\,D\xi$, $|\xi|$ the Euclidean norm of the
    components it acts on: $\dot H = -|\xi|\,\xi^\top D\xi \le 0$. The torque of air on a
    tumbling body at high Reynolds number (Newtonian drag: force $\propto$ speed squared).

    **Arguments:** as `LinearDrag`."""

    kind = "QuadraticDrag"


    def weight(self, xi):
        return _safe_norm(xi)

    def _heyoka_weight(self, xi):
        import heyoka as hy

        return hy.sqrt(sum((x * x for x in xi[1:]), xi[0] * xi[0]))


class ConstantTorque(AbstractForce):
    r"""A constant force/torque $F = \tau$ in the body frame (e.g. a gyroscope's frame that
    pushes the body at a fixed rate, a thruster): $\dot H = \xi\cdot\tau$, no sign.

    **Arguments:** `torque`, the `k` components of $\tau$; `indices`, the components they act
    on (default all: `k` must be the system's dimension)."""

    kind = "ConstantTorque"

    def __init__(self, torque: ArrayLike, indices: Sequence[int] | None = None):
        self.indices = _indices(indices)
        try:
            tau = np.asarray(torque)
        except (TypeError, ValueError) as err:
            raise TypeError(f"torque must be a real vector; got {torque!r}") from err
        if isinstance(torque, (str, bytes)) or np.iscomplexobj(tau) or not np.issubdtype(tau.dtype, np.number):
            raise TypeError(f"torque must be a real vector; got {torque!r}")
        tau = np.atleast_1d(tau.astype(np.float64))
        if tau.ndim != 1:
            raise ValueError(f"torque must be a vector; got shape {tau.shape}")
        if not np.all(np.isfinite(tau)):
            raise ValueError(f"torque must be finite; got {tau.tolist()}")
        if self.indices is not None and len(self.indices) != tau.shape[0]:
            raise ValueError(f"torque has {tau.shape[0]} components and indices {len(self.indices)}")
        self.torque = tau

    @property
    def size(self) -> int:
        return self.torque.shape[0]

    def _force(self, xi):
        return jnp.broadcast_to(jnp.asarray(self.torque), xi.shape)

    def _heyoka_force(self, xi):
        import heyoka as hy

        return [hy.expression(float(t)) for t in self.torque]

    @property
    def params(self):
        return {"kind": self.kind, "torque": self.torque.tolist(),
                "indices": None if self.indices is None else list(self.indices)}


FORCES: dict[str, type[AbstractForce]] = {cls.kind: cls for cls in (LinearDrag, QuadraticDrag, ConstantTorque)}


def force_from_params(params: Any) -> AbstractForce:
    """The force of `params` (as `AbstractForce.params` gives them)."""
    if not isinstance(params, dict) or params.get("kind") not in FORCES:
        raise ValueError(f"not a force definition (a dict with kind one of {sorted(FORCES)}); got {params!r}")
    args = {k: v for k, v in params.items() if k != "kind"}
    try:
        return FORCES[params["kind"]](**args)
    except TypeError as err:
        raise ValueError(f"not a valid {params['kind']} definition {params!r}: {err}") from err


class AbstractForcedSystem(AbstractLiePoissonSystem):
    r"""A Lie-Poisson system with external forces: $\dot\mu = \mathbb B(\mu)\nabla H + F$;
    `conservative` is the system without them, `force(y)` is $F$."""

    @property
    @abc.abstractmethod
    def conservative(self) -> AbstractLiePoissonSystem:
        r"""The unforced system $\dot\mu = \mathbb B\nabla H$, whose pieces
        `integrators.ForcedSplitting` splits."""

    @abc.abstractmethod
    def force(self, y: ArrayLike) -> jax.Array:
        r"""$F(\nabla H(\mu))$ `(..., dim)`."""


class Forced(AbstractWrappedSystem, AbstractForcedSystem):
    r"""A Lie-Poisson system driven by external forces in the body frame:

    $$\dot\mu = \mathbb B(\mu)\,\nabla H(\mu) + \sum_f F_f(\xi), \qquad \xi = \nabla H(\mu).$$

    The configuration still moves with the body velocity, $\dot g = g\,\xi$, so attitudes and
    poses are reconstructed as for the free system (`group` is the system's). Energy and
    Casimirs are diagnostics that now change: $\dot H = \xi\cdot F$ (`energy_rate`), $\le 0$
    for dissipative forces; the Casimirs change at $\nabla C\cdot F$.

    **Arguments:** `system`, a Lie-Poisson system (`RigidBody`, `Kirchhoff`, `HeavyTop`, a
    `LiePoissonSystem`); `forces`, one force or a sequence of them (`LinearDrag`,
    `QuadraticDrag`, `ConstantTorque`).

    `integrators.ground_truth` integrates it with heyoka; `integrators.ForcedSplitting`
    splits it into the system's exact flows and the forces' flow.
    """

    name = "Forced"

    def __init__(self, system: AbstractLiePoissonSystem, forces: AbstractForce | Sequence[AbstractForce]):
        if isinstance(system, AbstractForcedSystem):
            raise TypeError(f"system is already forced ({system!r}); give the unforced system (system.conservative) "
                            "with all the forces")
        from ._base import AbstractDissipativeSystem
        from ._nonholonomic import LiePoissonDAlembert

        if isinstance(system, (AbstractDissipativeSystem, LiePoissonDAlembert)) or not isinstance(
                system, AbstractLiePoissonSystem):
            kind = type(system).__name__
            what = "a Poisson system not on the dual of a Lie algebra" if isinstance(
                system, AbstractPoissonSystem) else "not a liepoisson system"
            if isinstance(system, AbstractLiePoissonSystem):
                what = "damped or constrained; forces are added to a Hamiltonian Lie-Poisson system"
            raise TypeError(f"system must be a Hamiltonian Lie-Poisson system (RigidBody, Kirchhoff, HeavyTop, a "
                            f"LiePoissonSystem); got {kind}, {what}")
        if isinstance(forces, AbstractForce):
            forces = (forces,)
        try:
            forces = tuple(forces)
        except TypeError:
            raise TypeError(f"forces must be a force (LinearDrag, QuadraticDrag, ConstantTorque) or a sequence of "
                            f"them; got {type(forces).__name__}") from None
        if not forces or not all(isinstance(f, AbstractForce) for f in forces):
            raise TypeError(f"forces must be a non-empty sequence of liepoisson.systems forces (LinearDrag, "
                            f"QuadraticDrag, ConstantTorque); got {forces!r}")
        dim = system.dim
        forces = tuple(f.resized(dim) if isinstance(f, (LinearDrag, QuadraticDrag)) else f for f in forces)
        for k, f in enumerate(forces):
            f.check_dim(dim, f"forces[{k}]")
        self.system = system
        self.forces: tuple[AbstractForce, ...] = forces
        self.algebra = system.algebra

    @property
    def conservative(self) -> AbstractLiePoissonSystem:
        return self.system

    @property
    def dissipative(self) -> bool:
        """Whether every force is dissipative ($\\dot H \\le 0$ for every state)."""
        return all(isinstance(f, AbstractDissipativeForce) for f in self.forces)


    def __repr__(self) -> str:
        return f"Forced({self.system!r}, {list(self.forces)!r})"

    def own_params(self) -> dict[str, Any]:
        return {"forces": [f.params for f in self.forces]}

    @classmethod
    def from_own_params(cls, system, params) -> Forced:
        return cls(system, [force_from_params(p) for p in params["forces"]])

    @property
    def group(self):
        """The system's configuration group: $\\dot g = g\\,\\nabla H$ as without forces."""
        return self.system.group

    def hamiltonian_splitting(self):
        raise ValueError(
            f"{self!r} is forced: a splitting of its Hamiltonian would integrate the unforced system. Use "
            "integrators.ForcedSplitting (the Hamiltonian's exact flows and the forces' flow) or "
            "integrators.ground_truth")

    def force(self, y: ArrayLike) -> jax.Array:
        xi = self.hamiltonian_gradient(y)
        return sum((f.force(xi) for f in self.forces[1:]), self.forces[0].force(xi))

    def vector_field(self, y: ArrayLike) -> jax.Array:
        r"""$\mathbb B(\mu)\nabla H + F(\nabla H)$."""
        y = self.check_regular(y)
        return self.system.vector_field(y) + self.force(y)

    def energy_rate(self, y: ArrayLike) -> jax.Array:
        r"""$\dot H = \nabla H\cdot F$ `(...)` ($\le 0$ when every force is dissipative)."""
        y = self.check_regular(y)
        return jnp.sum(self.hamiltonian_gradient(y) * self.force(y), axis=-1)

    def casimir_rates(self, y: ArrayLike) -> jax.Array:
        r"""$\dot C_j = \nabla C_j\cdot F$ `(..., k)`: what the forces do to the Casimirs."""
        y = as_state(y, "y", self.dim)
        return jnp.einsum("...ka,...a->...k", self.casimir_gradients(y), self.force(y))

    def quadratic_hamiltonian(self) -> tuple[np.ndarray, np.ndarray]:
        r"""`(A, b)` with $\nabla H(\mu) = A\mu + b$, or a `ValueError` when $H$ is not a
        quadratic polynomial (checked at random states: the gradient differs from $A\mu + b$ by
        more than round-off). The forces' flow (`force_flow`) needs it."""
        cached = self.__dict__.get("_quadratic")
        if cached is not None:
            return cached
        zero = jnp.zeros(self.dim)
        try:
            b = np.asarray(jax.grad(lambda y: self.system.hamiltonian_components(
                [y[i] for i in range(self.dim)], JAX))(zero))
            A = np.asarray(jax.hessian(lambda y: self.system.hamiltonian_components(
                [y[i] for i in range(self.dim)], JAX))(zero))
        except (TypeError, ValueError, ZeroDivisionError):
            A = b = np.full((1,), np.nan)
        probes = np.random.default_rng(0).normal(size=(8, self.dim))
        ok = bool(np.all(np.isfinite(A)) and np.all(np.isfinite(b)))
        if ok:
            grads = np.asarray(self.system.hamiltonian_gradient(probes))
            affine = probes @ A.T + b
            scale = float(np.max(np.abs(grads))) + float(np.max(np.abs(affine)))
            # a quadratic's gradient by two code paths: a few roundings of its size
            ok = float(np.max(np.abs(grads - affine))) <= 64 * np.finfo(float).eps * max(scale, 1.0)
        if not ok:
            raise ValueError(
                f"{self.system!r}'s Hamiltonian is not quadratic in the momenta: the forces' exact or "
                f"energy-decreasing flow (integrators.ForcedSplitting) needs grad H affine. Integrate {self!r} "
                f"with integrators.ground_truth (heyoka) or a Runge-Kutta method (integrators.RK4)")
        self.__dict__["_quadratic"] = (A, b)
        return A, b

    def drag_matrix(self, xi: jax.Array) -> jax.Array:
        r"""$\bar D(\xi) = \sum_f w_f(\xi)D_f$ `(dim, dim)` over the dissipative forces (their
        matrices embedded at their components), for one body velocity `xi` `(dim,)`."""
        out = jnp.zeros((self.dim, self.dim), dtype=xi.dtype)
        for f in self.forces:
            if isinstance(f, AbstractDissipativeForce):
                out = out + f.weight(xi[..., list(f.components(self.dim))]) * jnp.asarray(f.embedded(self.dim))
        return out

    def force_flow(self, t: ArrayLike, y: ArrayLike) -> jax.Array:
        r"""The flow of the forces alone over a time `t` from `y` `(..., dim)`, with the
        Hamiltonian's body velocity $\xi = \nabla H$ (`forces_flow`): exact for linear drag
        and constant torques, else the midpoint discrete gradient, whose energy never increases
        for $t > 0$ under dissipative forces."""
        A, b = self.quadratic_hamiltonian()
        drags = [f for f in self.forces if isinstance(f, AbstractDissipativeForce)]
        torques = [f.force(jnp.zeros(self.dim)) for f in self.forces if not isinstance(f, AbstractDissipativeForce)]
        torque = sum(torques[1:], torques[0]) if torques else None
        y = jnp.asarray(y, dtype=jnp.float64)
        t = jnp.asarray(t, dtype=jnp.float64)
        one = functools.partial(forces_flow, jnp.asarray(A), jnp.asarray(b), self.drag_matrix, torque,
                                constant=all(isinstance(f, LinearDrag) for f in drags))
        flat = y.reshape(-1, self.dim)
        out = jax.vmap(one, in_axes=(None, 0))(t, flat) if t.ndim == 0 else jax.vmap(one)(
            jnp.broadcast_to(t, y.shape[:-1]).reshape(-1), flat)
        return out.reshape(y.shape)

    def check_taylor_starts(self, y0: np.ndarray, name: str = "y0") -> None:
        r"""`ValueError` naming the first state of `y0` `(n, dim)` where a quadratic drag's
        $|\xi|$ is zero: $|\xi|$ is not analytic there, so Taylor's method (heyoka) cannot
        start from it (the motion from $\xi = 0$ is that of the unforced system there)."""
        xi = np.asarray(self.hamiltonian_gradient(y0))
        for f in self.forces:
            if isinstance(f, QuadraticDrag):
                comps = list(f.components(self.dim))
                zero = np.flatnonzero(np.all(xi[:, comps] == 0.0, axis=-1))
                if zero.size:
                    j = int(zero[0])
                    raise ValueError(
                        f"{name}[{j}] = {y0[j].tolist()} has zero body velocity on the components {tuple(comps)} of "
                        f"{f!r}: |xi| is not differentiable there, and Taylor's method (heyoka) cannot start from "
                        f"it. Start off xi = 0 (e.g. add 1e-12), or integrate with integrators.ForcedSplitting")

    def heyoka_system(self) -> list[tuple[Any, Any]]:
        r"""$\mathbb B\nabla H + F(\nabla H)$ as heyoka expressions."""
        import heyoka as hy

        pairs = self.system.heyoka_system()
        ys = [v for v, _ in pairs]
        H = self.hamiltonian_components(ys, HEYOKA)
        xi = [hy.diff(H, v) for v in ys]
        rhs = [r for _, r in pairs]
        for f in self.forces:
            for i, term in enumerate(f.heyoka_force(xi)):
                if not (isinstance(term, float) and term == 0.0):
                    rhs[i] = rhs[i] + term
        return list(zip(ys, rhs))


#: Fixed-point iterations for the midpoint weights of `forces_flow` (quadratic drag): each
#: gains one power of the step in the local error, and 6 make the step symmetric to
#: $O(h^7)$, beyond what an order-4 composition needs (tested against heyoka).
MIDPOINT_ITERATIONS = 6


def forces_flow(A: jax.Array, b: jax.Array, drag: Callable[[jax.Array], jax.Array], torque: jax.Array | None,
                t: jax.Array, y: jax.Array, *, constant: bool = False) -> jax.Array:
    r"""The flow of the forces alone, $\dot\mu = -\bar D(\xi)\,\xi + \tau$ with
    $\xi = A\mu + b$ (a quadratic Hamiltonian), over a time `t` from one state `y` `(dim,)`.

    `drag(xi)` is $\bar D(\xi)$ `(dim, dim)`, symmetric positive semidefinite for every
    $\xi$ (the sum of the drags' $w_f(\xi)D_f$); `constant`: it does not depend on $\xi$ (linear
    drags). `torque` is $\tau$ `(dim,)` or None.

    - Constant $\bar D$: exact, the exponential of the affine system
      $\dot\mu = -\bar D(A\mu + b) + \tau$ (augmented by one dimension).
    - Otherwise the midpoint discrete gradient: $\mu_1 - \mu_0 = t\,(-\bar D\,\bar\xi + \tau)$,
      $\bar\xi = A(\mu_0 + \mu_1)/2 + b$, $\bar D$ at the midpoint's $\xi$ (fixed-point
      iterations, `MIDPOINT_ITERATIONS`), one linear solve each. For a quadratic $H$,
      $H(\mu_1) - H(\mu_0) = \bar\xi\cdot(\mu_1 - \mu_0)$ exactly, so
      $H(\mu_1) - H(\mu_0) = -t\,\bar\xi^\top\bar D\bar\xi + t\,\bar\xi\cdot\tau$: without a
      torque the energy never increases, for every $t > 0$ and whatever $\bar D$ was evaluated
      at (the iterations' convergence does not matter). Symmetric ($\Phi_{-t} = \Phi_t^{-1}$
      at convergence) and of order 2, so that a symmetric composition of order 4 keeps its order.
    """
    dim = y.shape[-1]
    tau = jnp.zeros(dim, dtype=y.dtype) if torque is None else torque
    if constant:  # the exact affine flow
        Dbar = drag(b)
        M = jnp.zeros((dim + 1, dim + 1), dtype=y.dtype)
        M = M.at[:dim, :dim].set(-Dbar @ A).at[:dim, dim].set(tau - Dbar @ b)
        E = jax.scipy.linalg.expm(t * M)
        return E[:dim, :dim] @ y + E[:dim, dim]
    eye = jnp.eye(dim, dtype=y.dtype)

    def solve(mid: jax.Array) -> jax.Array:
        Dbar = drag(A @ mid + b)
        rhs = y - t * (0.5 * Dbar @ (A @ y) + Dbar @ b) + t * tau
        return jnp.linalg.solve(eye + 0.5 * t * Dbar @ A, rhs)

    def iterate(_, y1):
        return solve(0.5 * (y + y1))

    return jax.lax.fori_loop(0, MIDPOINT_ITERATIONS, iterate, solve(y))
