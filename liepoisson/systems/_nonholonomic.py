r"""Nonholonomic constraints on the body velocity: the Lie-Poisson-d'Alembert equations
(Bloch, *Nonholonomic Mechanics and Control*, 2003, Sec. 5.8; the Suslov problem and the
Chaplygin sleigh are its examples).

A Lie-Poisson system on $\mathfrak g^*$ and a constraint subspace
$\mathfrak d = \{\xi : \langle c_i, \xi\rangle = 0,\ i = 1..m\} \subset \mathfrak g$ given by
$m$ independent covectors $c_i \in \mathfrak g^*$ (the rows of $C$). The body velocity
$\xi = \nabla H(\mu)$ must stay in $\mathfrak d$; the reaction force, in the annihilator
$\mathfrak d^\circ$ spanned by the $c_i$, keeps it there:

$$\dot\mu = \mathbb B(\mu)\nabla H(\mu) + C^\top\lambda(\mu), \qquad
\bigl(C\,\nabla^2H\,C^\top\bigr)\lambda = -C\,\nabla^2H\,\mathbb B\nabla H,$$

$\lambda$ the multipliers for which $\frac{d}{dt}\,C\nabla H(\mu) = 0$. The reaction does no
work on admissible motions ($\dot H = \langle\nabla H, C^\top\lambda\rangle =
\langle C\nabla H, \lambda\rangle = 0$), so **the energy is conserved**; the Casimirs of
$\mathfrak g^*$ in general are **not** ($|\Pi|^2$ changes in the Suslov problem), nor is phase
volume, and the motion is not Hamiltonian: no composition of coadjoint flows follows it, and
a map that keeps the coadjoint orbit (an LPNet, a G-LPNet, a splitting method) cannot.
What a step must keep is the constraint $C\nabla H = 0$ and the energy.
"""

from __future__ import annotations

import functools
import itertools
import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._groups import AbstractLieGroup, MatrixGroup
from .._namespace import HEYOKA
from .._validation import finite_vector, positive_float
from ._base import AbstractLiePoissonSystem, AbstractPoissonSystem
from ._wrapped import AbstractWrappedSystem

#: Constraint covectors whose smallest singular value is below this fraction of the largest
#: are refused as dependent: a rank decided in float64, with a margin of ~1e4 over the
#: round-off of rows typed to 16 digits.
_RANK_RTOL = 1e-12


def check_constraints(constraints: Any, dim: int, name: str = "constraints") -> np.ndarray:
    r"""`constraints` as an `(m, dim)` float64 matrix of independent covectors, $1 \le m < $
    `dim` (a single covector `(dim,)` is one row)."""
    try:
        C = np.asarray(constraints)
    except (TypeError, ValueError) as err:  # ragged lists
        raise TypeError(f"{name} must be an (m, {dim}) real matrix of covectors; got {constraints!r}") from err
    if C.dtype == object or C.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be an (m, {dim}) real matrix of covectors; got dtype {C.dtype} ({constraints!r})")
    C = np.atleast_2d(C.astype(np.float64))
    if C.ndim != 2 or C.shape[1] != dim:
        raise ValueError(f"{name} must have shape (m, {dim}) (one covector of the algebra's dual per row); "
                         f"got shape {np.shape(constraints)}")
    if C.shape[0] == 0:
        raise ValueError(f"{name} must hold at least one covector; got none (an unconstrained system is the "
                         "Lie-Poisson system itself)")
    if not np.all(np.isfinite(C)):
        raise ValueError(f"{name} must be finite; got {C.tolist()}")
    if C.shape[0] >= dim:
        raise ValueError(f"{name} has {C.shape[0]} covectors for an algebra of dimension {dim}: they would forbid "
                         f"every velocity; give at most {dim - 1}")
    s = np.linalg.svd(C, compute_uv=False)
    if s[-1] <= _RANK_RTOL * s[0]:
        raise ValueError(f"{name} must be linearly independent (a subspace of the algebra given by independent "
                         f"covectors); its singular values are {s.tolist()}")
    return C


