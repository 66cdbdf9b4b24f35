r"""How the parameters $\alpha$ of an LPNet relate to one step: $y_{n+1} = \mathbb T(\alpha)\,y_n$.

A parametrisation is one per system family (`learn` never special-cases systems otherwise):
the step (an exact test flow, so Casimirs are conserved by construction) and the inverse
problem, the parameters that carry $y_0$ to $y_1$ (paper eqs. Loss_function,
alpha_mod_Casimirs, SO3_A_def).
"""

from __future__ import annotations

import abc
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import liepoisson as lp
from liepoisson._validation import check_system, pairs, positive_float, positive_int
from liepoisson.systems import AbstractLiePoissonSystem, AbstractPoissonSystem

# Below this ratio |y0 x y1| / (y0 . y1) the angle/sine ratio uses its series (error O(r^6)).
_SMALL_RATIO = 1e-4


def _check_rtol(rtol: Any) -> float:
    return positive_float(rtol, "rtol")


class AbstractStepParametrisation(abc.ABC):
    r"""The parameters $\alpha\in\mathbb R^{n_\text{params}}$ of one learned step
    $y \mapsto \mathbb T(\alpha)\,y$ and how to find them from a data pair.

    `step` must be an exact flow of the system's bracket for fixed parameters (a Poisson map
    that conserves every Casimir), usable under `jit`, `vmap` and `grad`.
    """

    system: AbstractPoissonSystem

    @property
    @abc.abstractmethod
    def n_params(self) -> int:
        """Number of parameters of one step."""

    @abc.abstractmethod
    def step(self, params: jax.Array, y: jax.Array, h: Any) -> jax.Array:
        """$\\mathbb T(\\alpha)\\,y$ for one sample: `params` `(n_params,)`, `y` `(dim,)`."""

    @abc.abstractmethod
    def params_from_pair(self, y0: Any, y1: Any, h: Any) -> np.ndarray:
        """Parameters carrying `y0` to `y1` in one step of size `h`, Casimir-projected.

        `y0`, `y1` of shape `(..., dim)`; returns `(..., n_params)`. Raises `ValueError`
        naming the pair when no step connects them (different Casimirs).
        """

    @property
    def exact_flows(self) -> int:
        """Exact test flows evaluated by one `step`."""
        return 1

    def params_estimate(self, y0: Any, y1: Any, h: Any) -> np.ndarray:
        r"""First-order estimate $\alpha \approx \mathbb B(y_0)^+ (y_1 - y_0)/h$ (minimum norm,
        hence orthogonal to the Casimir gradients); not validated. Used to scale networks."""
        y0, y1 = pairs(y0, y1, self.system.dim)
        h = positive_float(h, "h")
        B = np.asarray(self.system.poisson_tensor(y0))
        return np.einsum("...ab,...b->...a", np.linalg.pinv(B), (y1 - y0) / h)

    def hyperparameters(self) -> dict[str, Any]:
        """JSON-serialisable constructor arguments (besides `system`), for checkpoints."""
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.system!r})"


def _flat_pairs(y0: Any, y1: Any, h: Any, dim: int):
    """`params_from_pair`'s input checks: `(y0, y1)` flattened to `(N, dim)`, `h`, and the
    leading shape to restore."""
    y0, y1 = pairs(y0, y1, dim)
    h = positive_float(h, "h")
    return y0.reshape(-1, dim), y1.reshape(-1, dim), h, y0.shape[:-1]


def _is_so3(system: AbstractPoissonSystem) -> bool:
    if not isinstance(system, AbstractLiePoissonSystem) or system.dim != 3:
        return False
    C = np.asarray(system.algebra.structure_constants)
    eps = lp.levi_civita()
    return bool(np.allclose(C, eps, atol=1e-12) or np.allclose(C, -eps, atol=1e-12))


