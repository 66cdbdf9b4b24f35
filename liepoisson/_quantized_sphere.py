r"""The quantized sphere: the Hoppe-Yau Laplacian on u(N), its inverse, and the map between
real spherical-harmonic coefficients and skew-Hermitian matrices (Zeitlin's model).

Conventions follow the `quflow` code of Modin and Viviani (0-based indices, $s = (N-1)/2$):

- $\Delta_N W = \sum_a [S_a, [S_a, W]]$ with the skew-Hermitian spin-$s$ generators $S_a$
  ($[S_1, S_2] = S_3$, cyclic; $-\sum_a [L_a, [L_a, W]]$ for Hermitian ones); entrywise
  $(\Delta_N W)_{ij} = d_{ij}W_{ij} + c_{ij}W_{i-1,j-1} + c_{i+1,j+1}W_{i+1,j+1}$,
  $d_{ij} = -[(N-1)(i+j+1) - 2ij]$, $c_{ij} = \sqrt{i(N-i)\,j(N-j)}$: each diagonal of $W$ is
  transformed by its own symmetric tridiagonal matrix. Spectrum $-l(l+1)$, $l = 0..N-1$, with
  multiplicity $2l+1$ (the continuum's); kernel the multiples of the identity.
- $P = \Delta_N^{-1}W$ is the traceless solution of $\Delta_N P = W - (\mathrm{tr}\,W/N)\,1$,
  one tridiagonal solve per diagonal: $O(N^2)$.
- A field $\omega = \sum_{lm}\omega_{lm}Y^r_{lm}$ (real harmonics, $l < N$) is the matrix
  $W = \sum_{lm}\omega_{lm}T_{lm}$ with $\|T_{lm}\|_F^2 = N$; $T_{lm}$ on the $|m|$-th diagonals,
  built from the eigenvectors of that diagonal's tridiagonal block.
"""

from __future__ import annotations

import functools
import itertools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.special


def hbar(N: int) -> float:
    r"""$\hbar = 2/\sqrt{N^2 - 1}$: $\dot W = [P, W]/\hbar$ in physical time, independent of $N$."""
    return 2.0 / math.sqrt(N * N - 1)


