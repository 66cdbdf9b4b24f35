r"""Configurations: the Lie group $G$ whose body momenta a Lie-Poisson system on $\mathfrak g^*$
describes, and the reconstruction $\dot g = g\,\xi$ with the body velocity
$\xi = \partial H/\partial\mu$.

For the left-invariant (body) systems of the library ([the Lie-Poisson bracket][conventions],
`sign=-1`) a motion of $\mu$ lifts to $(g(t), \mu(t))$ with $\dot g = g\,\xi(\mu)$, and the
spatial momentum $J = \mathrm{Ad}^*_{g^{-1}}\mu$ is conserved (Noether). The test flow of
$\langle\alpha, \mu\rangle$ moves $\mu$ by the coadjoint action of $\exp(t\alpha)$; lifted, it moves
$g \mapsto g\exp(t\alpha)$, and $J$ is unchanged to round-off. A G-LPNet's module and each
`CollectiveTerm` of a splitting is such a flow with $\alpha$ frozen, so every step built of them
carries the configuration exactly.

Representations (a configuration is a flat float64 array of `group.size` components):

- `Rotations`: SO(3) as unit quaternions, **scalar last** $(x, y, z, w)$, as scipy's
  `Rotation.as_quat()`; Hamilton's product; $R(q)$ maps body to space coordinates,
  $v_\text{space} = R(q)\,v_\text{body}$; $\dot q = \tfrac12\,q\otimes(\Omega, 0)$.
- `Poses`: SE(3) as $(q, x)$, 7 components: the attitude quaternion and the position in space;
  $\dot R = R\hat\Omega$, $\dot x = R v$ for $\xi = (\Omega, v)$ (se(3)'s basis order).
- `MatrixGroup`: any matrix Lie group given by a matrix basis $E_a$ of its algebra with
  $[E_a, E_b] = E_aE_b - E_bE_a = C_{abd}E_d$; $g$ an $N\times N$ matrix stored row by row.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_state, is_traced, matrix_basis

#: How far from 1 the norm of a quaternion given as input may be (a star tracker prints 7-9
#: digits; a quaternion rounded to 7 digits is off by up to ~2e-7): nearer, it is normalised;
#: farther, it is refused as not a rotation.
QUATERNION_TOLERANCE = 1e-6
#: How far from orthonormal (max |R^T R - 1|) a rotation matrix given as input may be.
MATRIX_TOLERANCE = 1e-6


def hat(v: Any) -> list[list[Any]]:
    r"""$\hat v$ with $\hat v\,w = v\times w$, on the three components of `v` (any namespace)."""
    return [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]


def quaternion_product(p: Sequence[Any], q: Sequence[Any]) -> list[Any]:
    r"""Hamilton's product $p\otimes q$ of scalar-last quaternions, on their components (numbers,
    JAX arrays or heyoka expressions)."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return [
        pw * qx + qw * px + (py * qz - pz * qy),
        pw * qy + qw * py + (pz * qx - px * qz),
        pw * qz + qw * pz + (px * qy - py * qx),
        pw * qw - (px * qx + py * qy + pz * qz),
    ]


