r"""What a learned Hamiltonian says about the system: its quadratic part, and which of it the
dynamics identify.

On a Lie-Poisson system the motion only sees $H$ modulo Casimirs: $H + f(C)$ has the same
flow on every leaf. For a quadratic $\widetilde H(y) = \tfrac12 y^T A y + b^T y$ and quadratic
Casimirs $C_k = \tfrac12 y^T Q_k y$, $A$ is identified only modulo $\operatorname{span}\{Q_k\}$
(for the rigid body, $Q = I$: adding a multiple of $|\Pi|^2$ changes nothing, so only the
differences $A_{ii} - A_{jj}$ and the off-diagonal entries are identified).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from liepoisson.internals import states
from liepoisson.systems import AbstractPoissonSystem


@dataclasses.dataclass(frozen=True)
class QuadraticPart:
    r"""The least-squares quadratic $\tfrac12 y^T A y + b^T y + c$ of a Hamiltonian over samples.

    - `matrix` $A$ (symmetric), `linear` $b$, `constant` $c$;
    - `residual`: RMS of the Hamiltonian minus the quadratic, over the RMS of the
      Hamiltonian's variation on the samples (0 for a quadratic Hamiltonian);
    - `casimir_hessians`: the Hessians $Q_k$ of the system's quadratic Casimirs.
    """

    matrix: np.ndarray
    linear: np.ndarray
    constant: float
    residual: float
    casimir_hessians: np.ndarray

    def identifiable(self) -> np.ndarray:
        r"""$A$ minus its orthogonal (Frobenius) projection onto $\operatorname{span}\{Q_k\}$:
        the part of the matrix the dynamics determine. Two Hamiltonians with the same motion
        have the same identifiable matrix."""
        return project_out(self.matrix, self.casimir_hessians)

    def principal_axes(self) -> PrincipalAxes:
        r"""The eigen-decomposition of `identifiable()`, $\sum_k\lambda_kv_kv_k^T$: for the rigid
        body ($Q = I$: $A = \mathbb I^{-1}$ up to a multiple of $I$) its principal axes in the
        axes of the data, with $\lambda_k$ the $1/I_k$ less their mean. Adding a Casimir Hessian
        that commutes with $A$ moves no axis, so the axes are identified where the $1/I_k$ differ."""
        values, vectors = np.linalg.eigh(self.identifiable())
        if np.linalg.det(vectors) < 0:  # right-handed: a rotation from the data's axes
            vectors[:, -1] = -vectors[:, -1]
        return PrincipalAxes(values, vectors)

    def diagonal_differences(self) -> np.ndarray:
        r"""$A_{ii} - A_{jj}$ for $i < j$ (row-major order): for the rigid body, the identified
        $1/I_i - 1/I_j$."""
        d = np.diag(self.matrix)
        i, j = np.triu_indices(d.size, 1)
        return d[i] - d[j]


@dataclasses.dataclass(frozen=True)
class PrincipalAxes:
    r"""`values` $\lambda_k$ (ascending) and `axes` (the columns $v_k$, a rotation matrix) of a
    symmetric matrix."""

    values: np.ndarray
    axes: np.ndarray

    def rotation_vector(self) -> np.ndarray:
        r"""The rotation vector (radians) of the least rotation that turns the data's axes onto
        the principal axes (dimension 3): each axis is a line, so of the four right-handed
        choices of the axes' signs the one of least angle (the same vector for every sign an
        eigen-solver returns, so resampled fits compare). The axes' order is a convention
        (ascending $\lambda$); `angles_to` compares axes without order or sign."""
        if self.axes.shape != (3, 3):
            raise ValueError(f"a rotation vector needs 3 axes; these are {self.axes.shape[0]}")
        axes = self.axes if np.linalg.det(self.axes) > 0 else self.axes * np.array([1.0, 1.0, -1.0])
        candidates = [Rotation.from_matrix(axes * np.asarray(signs, dtype=np.float64)).as_rotvec()
                      for signs in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))]
        return min(candidates, key=lambda v: float(np.linalg.norm(v)))

    def angles_to(self, axes: ArrayLike) -> np.ndarray:
        r"""The angle (radians) between each axis and the column of `axes` in the same place,
        as lines (a sign flip is no error): $\arccos|v_k\cdot w_k|$."""
        other = np.asarray(axes, dtype=np.float64)
        if other.shape != self.axes.shape:
            raise ValueError(f"axes must have shape {self.axes.shape}; got {other.shape}")
        cosines = np.abs(np.sum(self.axes * other, axis=0)) / np.linalg.norm(other, axis=0)
        return np.arccos(np.clip(cosines, 0.0, 1.0))


def project_out(matrix: np.ndarray, hessians: np.ndarray) -> np.ndarray:
    """`matrix` minus its Frobenius projection onto the span of `hessians` `(k, n, n)`."""
    if hessians.shape[0] == 0:
        return matrix.copy()
    basis = hessians.reshape(hessians.shape[0], -1).T
    coefficients, *_ = np.linalg.lstsq(basis, matrix.reshape(-1), rcond=None)
    return matrix - (basis @ coefficients).reshape(matrix.shape)


def quadratic_casimir_hessians(system: AbstractPoissonSystem, samples: np.ndarray) -> np.ndarray:
    """The Hessians `(k, dim, dim)` of the Casimirs that are quadratic (the same Hessian at
    every sample, to round-off)."""
    if not system.n_casimirs:
        return np.zeros((0, system.dim, system.dim))

    def casimir(k):
        return lambda y: jnp.reshape(system.casimirs(y), (-1,))[k]

    out = []
    for k in range(system.n_casimirs):
        hessian = jax.vmap(jax.hessian(casimir(k)))(jnp.asarray(samples[: min(len(samples), 8)]))
        hessian = np.asarray(hessian)
        constant = np.allclose(hessian, hessian[0], rtol=0, atol=1e-10 * max(1.0, float(np.max(np.abs(hessian)))))
        if constant and np.any(hessian[0]):
            out.append(hessian[0])
    return np.asarray(out).reshape(-1, system.dim, system.dim)


#: Relative size (to the largest) below which a singular value of the column-scaled feature
#: matrix counts as zero: the samples satisfy a quadratic relation to that accuracy.
_RANK_RTOL = 1e-8


def _check_samples(samples: ArrayLike, dim: int) -> np.ndarray:
    """`samples` as a finite float64 `(N, dim)` array; `TypeError`/`ValueError` naming `samples`."""
    if isinstance(samples, (str, bytes)) or samples is None:
        raise TypeError(f"samples must be an array of states (N, {dim}); got {type(samples).__name__}")
    try:
        raw = np.asarray(samples)
    except (TypeError, ValueError) as err:  # ragged lists
        raise TypeError(f"samples must be an array of states (N, {dim}); got {type(samples).__name__} that is "
                        f"not one array ({err})") from None
    if raw.ndim != 2 or raw.shape[1] != dim:
        raise ValueError(f"samples must have shape (N, {dim}); got {raw.shape}")
    return states(raw, "samples", dim)


def _feature_rank(features: np.ndarray, casimir_hessians: np.ndarray) -> tuple[int, int, np.ndarray]:
    r"""The numerical rank of `features` (its columns scaled to unit norm), the number of
    independent relations $\sum_k \lambda_k C_k(y) + c = 0$ the samples satisfy (samples on
    one leaf of the quadratic Casimirs $C_k = \tfrac12 y^T Q_k y$), and the column scales."""
    scale = np.linalg.norm(features, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    scaled = features / scale
    singular = np.linalg.svd(scaled, compute_uv=False)
    cutoff = _RANK_RTOL * singular[0]
    rank = int(np.sum(singular > cutoff))
    # The directions (A = sum_k lambda_k Q_k, b = 0, c) in the scaled coordinates.
    n = casimir_hessians.shape[-1]
    i, j = np.triu_indices(n)
    directions = np.zeros((features.shape[1], casimir_hessians.shape[0] + 1))
    directions[: i.size, :-1] = casimir_hessians[:, i, j].T
    directions[-1, -1] = 1.0
    basis, _ = np.linalg.qr(scale[:, None] * directions)
    on_leaves = np.linalg.svd(scaled @ basis, compute_uv=False)
    casimir_relations = int(np.sum(on_leaves <= cutoff))
    return rank, casimir_relations, scale


def quadratic_part(hamiltonian: Callable[[np.ndarray], ArrayLike], system: AbstractPoissonSystem,
                   samples: ArrayLike) -> QuadraticPart:
    r"""The least-squares quadratic of `hamiltonian` (a function of states `(N, dim)` to
    `(N,)`, e.g. `gnet.hamiltonian`) over `samples` `(N, dim)` (e.g. the observed states: the
    region the data cover), with the system's quadratic Casimirs for `identifiable`.

    The samples must determine a quadratic in `dim` variables up to the system's quadratic
    Casimirs: samples on one Casimir leaf (all $|\Pi| = 1$) are fine, since $A$ is identified
    only modulo $\operatorname{span}\{Q_k\}$ anyway (the fit is then the minimum-norm one and
    `identifiable` is unchanged); samples on any other quadric (one energy level, one
    repeated state) are refused with a `ValueError`.
    """
    if not callable(hamiltonian):
        raise TypeError(f"hamiltonian must be a function of states (N, dim) -> (N,), e.g. gnet.hamiltonian; "
                        f"got {type(hamiltonian).__name__} {hamiltonian!r}")
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be a liepoisson.systems.AbstractPoissonSystem (e.g. RigidBody(...)), whose "
                        f"Casimirs say what is identified; got {type(system).__name__} {system!r}")
    y = _check_samples(samples, system.dim)
    n = system.dim
    i, j = np.triu_indices(n)
    n_features = i.size + n + 1
    if y.shape[0] < n_features:
        raise ValueError(f"a quadratic in {n} variables has {n_features} coefficients; give at least that many samples "
                         f"(got {y.shape[0]})")
    # 1/2 y^T A y = sum_i A_ii y_i^2 / 2 + sum_{i<j} A_ij y_i y_j
    weight = np.where(i == j, 0.5, 1.0)
    features = np.concatenate([weight * y[:, i] * y[:, j], y, np.ones((y.shape[0], 1))], axis=1)
    hessians = quadratic_casimir_hessians(system, y)
    rank, casimir_relations, scale = _feature_rank(features, hessians)
    if n_features - rank > casimir_relations:
        open_ = n_features - rank
        raise ValueError(
            f"samples do not determine a quadratic in {n} variables ({n_features} coefficients): the rank of their "
            f"quadratic features is {rank} (relative tolerance {_RANK_RTOL:g}), so {open_} combinations of the "
            f"coefficients are left open, and the system's Casimirs explain only {casimir_relations} of them (samples "
            f"on one Casimir leaf); the {y.shape[0]} samples lie on another quadric (e.g. one energy level, or the "
            f"same state repeated). Give samples whose features have rank at least {n_features - casimir_relations}, "
            f"e.g. the states of several trajectories at different energies"
        )
    try:
        values = np.asarray(hamiltonian(y))
    except (TypeError, ValueError) as err:
        raise TypeError(f"hamiltonian(samples) must return one real value per sample; calling it raised "
                        f"{type(err).__name__}: {err}") from err
    if values.dtype == object or not np.issubdtype(values.dtype, np.number) or np.iscomplexobj(values):
        raise TypeError(f"hamiltonian(samples) must return one real value per sample; got dtype {values.dtype}")
    values = values.astype(np.float64).reshape(-1)
    if values.shape != (y.shape[0],) or not np.all(np.isfinite(values)):
        raise ValueError(f"hamiltonian(samples) must return one finite value per sample ({y.shape[0]}); got "
                         f"{values.size} values, {int(np.sum(~np.isfinite(values)))} of them not finite")
    # In the scaled coordinates, cut at the tolerance of the rank: the directions the samples
    # leave open (the Casimir relations only) get the minimum-norm coefficient.
    scaled_coefficients, *_ = np.linalg.lstsq(features / scale, values, rcond=_RANK_RTOL)
    coefficients = scaled_coefficients / scale
    A = np.zeros((n, n))
    A[i, j] = coefficients[: i.size]
    A[j, i] = coefficients[: i.size]
    spread = float(np.sqrt(np.mean((values - values.mean()) ** 2)))
    residual = float(np.sqrt(np.mean((features @ coefficients - values) ** 2))) / max(spread, np.finfo(float).tiny)
    return QuadraticPart(A, coefficients[i.size : i.size + n], float(coefficients[-1]), residual, hessians)
