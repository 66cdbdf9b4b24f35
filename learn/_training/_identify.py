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

    def diagonal_differences(self) -> np.ndarray:
        r"""$A_{ii} - A_{jj}$ for $i < j$ (row-major order): for the rigid body, the identified
        $1/I_i - 1/I_j$."""
        d = np.diag(self.matrix)
        i, j = np.triu_indices(d.size, 1)
        return d[i] - d[j]


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


def quadratic_part(hamiltonian: Callable[[np.ndarray], ArrayLike], system: AbstractPoissonSystem,
                   samples: ArrayLike) -> QuadraticPart:
    r"""The least-squares quadratic of `hamiltonian` (a function of states `(N, dim)` to
    `(N,)`, e.g. `gnet.hamiltonian`) over `samples` `(N, dim)` (e.g. the observed states: the
    region the data cover), with the system's quadratic Casimirs for `identifiable`."""
    y = np.asarray(samples, dtype=np.float64)
    if y.ndim != 2 or y.shape[1] != system.dim:
        raise ValueError(f"samples must have shape (N, {system.dim}); got {y.shape}")
    n = system.dim
    i, j = np.triu_indices(n)
    n_features = i.size + n + 1
    if y.shape[0] < n_features:
        raise ValueError(f"a quadratic in {n} variables has {n_features} coefficients; give at least that many samples "
                         f"(got {y.shape[0]})")
    values = np.asarray(hamiltonian(y), dtype=np.float64).reshape(-1)
    if values.shape != (y.shape[0],) or not np.all(np.isfinite(values)):
        raise ValueError("hamiltonian(samples) must return one finite value per sample")
    # 1/2 y^T A y = sum_i A_ii y_i^2 / 2 + sum_{i<j} A_ij y_i y_j
    weight = np.where(i == j, 0.5, 1.0)
    features = np.concatenate([weight * y[:, i] * y[:, j], y, np.ones((y.shape[0], 1))], axis=1)
    coefficients, *_ = np.linalg.lstsq(features, values, rcond=None)
    A = np.zeros((n, n))
    A[i, j] = coefficients[: i.size]
    A[j, i] = coefficients[: i.size]
    spread = float(np.sqrt(np.mean((values - values.mean()) ** 2)))
    residual = float(np.sqrt(np.mean((features @ coefficients - values) ** 2))) / max(spread, np.finfo(float).tiny)
    return QuadraticPart(A, coefficients[i.size : i.size + n], float(coefficients[-1]), residual,
                         quadratic_casimir_hessians(system, y))