def _diagonal_coefficients(N: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """`(b, a)` of the m-th diagonal's block: main entries b_k and couplings a_k (k to k-1, a_0 = 0),
    k = 0..N-m-1."""
    k = np.arange(N - m, dtype=np.float64)
    b = -((N - 1) * (2 * k + m + 1) - 2 * k * (k + m))
    a = np.sqrt(k * (N - k) * (k + m) * (N - k - m))
    return b, a


@functools.cache
def _solver_arrays(N: int) -> tuple[np.ndarray, ...]:
    """The N upper diagonals of an N x N matrix as one tridiagonal system of N(N+1)/2
    unknowns, the blocks uncoupled (one solve is faster than N small ones: benchmarks,
    "Zeitlin's model"): `(rows, cols, dl, d, du, first)`, `first` the position of the m = 0
    block's first unknown (0)."""
    rows, cols, dl, d, du = [], [], [], [], []
    for m in range(N):
        n = N - m
        b, a = _diagonal_coefficients(N, m)
        if m == 0:
            b = b.copy()
            b[0] -= 0.5  # quflow's regularisation of the singular m = 0 block (its kernel: constants)
        rows.append(np.arange(n))
        cols.append(np.arange(n) + m)
        d.append(b)
        dl.append(a)  # a_0 = 0: no coupling to the previous block
        du.append(np.append(a[1:], 0.0))  # none to the next
    return tuple(np.concatenate(x) for x in (rows, cols, dl, d, du))


@jax.jit
def laplacian(W: jax.Array) -> jax.Array:
    r"""$\Delta_N W$ for `W` `(..., N, N)` (any complex matrices), entrywise in $O(N^2)$."""
    W = jnp.asarray(W)
    N = W.shape[-1]
    i = np.arange(N, dtype=np.float64)
    d = -((N - 1) * (i[:, None] + i[None, :] + 1) - 2 * i[:, None] * i[None, :])
    c = np.sqrt(i[:, None] * (N - i[:, None]) * i[None, :] * (N - i[None, :]))  # c_ij
    pad = [(0, 0)] * (W.ndim - 2) + [(1, 1), (1, 1)]
    Wp = jnp.pad(W, pad)
    cp = np.pad(c, 1)
    before = Wp[..., :-2, :-2]  # W_{i-1, j-1}
    after = Wp[..., 2:, 2:]  # W_{i+1, j+1}
    return d * W + c * before + cp[2:, 2:] * after


@jax.jit
def solve_poisson(W: jax.Array) -> jax.Array:
    r"""$P = \Delta_N^{-1}W$ for skew-Hermitian `W` `(N, N)`: the traceless $P$ with
    $\Delta_N P = W - (\mathrm{tr}\,W/N)\,1$ (one tridiagonal solve per upper diagonal, real
    and imaginary parts as two right-hand sides; the lower diagonals by skew-Hermitian symmetry)."""
    W = jnp.asarray(W)
    N = W.shape[-1]
    rows, cols, dl, d, du = _solver_arrays(N)
    W = W - (jnp.trace(W) / N) * jnp.eye(N, dtype=W.dtype)
    rhs = W[rows, cols]  # the upper diagonals, m = 0 first
    rhs = jnp.stack([jnp.real(rhs), jnp.imag(rhs)], axis=-1)  # (N(N+1)/2, 2)
    x = jax.lax.linalg.tridiagonal_solve(jnp.asarray(dl), jnp.asarray(d), jnp.asarray(du), rhs)
    x = x[..., 0] + 1j * x[..., 1]
    x = x.at[:N].add(-jnp.sum(x[:N]) / N)  # traceless (the m = 0 block is the main diagonal)
    U = jnp.zeros((N, N), dtype=jnp.complex128).at[rows, cols].set(x)
    strict = jnp.triu(U, 1)
    return U - jnp.conj(strict.T)


# -- spherical harmonics --------------------------------------------------------------------------
@functools.cache
def harmonic_basis(N: int) -> tuple[np.ndarray, ...]:
    r"""For each $m = 0..N-1$: the `(N - m, N - m)` matrix whose column $l - m$ is
    $v^{(l,m)}$, $l = m..N-1$, the eigenvector of the m-th diagonal's block for $-l(l+1)$,
    scaled to $|v|^2 = N$, the sign of its last component $(-1)^m$ (quflow's `compute_basis`)."""
    out = []
    for m in range(N):
        b, a = _diagonal_coefficients(N, m)
        if N - m == 1:
            V = np.ones((1, 1))
        else:
            _, V = scipy.linalg.eigh_tridiagonal(b, a[1:])
        V = V[:, ::-1] * math.sqrt(N)  # eigenvalues ascending -> l descending; reversed: l = m..N-1
        sign = np.sign(V[-1]) * (-1) ** m
        out.append(V * np.where(sign == 0, 1.0, sign))
    return tuple(out)


def harmonics_to_matrix(omega: np.ndarray, N: int) -> np.ndarray:
    r"""$W = \sum_{lm}\omega_{lm}T_{lm}$ from real coefficients `omega` `(N^2,)`, index
    $l^2 + l + m$ (quflow's `shr2mat`)."""
    omega = np.asarray(omega, dtype=np.float64)
    if omega.shape != (N * N,):
        raise ValueError(f"omega must hold the N^2 = {N * N} real coefficients omega_lm, l < N; got shape {omega.shape}")
    basis = harmonic_basis(N)
    W = np.zeros((N, N), dtype=np.complex128)
    ls = np.arange(N)
    W[np.diag_indices(N)] = 1j * (basis[0] @ omega[ls * ls + ls])
    for m in range(1, N):
        lm = np.arange(m, N)
        c = (omega[lm * lm + lm + m] - 1j * omega[lm * lm + lm - m]) / math.sqrt(2.0)
        dvec = (-1) ** m * (basis[m] @ c)
        k = np.arange(N - m)
        W[k, k + m] = 1j * dvec
        W[k + m, k] = 1j * np.conj(dvec)
    return W


def matrix_to_harmonics(W: np.ndarray) -> np.ndarray:
    r"""The real coefficients $\omega_{lm}$ `(N^2,)` of a skew-Hermitian `W` (quflow's
    `mat2shr`), the inverse of `harmonics_to_matrix`."""
    W = np.asarray(W)
    N = W.shape[-1]
    basis = harmonic_basis(N)
    omega = np.zeros(N * N)
    ls = np.arange(N)
    omega[ls * ls + ls] = np.real(basis[0].T @ np.diag(W) / 1j) / N
    for m in range(1, N):
        k = np.arange(N - m)
        z = basis[m].T @ W[k + m, k]
        lm = np.arange(m, N)
        omega[lm * lm + lm + m] = math.sqrt(2.0) * (-1) ** m * np.imag(z) / N
        omega[lm * lm + lm - m] = -math.sqrt(2.0) * (-1) ** m * np.real(z) / N
    return omega


def vorticity_on_grid(W: np.ndarray, n_theta: int | None = None, n_phi: int | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""The vorticity field $\omega(\theta, \phi) = \sqrt{4\pi}\sum_{lm}\omega_{lm}Y^r_{lm}$ of
    `W` on a grid: `(theta, phi, values)`, $\theta$ the colatitude (`n_theta` points, default
    $2N$), $\phi \in [0, 2\pi)$ (`n_phi`, default $4N$); real harmonics from scipy's complex
    ones with quflow's signs ($Y^r_{l,-m} = -\sqrt2(-1)^m\,\mathrm{Im}\,Y_l^m$)."""
    W = np.asarray(W)
    N = W.shape[-1]
    omega = matrix_to_harmonics(W)
    n_theta = 2 * N if n_theta is None else int(n_theta)
    n_phi = 4 * N if n_phi is None else int(n_phi)
    theta = (np.arange(n_theta) + 0.5) * np.pi / n_theta
    phi = np.arange(n_phi) * 2 * np.pi / n_phi
    T, F = np.meshgrid(theta, phi, indexing="ij")
    f = np.zeros_like(T)
    for l in range(N):
        for m in range(l + 1):
            Y = scipy.special.sph_harm_y(l, m, T, F)
            if m == 0:
                f += omega[l * l + l] * Y.real
            else:
                f += omega[l * l + l + m] * math.sqrt(2.0) * (-1) ** m * Y.real
                f += omega[l * l + l - m] * (-math.sqrt(2.0)) * (-1) ** m * Y.imag
    return theta, phi, math.sqrt(4 * np.pi) * f


# -- operators diagonal in the spherical harmonics ------------------------------------------------
#: The diagonals $m$ of `harmonic_multiplier` fall in this many groups of consecutive $m$, each
#: padded to its largest block ($N - m$ at its first $m$) rather than all to $N$: each way a call
#: reads $\approx 0.47 N^3$ numbers of basis (two stored copies, $0.94 N^3$ in all), where the
#: former four products read $N^3$ each (they are bound by that reading; BENCHMARKS.md, "Fluids
#: from data").
MULTIPLIER_GROUPS = 4


@functools.cache
def _multiplier_arrays(N: int) -> tuple[Any, ...]:
    r"""The arrays of `harmonic_multiplier` at size N, padded to `(N, N)` per diagonal $m$:
    `rows`, `cols` (entry $k$ of the m-th upper diagonal, $(k, k + m)$; padding at (0, 0)),
    `valid` (k < N - m), `sign` $(-1)^m$, the harmonic indices `plus` $l^2 + l + m$ and
    `minus` $l^2 + l - m$ of column $j$ ($l = m + j$; 0 where $l \ge N$), and `groups`: for
    each group of diagonals $m = a..b-1$ (`MULTIPLIER_GROUPS`), `(a, b, basis, transposed)`
    with `basis` `(b - a, N - a, N - a)` holding `harmonic_basis(N)[m]` in its top-left corner,
    zeros elsewhere, and `transposed` each of its blocks transposed (both ways a plain batched
    product)."""
    m = np.arange(N)[:, None]
    k = np.arange(N)[None, :]
    valid = k < N - m
    rows = np.where(valid, k, 0)
    cols = np.where(valid, k + m, 0)
    blocks = harmonic_basis(N)
    edges = sorted({round(N * i / MULTIPLIER_GROUPS) for i in range(MULTIPLIER_GROUPS + 1)})
    groups = []
    for a, b in itertools.pairwise(edges):
        basis = np.zeros((b - a, N - a, N - a))
        for mm in range(a, b):
            basis[mm - a, : N - mm, : N - mm] = blocks[mm]
        groups.append((a, b, basis, np.ascontiguousarray(basis.transpose(0, 2, 1))))
    l = m + k  # column j = k of diagonal m is degree l = m + j
    plus = np.where(valid, l * l + l + m, 0)
    minus = np.where(valid, l * l + l - m, 0)
    sign = (-1.0) ** np.arange(N)
    return rows, cols, valid, sign, plus, minus, tuple(groups)


def harmonic_multiplier(W: jax.Array, multiplier: jax.Array) -> jax.Array:
    r"""$\sum_{lm}\mu_{lm}\,\omega_{lm}T_{lm}$ for skew-Hermitian `W` `(N, N)` $= \sum_{lm}
    \omega_{lm}T_{lm}$ and real `multiplier` $\mu$ `(N^2,)` (index $l^2 + l + m$): the operator
    diagonal in the quantized spherical harmonics with eigenvalue $\mu_{lm}$ (JAX, traceable
    and differentiable in both arguments). $\mu_{lm} = -1/(l(l+1))$, $\mu_{00} = 0$ is
    $\Delta_N^{-1}$ (`solve_poisson`).

    Each upper diagonal $m$ of $W$ is $i(-1)^m V_m c$ with $V_m$ the m-th block's eigenvectors
    (`harmonic_basis`, $V_m^\top V_m = N\,1$) and $c_l = (\omega_{l,m} - i\,\omega_{l,-m})/\sqrt2$
    (`harmonics_to_matrix`): $c = -i(-1)^m V_m^\top d_m/N$, its real part scaled by
    $\mu_{l,m}$ and its imaginary part by $\mu_{l,-m}$, and back; the lower diagonals by
    skew-Hermitian symmetry. One batched product each way per group of diagonals
    (`MULTIPLIER_GROUPS`), the real and imaginary parts two right-hand sides of it: each basis
    read once a way, no matrix larger than $N\times N$ per diagonal."""
    W = jnp.asarray(W)
    N = W.shape[-1]
    rows, cols, valid, sign, plus, minus, groups = _multiplier_arrays(N)
    multiplier = jnp.asarray(multiplier)
    d = jnp.where(valid, W[rows, cols], 0.0)  # (N m, N k): the upper diagonals
    d = jnp.stack([jnp.real(d), jnp.imag(d)], axis=-1)
    mu_plus = jnp.where(valid, multiplier[plus], 0.0)
    mu_minus = jnp.where(valid, multiplier[minus], 0.0)
    parts = []
    for a, b, basis, transposed in groups:
        n = N - a
        z = jnp.einsum("mjk,mkc->mjc", transposed, d[a:b, :n])  # V^T d: real, imaginary
        # c = -i (-1)^m z / N: Re c = (-1)^m Im z / N, Im c = -(-1)^m Re z / N; scaled to c',
        # stacked (Im c', Re c'): the order the product back needs
        s = sign[a:b, None] / N
        c = jnp.stack([-s * z[..., 0] * mu_minus[a:b, :n], s * z[..., 1] * mu_plus[a:b, :n]], axis=-1)
        # d' = i (-1)^m V c': Re d' = -(-1)^m V Im c', Im d' = (-1)^m V Re c'
        out = jnp.einsum("mkj,mjc->mkc", basis, c)
        parts.append(jnp.pad(out, ((0, 0), (0, N - n), (0, 0))))
    out = jnp.concatenate(parts, axis=0)
    out = jax.lax.complex(-sign[:, None] * out[..., 0], sign[:, None] * out[..., 1])
    U = jnp.zeros((N, N), dtype=jnp.complex128).at[rows[valid], cols[valid]].set(out[valid])
    strict = jnp.triu(U, 1)
    return U - jnp.conj(strict.T)