class LiePoissonDAlembert(AbstractWrappedSystem, AbstractLiePoissonSystem):
    r"""The Lie-Poisson-d'Alembert system of `system` with the body velocity constrained to
    $\langle c_i, \nabla H(\mu)\rangle = 0$ (module docstring): energy conserved, Casimirs
    not; `constraint(y)` is the diagnostic, `reaction(y)` the force.

    **Arguments:** `system`, a Lie-Poisson system (`RigidBody`, `Kirchhoff`, a
    `LiePoissonSystem` on any algebra); `constraints`, the covectors $c_i$ as an `(m, dim)`
    matrix (or one `(dim,)` covector), independent, $1 \le m <$ `dim`. Its Hamiltonian must
    have a Hessian definite on the constraint directions ($C\nabla^2H\,C^\top$ invertible: a
    kinetic energy is).
    """

    name = "LiePoissonDAlembert"

    def __init__(self, system: AbstractLiePoissonSystem, constraints: ArrayLike):
        if isinstance(system, LiePoissonDAlembert):
            raise TypeError(f"system is already constrained ({system!r}); give the unconstrained system "
                            "(system.system) with all the constraints' covectors")
        if not isinstance(system, AbstractLiePoissonSystem):
            kind = "a Poisson system not on the dual of a Lie algebra" if isinstance(
                system, AbstractPoissonSystem) else "not a liepoisson system"
            raise TypeError(f"system must be a Lie-Poisson system (RigidBody, Kirchhoff or a LiePoissonSystem on any "
                            f"algebra): the constraint is on its body velocity in the algebra; got "
                            f"{type(system).__name__}, {kind}")
        from ._base import AbstractDissipativeSystem

        if isinstance(system, AbstractDissipativeSystem):
            raise TypeError(f"system must be conservative; got the dissipative {system!r}")
        self.system = system
        self.algebra = system.algebra
        self.constraints = check_constraints(constraints, system.dim)


    def __repr__(self) -> str:
        return f"LiePoissonDAlembert({self.system!r}, constraints={self.constraints.tolist()})"

    def own_params(self) -> dict[str, Any]:
        return {"constraints": self.constraints.tolist()}

    @classmethod
    def from_own_params(cls, system, params) -> LiePoissonDAlembert:
        return cls(system, params["constraints"])

    @property
    def group(self) -> AbstractLieGroup | None:
        r"""The unconstrained system's group: $\dot g = g\,\nabla H(\mu)$ holds as before, with
        $\nabla H \in \mathfrak d$ (the admissible velocities)."""
        return self.system.group

    def hamiltonian_splitting(self):
        raise ValueError(
            f"{self!r} is nonholonomic: its flow is not a composition of Hamiltonian flows (the Casimirs change), so "
            "the splitting methods of integrators.splitting cannot integrate it; integrators.GaussLegendre4, "
            "ImplicitMidpoint (the constraint and, for a quadratic H, the energy kept), RK4 and ground_truth can")

    # -- the admissible velocities and a kinetic energy's metric -------------------------
    def admissible_basis(self) -> np.ndarray:
        r"""$N$ `(dim, k)`: an orthonormal basis of $\ker C$, the admissible velocities, the same
        on every machine (a learned map's weights are in it): the basis vectors $e_i$ projected
        onto $\ker C$ and orthonormalised in order (Gram-Schmidt, twice), those that add less
        than $10^{-6}$ skipped, each signed so that its largest entry is positive."""
        C = self.constraints
        dim, k = C.shape[1], C.shape[1] - C.shape[0]
        P = np.eye(dim) - C.T @ np.linalg.solve(C @ C.T, C)
        basis: list[np.ndarray] = []
        for i in range(dim):
            v = P[:, i].copy()
            for _ in range(2):
                for b in basis:
                    v -= (b @ v) * b
            norm = np.linalg.norm(v)
            if norm > 1e-6:
                v /= norm
                basis.append(v if v[np.argmax(np.abs(v))] > 0 else -v)
            if len(basis) == k:
                break
        return np.stack(basis, axis=1)

    def kinetic_metric(self) -> np.ndarray:
        r"""$\mathbb M$ `(dim, dim)` of a quadratic $H = \tfrac12\mu^\top\mathbb M^{-1}\mu$ (a
        kinetic energy: the body velocity is $\xi = \mathbb M^{-1}\mu$), the inverse of its
        Hessian. `ValueError` if $H$ is not quadratic (its Hessian changes with the state)."""
        dim = self.dim
        points = np.random.default_rng(0).normal(size=(2, dim))
        hessians = [np.asarray(jax.hessian(self.system.hamiltonian)(jnp.asarray(y)))
                    for y in (np.zeros(dim), *points)]
        scale = max(1.0, float(np.max(np.abs(hessians[0]))))
        # one Hessian for a quadratic H: only round-off (a thousand roundings) may differ
        if any(np.max(np.abs(H - hessians[0])) > 1e3 * np.finfo(np.float64).eps * scale for H in hessians[1:]):
            raise ValueError(f"{self!r} has a Hamiltonian that is not quadratic (its Hessian changes with the "
                             "state): a kinetic energy's metric, and what is built on it, needs a quadratic H")
        return np.linalg.inv(hessians[0])

    # -- the constraint ------------------------------------------------------------------
    def _hessian(self, y: jax.Array) -> jax.Array:
        flat = y.reshape((-1, self.dim))
        hess = jax.vmap(jax.hessian(lambda v: self.system.hamiltonian(v)))(flat)
        return hess.reshape(y.shape + (self.dim,))

    def multipliers(self, y: ArrayLike) -> jax.Array:
        r"""$\lambda(\mu)$, shape `(..., m)`: the reaction is $C^\top\lambda$ (with the
        `STABILISATION` term, zero on the constraint)."""
        return _multipliers(self, self.check_regular(y))

    def _multipliers(self, y: jax.Array) -> jax.Array:
        C = jnp.asarray(self.constraints)
        hess = self._hessian(y)
        CH = jnp.einsum("ia,...ab->...ib", C, hess)
        S = jnp.einsum("...ib,jb->...ij", CH, C)
        r = jnp.einsum("...ib,...b->...i", CH, self.system.vector_field(y))
        r = r + self.STABILISATION * self.constraint(y)
        return -jnp.linalg.solve(S, r[..., None])[..., 0]

    def reaction(self, y: ArrayLike) -> jax.Array:
        r"""The reaction force $C^\top\lambda(\mu)$, shape `(..., dim)`."""
        return jnp.einsum("...i,ia->...a", self.multipliers(y), jnp.asarray(self.constraints))

    def vector_field(self, y: ArrayLike) -> jax.Array:
        r"""$\dot\mu = \mathbb B(\mu)\nabla H(\mu) + C^\top\lambda(\mu)$."""
        y = self.check_regular(y)
        return self.system.vector_field(y) + self.reaction(y)

    def generator(self, y: ArrayLike) -> jax.Array:
        r"""$\nabla H(\mu)$, the body velocity; the reaction is not a coadjoint motion, so
        $\dot\mu \ne \mathbb B(\mu)\,\xi$ for any $\xi$ in general."""
        return self.system.generator(y)

    def constraint(self, y: ArrayLike) -> jax.Array:
        r"""$C\nabla H(\mu)$, shape `(..., m)`: zero on admissible states (the diagnostic)."""
        return jnp.einsum("ia,...a->...i", jnp.asarray(self.constraints), self.hamiltonian_gradient(y))

    def relative_constraint(self, y: ArrayLike) -> jax.Array:
        r"""$\max_i |\langle c_i, \nabla H\rangle| / (|c_i|\,|\nabla H|)$, shape `(...)`: the
        constraint's defect relative to the velocity (0 where $\nabla H = 0$)."""
        grad = self.hamiltonian_gradient(y)
        norms = jnp.linalg.norm(jnp.asarray(self.constraints), axis=1)
        size = jnp.linalg.norm(grad, axis=-1)
        defect = jnp.max(jnp.abs(self.constraint(y)) / norms, axis=-1)
        return jnp.where(size > 0, defect / jnp.where(size > 0, size, 1.0), 0.0)

    def project(self, y: ArrayLike) -> jax.Array:
        r"""The admissible state nearest `y` in the metric of $\nabla^2H$ (exact for a quadratic
        $H$): $\mu - C^\top(C\,\nabla^2H\,C^\top)^{-1}C\nabla H(\mu)$, so that
        $C\nabla H = 0$ afterwards. For initial conditions."""
        y = self.check_regular(y)
        C = jnp.asarray(self.constraints)
        hess = self._hessian(y)
        S = jnp.einsum("ia,...ab,jb->...ij", C, hess, C)
        nu = jnp.linalg.solve(S, self.constraint(y)[..., None])[..., 0]
        return y - jnp.einsum("...i,ia->...a", nu, C)

    #: The rate $\kappa$ (per unit time) at which the equations pull a state back onto the
    #: constraint: $\lambda$ solves $S\lambda = -C\nabla^2H\,\mathbb B\nabla H - \kappa\,C\nabla H$,
    #: so $\frac{d}{dt}C\nabla H = -\kappa\,C\nabla H$ (Baumgarte's stabilisation), in
    #: `vector_field` and heyoka's right-hand side alike. On the constraint the equations are
    #: unchanged; off it, the round-off that leaves it decays instead of feeding the energy
    #: ($\dot H = \langle C\nabla H, \lambda\rangle$): a Runge-Kutta method keeps the (linear)
    #: constraint's round-off offset exactly and would drift the energy linearly without it
    #: (BENCHMARKS.md, "Nonholonomic systems", with and without).
    STABILISATION = 1.0

    def heyoka_system(self) -> list[tuple[Any, Any]]:
        r"""$\mathbb B\nabla H + C^\top\lambda$ as heyoka expressions: $\nabla H$ and
        $\nabla^2H$ by `heyoka.diff` of the same Hamiltonian, $\lambda$ (with the
        `STABILISATION` term) by Cramer's rule."""
        import heyoka as hy

        pairs = self.system.heyoka_system()
        ys = [v for v, _ in pairs]
        f = [rhs for _, rhs in pairs]  # B grad H
        H = self.hamiltonian_components(ys, HEYOKA)
        grad = [hy.diff(H, v) for v in ys]
        C = self.constraints
        m = C.shape[0]
        # (C Hess)_ib = sum_a c_ia d(grad_a)/dy_b = d(c_i . grad)/dy_b
        c_grad = [_dot(C[i], grad) for i in range(m)]
        CH = [[hy.diff(c_grad[i], v) for v in ys] for i in range(m)]
        S = [[_dot(C[j], CH[i]) for j in range(m)] for i in range(m)]
        r = [-_dot_expr(CH[i], f) - self.STABILISATION * c_grad[i] for i in range(m)]
        lam = _cramer(S, r)
        reaction = [sum((float(C[i, a]) * lam[i] for i in range(m) if C[i, a] != 0.0), hy.expression(0.0))
                    for a in range(self.dim)]
        return [(y, rhs + force) for y, rhs, force in zip(ys, f, reaction)]