class SO3Rotation(AbstractStepParametrisation):
    r"""so(3)* (rigid body): one step is the single rotation $\Pi \mapsto \exp(h\,\mathbb M(A))\Pi$,
    the exact flow of $H = A\cdot\Pi$ (`system.test_flow(A, h, y)`), parameters $A\in\mathbb R^3$.

    `params_from_pair` is the closed form of the shortest rotation carrying $\Pi^0$ to $\Pi^f$:
    axis $\Pi^0\times\Pi^f$, angle $\theta = \operatorname{atan2}(|\Pi^0\times\Pi^f|,
    \Pi^0\cdot\Pi^f)$, so $A\perp\Pi^0$ (already Casimir-projected). This is the paper's
    eq. SO3_A_def with the exact angle instead of $\sin\theta$ and the sign fixed by the
    convention of `test_flow`.

    **Arguments:** `system` (an so(3) Lie-Poisson system), `rtol`: the relative mismatch of
    $|\Pi^0|$ and $|\Pi^f|$ beyond which a pair is rejected.
    """

    def __init__(self, system: Any, rtol: float = 1e-10):
        system = check_system(system)
        if not _is_so3(system):
            raise ValueError(
                "SO3Rotation needs a Lie-Poisson system on so(3)* (structure constants = "
                f"Levi-Civita); got {system!r}. Use LieAlgebraParametrisation(system) instead."
            )
        self.system = system
        self.rtol = _check_rtol(rtol)
        # Orientation of the test flow relative to rotate(hA, y) = exp(-h hat A) y, checked
        # numerically so that either sign convention of the algebra is handled.
        self.orientation = _rotation_orientation(lambda A, y: system.test_flow(A, 1.0, y))

    @property
    def n_params(self) -> int:
        return 3

    def hyperparameters(self):
        return {"rtol": self.rtol}

    def step(self, params, y, h):
        return self.system.test_flow(params, h, y)

    def params_from_pair(self, y0, y1, h):
        a, b, h, batch = _flat_pairs(y0, y1, h, 3)
        A = -self.orientation * _shortest_rotation(a, b, self.rtol, "y") / h
        return A.reshape(batch + (3,))


def _rotation_orientation(rotation: Any) -> float:
    """+1 if `rotation(A, y)` = exp(-hat A) y (`lp.rotate`), -1 if exp(+hat A) y."""
    A = np.array([0.3, -0.2, 0.5])
    y = np.array([0.7, 0.1, -0.4])
    out = np.asarray(rotation(A, y))
    if np.allclose(out, np.asarray(lp.rotate(A, y)), atol=1e-13):
        return 1.0
    if np.allclose(out, np.asarray(lp.rotate(-A, y)), atol=1e-13):
        return -1.0
    raise ValueError("the test flow is not a rotation about alpha")  # pragma: no cover


def _shortest_rotation(a: np.ndarray, b: np.ndarray, rtol: float, name: str) -> np.ndarray:
    r"""$\theta\,(a\times b)/|a\times b|$ with $\theta = \operatorname{atan2}(|a\times b|, a\cdot b)$:
    the rotation vector of the shortest rotation carrying `a` to `b` (rows of `(N, 3)`);
    zero for parallel rows. Raises `ValueError` if $|a| \neq |b|$ or they are antiparallel."""
    n0, n1 = np.linalg.norm(a, axis=-1), np.linalg.norm(b, axis=-1)
    scale = np.maximum(n0, n1)
    bad = np.abs(n0 - n1) > rtol * scale
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ValueError(
            f"pair {i}: |{name}0| = {n0[i]:.17g} and |{name}1| = {n1[i]:.17g} differ by "
            f"{abs(n0[i] - n1[i]) / scale[i]:.3g} (relative) > rtol = {rtol:g}; they lie "
            "on different Casimir spheres and no rotation (Poisson map) connects them"
        )
    cross = np.cross(a, b)
    s = np.linalg.norm(cross, axis=-1)
    c = np.einsum("ia,ia->i", a, b)
    anti = (s <= 1e-8 * n0 * n1) & (c < 0)
    if np.any(anti):
        i = int(np.argmax(anti))
        raise ValueError(
            f"pair {i}: {name}0 = {a[i].tolist()} and {name}1 = {b[i].tolist()} are antiparallel; the "
            "rotation axis carrying one to the other is not unique"
        )
    c_safe = np.where(c == 0.0, 1.0, np.abs(c))
    r = s / c_safe
    s_safe = np.where(s == 0.0, 1.0, s)
    small = (r < _SMALL_RATIO) & (c > 0)
    # theta / |a x b|, with theta = atan2(s, c); series for small angles: no 0/0.
    factor = np.where(small, (1.0 - r * r / 3.0 + r**4 / 5.0) / c_safe, np.arctan2(s, c) / s_safe)
    factor = np.where(scale == 0.0, 0.0, factor)
    return factor[:, None] * cross