def rotation_matrix_components(q: Sequence[Any]) -> list[list[Any]]:
    r"""$R(q) = (w^2 - |u|^2)\,1 + 2uu^\top + 2w\hat u$ for $q = (u, w)$ (a rotation when
    $|q| = 1$), on the components."""
    x, y, z, w = q
    return [
        [w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ]


def _stack(rows: list[list[Any]]) -> jax.Array:
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def _split(x: jax.Array) -> list[jax.Array]:
    return [x[..., i] for i in range(x.shape[-1])]


def rotation_matrix(q: jax.Array) -> jax.Array:
    """`(..., 3, 3)` rotation matrices of unit quaternions `(..., 4)` (scalar last)."""
    return _stack(rotation_matrix_components(_split(q)))


def quaternion_exp(phi: jax.Array) -> jax.Array:
    r"""$\exp(\hat\phi)$ as a unit quaternion, $(\sin(\theta/2)\,\phi/\theta, \cos(\theta/2))$
    with $\theta = |\phi|$; finite, with finite derivatives, at $\phi = 0$ (series there)."""
    theta2 = jnp.sum(phi * phi, axis=-1)
    small = theta2 < 1e-6  # the series' first omitted terms are below theta^6/46080 < 3e-23
    theta = jnp.sqrt(jnp.where(small, 1.0, theta2))
    s = jnp.where(small, 0.5 - theta2 / 48.0 + theta2 * theta2 / 3840.0, jnp.sin(0.5 * theta) / theta)
    c = jnp.where(small, 1.0 - theta2 / 8.0 + theta2 * theta2 / 384.0, jnp.cos(0.5 * theta))
    return jnp.concatenate([s[..., None] * phi, c[..., None]], axis=-1)


def rotation_angle(q1: jax.Array, q2: jax.Array) -> jax.Array:
    r"""The angle in $[0, \pi]$ of the rotation $R(q_1)^\top R(q_2)$ between two attitudes
    (the same for $\pm q$): $2\,\mathrm{atan2}(|u|, |w|)$ of $q_1^{-1}\otimes q_2$."""
    conj = q1 * jnp.asarray([-1.0, -1.0, -1.0, 1.0])
    rel = jnp.stack(quaternion_product(_split(conj), _split(q2)), axis=-1)
    u2 = jnp.sum(rel[..., :3] ** 2, axis=-1)
    u = jnp.where(u2 > 0.0, jnp.sqrt(jnp.where(u2 > 0.0, u2, 1.0)), 0.0)  # finite gradient at u = 0
    return 2.0 * jnp.arctan2(u, jnp.abs(rel[..., 3]))


def se3_translation(phi: jax.Array, v: jax.Array) -> jax.Array:
    r"""$V(\phi)\,v = v + A\,\phi\times v + B\,\phi\times(\phi\times v)$ with
    $A = (1 - \cos\theta)/\theta^2$, $B = (\theta - \sin\theta)/\theta^3$
    (`liepoisson.rotation_coefficients`, series at small $\theta$): the body-frame
    displacement of $\exp$ of $(\phi, v)$ in se(3)."""
    from ._coadjoint import rotation_coefficients

    _, A, B = rotation_coefficients(jnp.sum(phi * phi, axis=-1))
    pv = jnp.cross(phi, v)
    return v + A[..., None] * pv + B[..., None] * jnp.cross(phi, pv)


class AbstractLieGroup(abc.ABC):
    r"""The configuration space $G$ of a Lie-Poisson system on $\mathfrak g^*$: how a
    configuration is stored (`size` float64 components), moved by $g\mapsto g\exp(\xi)$, and
    read (the spatial momentum $J = \mathrm{Ad}^*_{g^{-1}}\mu$, the velocity $g\,\xi$ for
    heyoka). Final subclasses: `Rotations`, `Poses`, `MatrixGroup`."""

    #: Components of one configuration.
    size: int
    #: Dimension of the algebra (of $\xi$ and $\mu$).
    dim: int
    name: str

    @abc.abstractmethod
    def identity(self) -> np.ndarray:
        """The identity, `(size,)`."""

    @abc.abstractmethod
    def right_exp(self, g: jax.Array, xi: jax.Array) -> jax.Array:
        r"""$g\exp(\xi)$, batched over leading axes: the configuration after a motion of
        constant body velocity $\xi/t$ for time $t$ (pass $t\xi$)."""

    @abc.abstractmethod
    def velocity_components(self, g: Sequence[Any], xi: Sequence[Any]) -> list[Any]:
        r"""$\dot g = g\,\xi$ on the components of `g` and `xi` (numbers, JAX arrays or heyoka
        expressions; a polynomial in them)."""

    @abc.abstractmethod
    def spatial_momentum(self, g: jax.Array, mu: jax.Array) -> jax.Array:
        r"""$J = \mathrm{Ad}^*_{g^{-1}}\mu$, `(..., dim)`: conserved along every motion of a
        left-invariant system (Noether)."""

    @abc.abstractmethod
    def matrix_basis(self) -> np.ndarray:
        r"""Matrices $E_a$ `(dim, N, N)` of a faithful representation of the algebra, with
        $[E_a, E_b] = C_{abd}E_d$ for the structure constants this group goes with."""

    @abc.abstractmethod
    def between(self, g1: jax.Array, g2: jax.Array) -> jax.Array:
        r"""$g_1^{-1}g_2$ `(..., size)`, exactly, in this representation (traceable, batched): a
        configuration relative to another, the same for both moved by any $h$ on the left."""

    @abc.abstractmethod
    def compose(self, g1: jax.Array, g2: jax.Array) -> jax.Array:
        r"""$g_1g_2$ `(..., size)` (traceable, batched): `between`'s inverse,
        $g_1\,(g_1^{-1}g_2) = g_2$."""

    @abc.abstractmethod
    def difference(self, g1: jax.Array, g2: jax.Array) -> jax.Array:
        r"""A smooth measure of $g_1^{-1}g_2$ in $\mathbb R^{\dim}$, equal to
        $\log(g_1^{-1}g_2)$ to first order (traceable, batched): the residual of a fit."""

    @abc.abstractmethod
    def log_between(self, g1: ArrayLike, g2: ArrayLike) -> np.ndarray:
        r"""$\log(g_1^{-1}g_2)$ `(..., dim)` in numpy (for estimates from data, not traced): the
        constant body velocity times the time that carries $g_1$ to $g_2$."""

    def check(self, g: ArrayLike, name: str = "g") -> jax.Array:
        """`g` as float64 configurations `(..., size)`, finite, on the group (within the
        stated tolerance; then projected onto it). `ValueError` naming `name` otherwise."""
        return as_state(g, name, self.size)

    def project(self, g: jax.Array) -> jax.Array:
        """The nearest point of the group (for representations with a constraint: a unit
        quaternion is normalised); the identity map here."""
        return g

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and self._key() == other._key()  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash((type(self), self._key()))

    def _key(self) -> Any:
        return ()

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def check_algebra(self, structure_constants: np.ndarray, what: str) -> None:
        """`ValueError` unless `matrix_basis()` represents the algebra of `structure_constants`
        (`what` names the system in the message)."""
        check_matrix_basis(self.matrix_basis(), np.asarray(structure_constants), what)


def _check_quaternions(q: ArrayLike, name: str, size: int, what: str) -> jax.Array:
    arr = as_state(q, name, size)
    if is_traced(arr):
        return arr
    norm = np.linalg.norm(np.asarray(arr)[..., :4], axis=-1)
    off = np.abs(norm - 1.0)
    if np.any(off > QUATERNION_TOLERANCE):
        index = tuple(int(i) for i in np.argwhere(np.atleast_1d(off > QUATERNION_TOLERANCE))[0])[: arr.ndim - 1]
        where = f"{name}[{', '.join(map(str, index))}]" if index else name
        raise ValueError(
            f"{where} must hold a unit quaternion (x, y, z, w), scalar last as scipy's Rotation.as_quat(), "
            f"{what}; its norm is {float(np.atleast_1d(norm)[index] if index else norm):.12g}, more than "
            f"{QUATERNION_TOLERANCE:g} from 1. Normalise it if it is a rotation (q / |q|), or pass a "
            "scipy.spatial.transform.Rotation through from_scipy"
        )
    unit = np.asarray(arr).copy()
    # normalised where the norm is off by more than roundings: a saved, normalised quaternion
    # reads back bitwise
    unit[..., :4] /= np.where(off > 4 * np.finfo(np.float64).eps, norm, 1.0)[..., None]
    return jnp.asarray(unit)


class Rotations(AbstractLieGroup):
    r"""SO(3) as unit quaternions $(x, y, z, w)$, scalar last (scipy's `Rotation.as_quat()`),
    for so(3) with $[e_a, e_b] = \epsilon_{abc}e_c$: $R(q)$ maps body to space coordinates,
    $\dot q = \tfrac12 q\otimes(\Omega, 0)$, the spatial angular momentum $J = R(q)\,\Pi$."""

    size = 4
    dim = 3
    name = "SO(3), unit quaternions (x, y, z, w)"

    def identity(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.0, 1.0])

    def right_exp(self, g, xi):
        # normalised: |q| = 1 to round-off after every step, not a random walk of roundings
        return self.project(jnp.stack(quaternion_product(_split(g), _split(quaternion_exp(xi))), axis=-1))

    def velocity_components(self, g, xi):
        return [0.5 * c for c in quaternion_product(list(g), [xi[0], xi[1], xi[2], 0.0])]

    def spatial_momentum(self, g, mu):
        return jnp.einsum("...ij,...j->...i", rotation_matrix(g), mu)

    def matrix_basis(self) -> np.ndarray:
        return np.array([np.array(hat(e), dtype=np.float64) for e in np.eye(3)])

    def between(self, g1, g2):
        r"""$q_1^{-1}\otimes q_2$ (the conjugate of $q_1$, the signs of both kept)."""
        return jnp.stack(quaternion_product(_split(g1 * jnp.asarray([-1.0, -1.0, -1.0, 1.0])), _split(g2)), axis=-1)

    def compose(self, g1, g2):
        return jnp.stack(quaternion_product(_split(g1), _split(g2)), axis=-1)

    def difference(self, g1, g2):
        r"""$2\,\mathrm{sign}(w)\,u$ of $q_1^{-1}\otimes q_2 = (u, w)$: the rotation vector to
        first order, $2\sin(\theta/2)$ along the axis (the same for $\pm q$)."""
        rel = self.between(g1, g2)
        return 2.0 * jnp.where(rel[..., 3:] < 0.0, -1.0, 1.0) * rel[..., :3]

    def log_between(self, g1, g2):
        from scipy.spatial.transform import Rotation

        q1, q2 = np.asarray(self.check(g1, "g1")), np.asarray(self.check(g2, "g2"))
        shape = _broadcast(q1, q2)
        q1, q2 = np.broadcast_to(q1, shape).reshape(-1, 4), np.broadcast_to(q2, shape).reshape(-1, 4)
        return (Rotation.from_quat(q1).inv() * Rotation.from_quat(q2)).as_rotvec().reshape(shape[:-1] + (3,))

    def check(self, g, name="g"):
        return _check_quaternions(g, name, 4, "an attitude")

    def project(self, g):
        return g / jnp.linalg.norm(g, axis=-1, keepdims=True)

    # -- in and out ---------------------------------------------------------------------
    @staticmethod
    def from_scipy(rotation: Any) -> np.ndarray:
        """Quaternions `(..., 4)` of a `scipy.spatial.transform.Rotation` (one or many)."""
        from scipy.spatial.transform import Rotation

        if not isinstance(rotation, Rotation):
            raise TypeError(f"rotation must be a scipy.spatial.transform.Rotation; got {type(rotation).__name__}")
        return np.asarray(rotation.as_quat(), dtype=np.float64)

    @staticmethod
    def to_scipy(q: ArrayLike) -> Any:
        """The `scipy.spatial.transform.Rotation` of quaternions `(4,)` or `(n, 4)` (checked)."""
        from scipy.spatial.transform import Rotation

        q = np.asarray(Rotations().check(q, "q"))
        if q.ndim > 2:
            raise ValueError(f"q must have shape (4,) or (n, 4); got shape {q.shape} (reshape it to (-1, 4))")
        return Rotation.from_quat(q)

    @staticmethod
    def from_matrix(R: ArrayLike, name: str = "R") -> np.ndarray:
        """Quaternions `(..., 4)` of rotation matrices `(..., 3, 3)` (body to space), each checked
        to be a rotation: $|R^\\top R - 1| \\le$ `MATRIX_TOLERANCE`, $\\det R > 0$."""
        from scipy.spatial.transform import Rotation

        try:
            R = np.asarray(R, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise TypeError(f"{name} must be a real array of rotation matrices (..., 3, 3); got {type(R).__name__}") from err
        if R.ndim < 2 or R.shape[-2:] != (3, 3):
            raise ValueError(f"{name} must have shape (..., 3, 3); got shape {R.shape}")
        if not np.all(np.isfinite(R)):
            raise ValueError(f"{name} must be finite")
        flat = R.reshape(-1, 3, 3)
        off = np.abs(np.einsum("nki,nkj->nij", flat, flat) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(flat)
        bad = np.flatnonzero((off > MATRIX_TOLERANCE) | (det <= 0))
        if bad.size:
            k = int(bad[0])
            index = np.unravel_index(k, R.shape[:-2]) if R.ndim > 2 else ()
            where = f"{name}[{', '.join(str(int(i)) for i in index)}]" if index else name
            why = (f"det = {det[k]:.6g} (a reflection, not a rotation)" if det[k] <= 0 else
                   f"max |R^T R - 1| = {off[k]:.3g} > {MATRIX_TOLERANCE:g}")
            raise ValueError(f"{where} is not a rotation matrix: {why}")
        return Rotation.from_matrix(flat).as_quat().reshape(R.shape[:-2] + (4,))


class Poses(AbstractLieGroup):
    r"""SE(3) as $(q, x)$: the attitude quaternion (scalar last, as `Rotations`) and the position
    in space, for se(3) with $\xi = (\Omega, v)$, $\mu = (\Pi, p)$:
    $\dot R = R\hat\Omega$, $\dot x = R\,v$; spatial momentum
    $J = (R\Pi + x\times Rp,\ Rp)$ (angular about the origin, linear)."""

    size = 7
    dim = 6
    name = "SE(3), (quaternion (x, y, z, w), position)"

    def identity(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])

    def right_exp(self, g, xi):
        q, x = g[..., :4], g[..., 4:]
        phi, v = xi[..., :3], xi[..., 3:]
        q1 = Rotations().project(jnp.stack(quaternion_product(_split(q), _split(quaternion_exp(phi))), axis=-1))
        x1 = x + jnp.einsum("...ij,...j->...i", rotation_matrix(q), se3_translation(phi, v))
        return jnp.concatenate([q1, x1], axis=-1)

    def velocity_components(self, g, xi):
        q = list(g[:4])
        dq = [0.5 * c for c in quaternion_product(q, [xi[0], xi[1], xi[2], 0.0])]
        R = rotation_matrix_components(q)
        dx = [R[i][0] * xi[3] + R[i][1] * xi[4] + R[i][2] * xi[5] for i in range(3)]
        return dq + dx

    def spatial_momentum(self, g, mu):
        R = rotation_matrix(g[..., :4])
        Rp = jnp.einsum("...ij,...j->...i", R, mu[..., 3:])
        RPi = jnp.einsum("...ij,...j->...i", R, mu[..., :3])
        return jnp.concatenate([RPi + jnp.cross(g[..., 4:], Rp), Rp], axis=-1)

    def matrix_basis(self) -> np.ndarray:
        E = np.zeros((6, 4, 4))
        for a in range(3):
            E[a, :3, :3] = hat(np.eye(3)[a])
            E[3 + a, a, 3] = 1.0
        return E

    def between(self, g1, g2):
        r"""$(q_1^{-1}\otimes q_2,\ R_1^\top(x_2 - x_1))$."""
        d = jnp.einsum("...ji,...j->...i", rotation_matrix(g1[..., :4]), g2[..., 4:] - g1[..., 4:])
        return jnp.concatenate([Rotations().between(g1[..., :4], g2[..., :4]), d], axis=-1)

    def compose(self, g1, g2):
        r"""$(q_1\otimes q_2,\ x_1 + R_1x_2)$."""
        x = g1[..., 4:] + jnp.einsum("...ij,...j->...i", rotation_matrix(g1[..., :4]), g2[..., 4:])
        return jnp.concatenate([Rotations().compose(g1[..., :4], g2[..., :4]), x], axis=-1)

    def difference(self, g1, g2):
        """The attitudes' `Rotations.difference`, then $R_1^\top(x_2 - x_1)$ (body frame)."""
        rel = self.between(g1, g2)
        return jnp.concatenate([Rotations().difference(g1[..., :4], g2[..., :4]), rel[..., 4:]], axis=-1)

    def log_between(self, g1, g2):
        g1, g2 = np.asarray(self.check(g1, "g1")), np.asarray(self.check(g2, "g2"))
        shape = _broadcast(g1, g2)
        g1, g2 = np.broadcast_to(g1, shape).reshape(-1, 7), np.broadcast_to(g2, shape).reshape(-1, 7)
        phi = Rotations().log_between(g1[:, :4], g2[:, :4])
        R1 = np.asarray(rotation_matrix(jnp.asarray(g1[:, :4])))
        d = np.einsum("nji,nj->ni", R1, g2[:, 4:] - g1[:, 4:])  # R1^T (x2 - x1)
        # V(phi) v = d: V is a linear map of v (se3_translation), solved column by column
        V = np.stack([np.asarray(se3_translation(jnp.asarray(phi), jnp.broadcast_to(jnp.asarray(e), phi.shape)))
                      for e in np.eye(3)], axis=-1)
        v = np.linalg.solve(V, d[..., None])[..., 0]
        return np.concatenate([phi, v], axis=1).reshape(shape[:-1] + (6,))

    def check(self, g, name="g"):
        return _check_quaternions(g, name, 7, "then a position (a pose is 7 numbers)")

    def project(self, g):
        q = g[..., :4]
        return jnp.concatenate([q / jnp.linalg.norm(q, axis=-1, keepdims=True), g[..., 4:]], axis=-1)


def check_matrix_basis(basis: np.ndarray, C: np.ndarray, what: str) -> None:
    """`ValueError` unless the matrices `basis` `(n, N, N)` are linearly independent and
    $[E_a, E_b] = C_{abd}E_d$ to a relative 1e-10 (a few hundred roundings of the products)."""
    n = C.shape[0]
    if basis.ndim != 3 or basis.shape[0] != n or basis.shape[1] != basis.shape[2]:
        raise ValueError(f"the matrix basis of {what} must have shape ({n}, N, N) for an algebra of dimension {n}; "
                         f"got shape {basis.shape}")
    flat = basis.reshape(n, -1)
    if np.linalg.matrix_rank(flat) < n:
        raise ValueError(f"the matrix basis of {what} is linearly dependent: its {n} matrices span less than {n} "
                         "dimensions")
    comm = np.einsum("aij,bjk->abik", basis, basis) - np.einsum("bij,ajk->abik", basis, basis)
    want = np.einsum("abd,dik->abik", C, basis)
    err = np.abs(comm - want)
    scale = max(1.0, float(np.abs(comm).max()), float(np.abs(want).max()))
    if err.max() > 1e-10 * scale:
        a, b = (int(i) for i in np.unravel_index(int(np.argmax(err.max(axis=(2, 3)))), (n, n)))
        raise ValueError(
            f"the matrix basis does not represent the algebra of {what}: [E_{a}, E_{b}] - C[{a}, {b}, d] E_d has "
            f"entries up to {err.max():.3g} (relative to {scale:.3g}); the commutators of the matrices must follow "
            "the structure constants, [E_a, E_b] = C_abd E_d"
        )


class MatrixGroup(AbstractLieGroup):
    r"""A matrix Lie group given by a basis $E_a$ `(dim, N, N)` of its algebra; a configuration
    is an $N\times N$ matrix stored row by row (`size` $= N^2$). $g\exp(\xi)$ is
    `jax.scipy.linalg.expm`; $J = \mathrm{Ad}^*_{g^{-1}}\mu$ with
    $\langle J, \eta\rangle = \langle\mu, g^{-1}\hat\eta\,g\rangle$ (coordinates by least
    squares on the basis)."""

    def __init__(self, basis: ArrayLike, name: str = "matrix group"):
        basis = matrix_basis(basis, "(dim, N, N)")
        self.basis = basis
        self.dim = basis.shape[0]
        self.n = basis.shape[1]
        self.size = self.n * self.n
        self.name = str(name)
        self._coordinates = np.linalg.pinv(basis.reshape(self.dim, -1))  # (N^2, dim)

    def __repr__(self) -> str:
        return f"MatrixGroup(<{self.dim} matrices {self.n}x{self.n}>, name={self.name!r})"

    def _key(self):
        return (self.basis.tobytes(), self.basis.shape)

    def identity(self) -> np.ndarray:
        return np.eye(self.n).reshape(-1)

    def _hat(self, xi: jax.Array) -> jax.Array:
        return jnp.einsum("...a,aij->...ij", xi, jnp.asarray(self.basis))

    def right_exp(self, g, xi):
        from jax.scipy.linalg import expm

        G = g.reshape(g.shape[:-1] + (self.n, self.n))
        out = G @ expm(self._hat(xi))
        return out.reshape(out.shape[:-2] + (self.size,))

    def velocity_components(self, g, xi):
        n = self.n
        X = [[sum((float(self.basis[a, i, j]) * xi[a] for a in range(self.dim) if self.basis[a, i, j] != 0), 0.0)
              for j in range(n)] for i in range(n)]
        return [sum((g[i * n + k] * X[k][j] for k in range(n) if not (isinstance(X[k][j], float) and X[k][j] == 0)),
                    0.0) for i in range(n) for j in range(n)]

    def spatial_momentum(self, g, mu):
        G = g.reshape(g.shape[:-1] + (self.n, self.n))
        conj = jnp.linalg.solve(G[..., None, :, :], jnp.asarray(self.basis) @ G[..., None, :, :])  # g^-1 E_b g
        coords = jnp.einsum("...bk,ka->...ba", conj.reshape(conj.shape[:-2] + (self.size,)), jnp.asarray(self._coordinates))
        return jnp.einsum("...ba,...a->...b", coords, mu)

    def matrix_basis(self) -> np.ndarray:
        return self.basis

    def between(self, g1, g2):
        G1 = g1.reshape(g1.shape[:-1] + (self.n, self.n))
        G2 = g2.reshape(g2.shape[:-1] + (self.n, self.n))
        rel = jnp.linalg.solve(G1, G2)
        return rel.reshape(rel.shape[:-2] + (self.size,))

    def compose(self, g1, g2):
        out = g1.reshape(g1.shape[:-1] + (self.n, self.n)) @ g2.reshape(g2.shape[:-1] + (self.n, self.n))
        return out.reshape(out.shape[:-2] + (self.size,))

    def difference(self, g1, g2):
        """The basis coordinates of $g_1^{-1}g_2 - 1$ (the logarithm to first order)."""
        return (self.between(g1, g2) - jnp.asarray(self.identity())) @ jnp.asarray(self._coordinates)

    def log_between(self, g1, g2):
        from scipy.linalg import logm

        g1, g2 = np.asarray(self.check(g1, "g1")), np.asarray(self.check(g2, "g2"))
        shape = _broadcast(g1, g2)
        G1 = np.broadcast_to(g1, shape).reshape(-1, self.n, self.n)
        G2 = np.broadcast_to(g2, shape).reshape(-1, self.n, self.n)
        logs = []
        for k, (a, b) in enumerate(zip(G1, G2)):
            log = logm(np.linalg.solve(a, b))
            if np.abs(np.imag(log)).max(initial=0.0) > 1e-8 * max(1.0, np.abs(log).max()):
                raise ValueError(f"g1^-1 g2 (pair {k}) has no real logarithm near the identity (a half-turn or "
                                 "more between consecutive configurations): sample them more densely")
            logs.append(np.real(log).reshape(-1))
        logs = np.stack(logs)
        return (logs @ self._coordinates).reshape(shape[:-1] + (self.dim,))

    def check(self, g, name="g"):
        g = as_state(g, name, self.size)
        if not is_traced(g):
            G = np.asarray(g).reshape(-1, self.n, self.n)
            det = np.linalg.det(G) if G.size else np.ones(0)
            if np.any(np.abs(det) < 1e-12):
                raise ValueError(f"{name} must hold invertible {self.n}x{self.n} matrices (row by row); "
                                 f"one has determinant {det[np.argmin(np.abs(det))]:.3g}")
        return g


def _broadcast(g1: np.ndarray, g2: np.ndarray) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(g1.shape, g2.shape)
    except ValueError:
        raise ValueError(f"g1 and g2 must have shapes that broadcast; got {g1.shape} and {g2.shape}") from None


def default_group(algebra: Any) -> AbstractLieGroup | None:
    """The configuration group the library knows for `algebra`: `Rotations` for so(3), `Poses`
    for se(3) (their matrix bases represent its structure constants), else `None`."""
    cached = algebra.__dict__.get("_default_group", False)
    if cached is not False:
        return cached
    if algebra.dim not in (Rotations().dim, Poses().dim):  # no structure constants formed for others
        algebra.__dict__["_default_group"] = None
        return None
    C = np.asarray(algebra.structure_constants)
    found = None
    for group in (Rotations(), Poses()):
        if C.shape[0] == group.dim:
            try:
                group.check_algebra(C, "the algebra")
            except ValueError:
                continue
            found = group
    algebra.__dict__["_default_group"] = found
    return found


def group_definition(group: AbstractLieGroup) -> dict[str, Any] | None:
    """`group` as JSON values (`group_from_definition` rebuilds it), or `None` for a group no
    file can hold (a user's own subclass)."""
    if type(group) in (Rotations, Poses):
        return {"kind": type(group).__name__}
    if type(group) is MatrixGroup:
        return {"kind": "MatrixGroup", "basis": group.basis.tolist(), "name": group.name}
    return None


def group_from_definition(definition: dict[str, Any]) -> AbstractLieGroup:
    """The group of `group_definition`'s values; `ValueError` for a malformed one."""
    kind = definition.get("kind") if isinstance(definition, dict) else None
    if kind == "Rotations":
        return Rotations()
    if kind == "Poses":
        return Poses()
    if kind == "MatrixGroup":
        return MatrixGroup(definition["basis"], name=definition.get("name", "matrix group"))
    raise ValueError(f"not a group definition (a dict with kind Rotations, Poses or MatrixGroup): {definition!r}")