def _dot(c: np.ndarray, exprs: list[Any]) -> Any:
    """`sum_a c_a exprs_a` over the nonzero numbers `c_a`."""
    import heyoka as hy

    return sum((float(w) * e for w, e in zip(c, exprs) if w != 0.0), hy.expression(0.0))


def _dot_expr(a: list[Any], b: list[Any]) -> Any:
    import heyoka as hy

    return sum((x * y for x, y in zip(a, b)), hy.expression(0.0))


def _det(M: list[list[Any]]) -> Any:
    """The determinant of a small matrix of expressions (Leibniz: m! terms)."""
    m = len(M)
    if m == 1:
        return M[0][0]
    total = None
    for perm in itertools.permutations(range(m)):
        sign = 1.0 if _parity(perm) == 0 else -1.0
        term = M[0][perm[0]]
        for i in range(1, m):
            term = term * M[i][perm[i]]
        total = sign * term if total is None else total + sign * term
    return total


def _parity(perm: tuple[int, ...]) -> int:
    return sum(1 for i in range(len(perm)) for j in range(i + 1, len(perm)) if perm[i] > perm[j]) % 2


def _cramer(S: list[list[Any]], r: list[Any]) -> list[Any]:
    """The solution of `S x = r` by Cramer's rule (`len(r)` <= 4: the constraints of a body)."""
    m = len(r)
    if m > 4:
        raise ValueError(f"heyoka's right-hand side is written for at most 4 constraints (Cramer's rule); got {m}")
    det = _det(S)
    return [_det([[r[i] if j == k else S[i][j] for j in range(m)] for i in range(m)]) / det for k in range(m)]