def _is_se3(system: AbstractPoissonSystem) -> bool:
    return (
        isinstance(system, AbstractLiePoissonSystem)
        and system.dim == 6
        and np.allclose(
            np.asarray(system.algebra.structure_constants),
            np.asarray(lp.se3().structure_constants),
            atol=1e-12,
        )
    )


class SE3RotationShear(AbstractStepParametrisation):
    r"""se(3)* (Kirchhoff): one step is a rotation followed by a shear, the paper's data
    preparation for Kirchhoff's equations re-derived,
    $(\Pi, p) \mapsto \mathbb T_{(0,b)}\,\mathbb T_{(A,0)}(\Pi, p)$, parameters
    $\alpha = (A, b)\in\mathbb R^6$, where $\mathbb T_\alpha$ = `system.test_flow(alpha, h, .)`:
    $\mathbb T_{(A,0)}$ rotates $\Pi$ and $p$ by the same rotation $R$ (angle $h|A|$ about
    $A$), $\mathbb T_{(0,b)}$ is the shear $\Pi \mapsto \Pi + \sigma h\,b\times p$, $p$ fixed
    ($\sigma = \pm1$ from the algebra's sign convention). Both are exact Poisson maps, so their
    composition conserves $|p|^2$ and $\Pi\cdot p$ exactly.

    `params_from_pair` (closed form): $A$ is the shortest rotation carrying $p^0$ to $p^f$
    (axis $p^0\times p^f$, angle $\operatorname{atan2}(|p^0\times p^f|, p^0\cdot p^f)$, as in
    `SO3Rotation`), so $A\perp p^0$; then with $d = R\Pi^0 - \Pi^f$, which is orthogonal to
    $p^f$ exactly when $\Pi\cdot p$ agrees ($R\Pi^0\cdot p^f = \Pi^0\cdot p^0$), the
    minimum-norm solution of $\sigma h\,b\times p^f = -d$ is
    $b = -\sigma\,p^f\times d/(h|p^f|^2)$, $b\perp p^f$. Four effective parameters of six, like
    the Casimir-projected coadjoint flow; the step is not a single $\exp(h\mathbb M(\alpha))$.

    **Arguments:** `system` (a Lie-Poisson system on se(3)*), `rtol`: relative tolerance for
    the Casimir mismatch of a pair.
    """

    def __init__(self, system: Any, rtol: float = 1e-10):
        system = check_system(system)
        if not _is_se3(system):
            raise ValueError(
                "SE3RotationShear needs a Lie-Poisson system on se(3)* (e.g. "
                f"liepoisson.systems.Kirchhoff); got {system!r}"
            )
        self.system = system
        self.rtol = _check_rtol(rtol)
        zero = np.zeros(3)
        y = np.array([0.2, -0.5, 0.9, 0.7, 0.1, -0.4])
        self.orientation = _rotation_orientation(
            lambda A, v: np.asarray(
                system.test_flow(np.concatenate([A, zero]), 1.0, np.concatenate([zero, v]))
            )[3:]
        )
        b = np.array([0.3, -0.2, 0.5])
        shear = np.asarray(system.test_flow(np.concatenate([zero, b]), 1.0, y))
        if np.allclose(shear, np.concatenate([y[:3] + np.cross(b, y[3:]), y[3:]]), atol=1e-13):
            self.shear_sign = 1.0
        elif np.allclose(shear, np.concatenate([y[:3] - np.cross(b, y[3:]), y[3:]]), atol=1e-13):
            self.shear_sign = -1.0
        else:  # pragma: no cover - would be a bug in liepoisson
            raise ValueError(f"the test flow of {system!r} along p is not a shear of Pi")
        self._step_batch = jax.jit(jax.vmap(self.step, in_axes=(0, 0, None)))

    @property
    def n_params(self) -> int:
        return 6

    @property
    def exact_flows(self) -> int:
        return 2

    def hyperparameters(self):
        return {"rtol": self.rtol}

    def step(self, params, y, h):
        zero = jnp.zeros_like(params[:3])
        rotated = self.system.test_flow(jnp.concatenate([params[:3], zero]), h, y)
        return self.system.test_flow(jnp.concatenate([zero, params[3:]]), h, rotated)

    def params_from_pair(self, y0, y1, h):
        a, b, h, batch = _flat_pairs(y0, y1, h, 6)
        p0, pf, Pif = a[:, 3:], b[:, 3:], b[:, :3]
        npf = np.linalg.norm(pf, axis=-1)
        zero_p = npf == 0.0
        if np.any(zero_p):
            i = int(np.argmax(zero_p))
            raise ValueError(
                f"pair {i}: p = 0; the rotation is not determined by p (a rigid-body pair: use "
                "LieAlgebraParametrisation)"
            )
        A = -self.orientation * _shortest_rotation(p0, pf, self.rtol, "p") / h
        zeros = np.zeros_like(A)
        rotated = np.asarray(
            self._step_batch(jnp.asarray(np.concatenate([A, zeros], -1)), jnp.asarray(a), h)
        )
        d = rotated[:, :3] - Pif
        # The component of d along p^f is the change of the Casimir Pi . p.
        along = np.einsum("ia,ia->i", d, pf) / npf
        cscale = np.linalg.norm(a[:, :3], axis=-1) + np.linalg.norm(Pif, axis=-1)
        bad = np.abs(along) > self.rtol * np.maximum(cscale, np.finfo(float).tiny)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise ValueError(
                f"pair {i}: the Casimir Pi . p differs between y0 and y1 ({a[i, :3] @ p0[i]:.17g} vs "
                f"{Pif[i] @ pf[i]:.17g}); no Poisson map connects them"
            )
        bvec = -self.shear_sign * np.cross(pf, d) / (h * npf[:, None] ** 2)
        return np.concatenate([A, bvec], -1).reshape(batch + (6,))


class LieAlgebraParametrisation(AbstractStepParametrisation):
    r"""Any system with exact test flows (Lie-Poisson on any algebra, or the affine/canonical
    systems of the paper): one step is $y \mapsto \mathbb T(h, \alpha)\,y$ = `test_flow(alpha, h, y)`,
    $\alpha\in\mathbb R^n$.

    `params_from_pair` solves $\mathbb T(h, \alpha)y_0 = y_1$ by Gauss-Newton on $\alpha$
    restricted to the orthogonal complement of the Casimir gradients at $y_0$ (paper eqs.
    Loss_function and alpha_mod_Casimirs), starting from the least-squares solution of
    $\mathbb B(y_0)\alpha = (y_1 - y_0)/h$.

    **Arguments:** `system`; `rtol`: tolerance for the Casimir mismatch of a pair and for the
    final residual (relative to the size of the states); `max_iter`: Gauss-Newton iterations.
    """

    def __init__(self, system: Any, rtol: float = 1e-10, max_iter: int = 30):
        self.system = check_system(system)
        self.rtol = _check_rtol(rtol)
        self.max_iter = positive_int(max_iter, "max_iter")
        self._solve = jax.jit(jax.vmap(self._solve_one, in_axes=(0, 0, None)))

    @property
    def n_params(self) -> int:
        return self.system.dim

    def hyperparameters(self):
        return {"rtol": self.rtol, "max_iter": self.max_iter}

    def step(self, params, y, h):
        return self.system.test_flow(params, h, y)

    def _complement(self, y0):
        n, k = self.system.dim, self.system.n_casimirs
        if k == 0:
            return jnp.eye(n)
        G = self.system.casimir_gradients(y0)
        _, _, Vt = jnp.linalg.svd(G, full_matrices=True)
        return Vt[k:].T  # (n, n - k), orthonormal, orthogonal to every Casimir gradient

    def _solve_one(self, y0, y1, h):
        P = self._complement(y0)
        B = self.system.poisson_tensor(y0)
        z0 = jnp.linalg.lstsq(B @ P, (y1 - y0) / h)[0]

        def residual(z):
            return self.system.test_flow(P @ z, h, y0) - y1

        def body(_, z):
            J = jax.jacfwd(residual)(z)
            return z - jnp.linalg.lstsq(J, residual(z))[0]

        z = jax.lax.fori_loop(0, self.max_iter, body, z0)
        return P @ z, jnp.max(jnp.abs(residual(z)))

    def params_from_pair(self, y0, y1, h):
        a, b, h, batch = _flat_pairs(y0, y1, h, self.system.dim)
        scale = np.maximum(np.max(np.abs(a), axis=-1), np.max(np.abs(b), axis=-1))
        scale = np.maximum(scale, np.finfo(float).tiny)
        if self.system.n_casimirs:
            C0, C1 = np.asarray(self.system.casimirs(a)), np.asarray(self.system.casimirs(b))
            G = np.asarray(self.system.casimir_gradients(a))
            # A Casimir change comparable to rtol times |grad C| |y| is round-off-level.
            cscale = np.linalg.norm(G, axis=-1) * np.linalg.norm(a, axis=-1)[:, None]
            cscale = np.maximum(cscale, np.abs(C0)) + np.finfo(float).tiny
            bad = np.abs(C1 - C0) > self.rtol * cscale
            if np.any(bad):
                i, j = (int(v) for v in np.argwhere(bad)[0])
                raise ValueError(
                    f"pair {i}: Casimir {j} differs between y0 and y1 ({C0[i, j]:.17g} vs "
                    f"{C1[i, j]:.17g}, relative {abs(C1[i, j] - C0[i, j]) / cscale[i, j]:.3g} > "
                    f"rtol = {self.rtol:g}); no Poisson map connects them"
                )
        alpha, res = self._solve(jnp.asarray(a), jnp.asarray(b), h)
        alpha, res = np.asarray(alpha), np.asarray(res)
        bad = ~(res <= 100 * self.rtol * scale)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise ValueError(
                f"pair {i}: Gauss-Newton found no alpha with test_flow(alpha, h, y0) = y1 "
                f"(residual {res[i]:.3g} after {self.max_iter} iterations); the step may be too "
                "large for the exponential map or the pair inconsistent"
            )
        return alpha.reshape(batch + (self.system.dim,))