@functools.partial(jax.jit, static_argnums=0)
def _multipliers(system: LiePoissonDAlembert, y: jax.Array) -> jax.Array:
    """`system.multipliers` compiled once per system and shape (not a Hessian traced eagerly at
    every call)."""
    return system._multipliers(y)


def refuse_nonholonomic(system: Any, what: str) -> None:
    """`ValueError` if `system` is nonholonomic (a `LiePoissonDAlembert`): `what` (a splitting,
    a Lie-group method, an LPNet or G-LPNet) moves along coadjoint orbits and would follow the
    unconstrained system, keeping the Casimirs the reaction force changes."""
    if isinstance(system, LiePoissonDAlembert):
        raise ValueError(  # noqa: TRY004 (a system of the right type, unsuitable)
            f"{system!r} is nonholonomic: {what} moves along the coadjoint orbit (its Casimirs kept), while the "
            "constraint's reaction force changes the Casimirs, so it would follow the unconstrained system. "
            "Integrate it with integrators.GaussLegendre4 or ImplicitMidpoint (they keep the constraint and, for a "
            "quadratic H, the energy), RK4 or ground_truth (heyoka); learn it with learn.DAlembertMap")


# -- the named examples ----------------------------------------------------------------------
def suslov(inertia: ArrayLike = (1.0, 2.0, 3.0), a: ArrayLike = (1.0, 1.0, 1.0)) -> LiePoissonDAlembert:
    r"""The Suslov problem: a rigid body (principal moments `inertia`) whose angular velocity
    is kept orthogonal to the body vector `a`, $\langle a, \Omega\rangle = 0$:
    $\dot\Pi = \Pi\times\Omega + \lambda a$, $\lambda = -\langle a, \mathbb I^{-1}(\Pi\times\Omega)\rangle
    / \langle a, \mathbb I^{-1}a\rangle$ (Bloch 2003, Sec. 1.7). With `a` not an eigenvector
    of the inertia (the default $(1, 1, 1)$) the body tends to a steady rotation about an axis
    in the plane $a^\perp$ as $t \to \pm\infty$; $|\Pi|^2$ changes along the way."""
    from ._rigid_body import RigidBody

    body = RigidBody(inertia)
    a = finite_vector(a, "a", 3)
    square = sum(float(x) * float(x) for x in a)  # Python floats: inf or 0 beyond float64, no warning
    if not 0.0 < square < np.inf:
        why = "which is zero" if not np.any(a) else "whose squared length is beyond float64"
        raise ValueError(f"a must be a non-zero body vector of moderate length (the constraint is <a, Omega> = 0, "
                         f"so only its direction matters: scale it); got {a.tolist()}, {why}")
    return LiePoissonDAlembert(body, a)