def default_parametrisation(system: Any) -> AbstractStepParametrisation:
    """`SO3Rotation` for so(3)* systems, `LieAlgebraParametrisation` for any other
    Lie-Poisson system; other systems must name their parametrisation explicitly."""
    system = check_system(system)
    if _is_so3(system):
        return SO3Rotation(system)
    if isinstance(system, AbstractLiePoissonSystem):
        return LieAlgebraParametrisation(system)
    raise TypeError(
        f"no default parametrisation for {system!r}, which is not a Lie-Poisson system; pass "
        "parametrisation=learn.LieAlgebraParametrisation(system) (Gauss-Newton on the exact test "
        "flow; works for any system with exact test flows) or your own "
        "learn.AbstractStepParametrisation"
    )


PARAMETRISATIONS = {cls.__name__: cls for cls in (SO3Rotation, SE3RotationShear, LieAlgebraParametrisation)}


def parametrisation_from_name(name: str, system: AbstractPoissonSystem) -> AbstractStepParametrisation:
    """The parametrisation class `name` built for `system` (as stored in model files)."""
    if name not in PARAMETRISATIONS:
        raise ValueError(f"unknown parametrisation {name!r}; known: {sorted(PARAMETRISATIONS)}")
    return PARAMETRISATIONS[name](system)