#: se(2)'s matrix basis $(E_\theta, E_x, E_y)$ as $3\times3$ homogeneous matrices, matching
#: `liepoisson.se2()`'s structure constants ($[E_\theta, E_x] = E_y$, $[E_\theta, E_y] = -E_x$).
SE2_BASIS = np.array([
    [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
    [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
    [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]],
])


def chaplygin_sleigh(mass: float = 1.0, inertia: float = 1.0, a: float = 0.5) -> LiePoissonDAlembert:
    r"""The Chaplygin sleigh: a body on the plane on a knife edge at the body origin that
    cannot slide sideways, its centre of mass at distance `a` along the blade, `mass` and
    `inertia` (about the centre of mass). On se(2)* with $\xi = (\omega, v_x, v_y)$ at the
    contact point, $L = \tfrac12 I\omega^2 + \tfrac12 m(v_x^2 + (v_y + a\omega)^2)$, so
    $\mu = M\xi$ with $M = \begin{pmatrix} I + ma^2 & 0 & ma\\ 0 & m & 0\\ ma & 0 & m\end{pmatrix}$,
    $H = \tfrac12\mu^\top M^{-1}\mu$; the constraint $v_y = 0$. On it $\dot v = a\omega^2$,
    $\dot\omega = -ma\,v\omega/(I + ma^2)$ (Bloch 2003, Sec. 1.7): the sleigh turns less and
    less and slides along a straight line at $v_\infty = \sqrt{2H/m}$. Configurations on SE(2)
    as $3\times3$ matrices (`liepoisson.MatrixGroup(SE2_BASIS)`): the heading and the position
    of the contact point are `sleigh_pose(g)`."""
    from .._catalogue import se2
    from ._lie_poisson import LiePoissonSystem

    m, J = positive_float(mass, "mass"), positive_float(inertia, "inertia")
    real = isinstance(a, numbers.Real) or (isinstance(a, (np.ndarray, np.generic)) and np.ndim(a) == 0
                                           and np.asarray(a).dtype.kind in "iuf")
    if isinstance(a, bool) or not real:
        raise TypeError(f"a must be a real number (the distance of the centre of mass along the blade); got "
                        f"{type(a).__name__} {a!r}")
    a = float(a)
    if not np.isfinite(a):
        raise ValueError(f"a must be finite (the distance of the centre of mass along the blade); got {a!r}")
    # M^{-1} in closed form (det M = m^2 I): exact where inverting M would cancel I against m a^2
    Minv = np.array([[1.0 / J, 0.0, -a / J], [0.0, 1.0 / m, 0.0], [-a / J, 0.0, 1.0 / m + a * a / J]])
    if not np.all(np.isfinite(Minv)):
        raise ValueError(f"mass = {m!r}, inertia = {J!r} and a = {a!r} give an inverse mass matrix beyond float64 "
                         f"(a / inertia = {a / J:.3g}, a^2 / inertia = {a * a / J:.3g}, 1 / mass = {1.0 / m:.3g}); "
                         "give them in units where they are of moderate size")

    def hamiltonian(mu, xp):
        return 0.5 * sum(float(Minv[i, j]) * mu[i] * mu[j] for i in range(3) for j in range(3) if Minv[i, j] != 0.0)

    body = LiePoissonSystem(se2(), hamiltonian, name="ChaplyginSleighBody", group=MatrixGroup(SE2_BASIS, name="SE(2)"))
    return LiePoissonDAlembert(body, (0.0, 0.0, 1.0))


def sleigh_pose(g: ArrayLike) -> np.ndarray:
    r"""`(heading, x, y)` of SE(2) configurations `(..., 9)` (3x3 matrices row by row): the
    angle of the blade from the x axis and the position of the contact point."""
    g = np.asarray(g, dtype=np.float64)
    if g.ndim < 1 or g.shape[-1] != 9:
        raise ValueError(f"g must hold SE(2) configurations as 3x3 matrices row by row, shape (..., 9); got shape "
                         f"{g.shape}")
    g = g.reshape(g.shape[:-1] + (3, 3))
    return np.stack([np.arctan2(g[..., 1, 0], g[..., 0, 0]), g[..., 0, 2], g[..., 1, 2]], axis=-1)

