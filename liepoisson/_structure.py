r"""Validation of structure constants and the generic corank of the Lie-Poisson tensor.

Conventions: $[e_a, e_b] = C_{abd}\,e_d$. The Jacobi identity is checked without forming the
$n^4$ Jacobiator tensor (10 GB for so(20)): its trilinear form is evaluated on a few seeded
random vectors in $O(n^3)$, and only when that fails is the tensor searched, in slices of
$O(n^3)$ memory, for the largest violation to name in the message.
"""

from __future__ import annotations

from typing import Any

import numpy as np

# Structure constants given as floats (e.g. computed ones) may carry round-off: accept
# violations of antisymmetry and Jacobi up to 1e-10 relative to the size of the constants.
_STRUCTURE_RTOL = 1e-10

# Random triples (x, y, z) on which the Jacobiator is evaluated; seeded, so a given C is
# always accepted or rejected alike.
_JACOBI_PROBES = 3
_JACOBI_SEED = 20240043
# Entries of one slice J[a0:a1] of the Jacobiator searched at a time (x 8 bytes, x ~4 arrays):
# at least one slice a (n^3 entries), more when they fit, for fewer BLAS calls.
_JACOBI_SLICE_ENTRIES = 1 << 20
# Entries of J within this relative distance of the largest count as tied with it (round-off).
_TIE_RTOL = 1e-9


def check_structure_constants(C: Any) -> np.ndarray:
    r"""`C` as a read-only float64 array `(n, n, n)`, checked: real, finite, antisymmetric
    $C_{abd} = -C_{bad}$ and satisfying Jacobi,
    $J_{abce} = C_{abd}C_{dce} + C_{bcd}C_{dae} + C_{cad}C_{dbe} = 0$,
    both up to `_STRUCTURE_RTOL` relative to $\max(1, \max|C|)$ (squared for Jacobi).

    `TypeError` for a non-real or non-array input, `ValueError` naming the largest violation.
    """
    what = f"{type(C).__name__} {C!r}"
    try:
        if isinstance(C, (str, bytes)) or C is None:
            raise TypeError
        if np.iscomplexobj(C):
            what = f"complex {type(C).__name__} of dtype {np.asarray(C).dtype}"
            raise TypeError
        C = np.asarray(C, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"structure_constants must be a real array of shape (n, n, n); got {what}") from err
    if C.ndim != 3 or not (C.shape[0] == C.shape[1] == C.shape[2]) or C.shape[0] == 0:
        raise ValueError(f"structure_constants must have shape (n, n, n) with n >= 1; got {C.shape}")
    if not np.all(np.isfinite(C)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(C))[0])
        raise ValueError(f"structure_constants must be finite; found {C[bad]} at (a, b, d) = {bad}")
    scale = max(1.0, float(np.max(np.abs(C))))
    sym = C + C.transpose(1, 0, 2)
    if np.max(np.abs(sym)) > _STRUCTURE_RTOL * scale:
        idx = tuple(int(i) for i in np.unravel_index(np.argmax(np.abs(sym)), sym.shape))
        raise ValueError(
            "structure_constants must be antisymmetric, C[a, b, d] = -C[b, a, d]; the largest "
            f"violation is {np.abs(sym)[idx]:.3g} at (a, b, d) = {idx}"
        )
    tol = _STRUCTURE_RTOL * scale * scale
    if not _jacobiator_small_on_probes(C, tol):
        # Invalid input (or a violation just above tol): the entrywise criterion of the full
        # tensor decides, so nothing it accepts is rejected, and names the largest violation.
        worst, idx = _largest_jacobi_violation(C)
        if worst > tol:
            raise ValueError(
                "structure_constants must satisfy the Jacobi identity; the largest violation is "
                f"{worst:.3g} at (a, b, c) = {idx[:3]} (component {idx[3]})"
            )
    C = C.copy()
    C.setflags(write=False)
    return C


def _jacobiator_small_on_probes(C: np.ndarray, tol: float) -> bool:
    r"""$|J(x, y, z)|_\infty \le \mathrm{tol}\,|x|\,|y|\,|z|$ on seeded Gaussian triples, where
    $J(x, y, z) = [[x, y], z] + [[y, z], x] + [[z, x], y]$, i.e. $J(x,y,z)_e = J_{abce}x_ay_bz_c$.

    $O(n^3)$ per triple. Why the bound scales with $|x|\,|y|\,|z|$: for basis vectors it is
    the entrywise criterion $|J_{abce}| \le \mathrm{tol}$ of the full check, and $J$ is
    trilinear, so on any directions the same tolerance applies per unit length. Valid
    constants pass with a wide margin: their $J_{abce}$ are round-off, $\sim \epsilon n
    \max|C|^2$, and $J(x, y, z)_e$ sums $n^3$ of them with random signs, $\sim \epsilon
    n^{5/2}\max|C|^2$ against $\mathrm{tol}\,|x||y||z| \approx 10^{-10} n^{3/2}\max|C|^2$
    (and the probe's own round-off is of the same order). A violation $v$ at one
    $(a, b, c)$ shows as $\approx v\,x_ay_bz_c$ (antisymmetrised, $O(1)$ for Gaussians), so it
    is caught from a few times $\mathrm{tol}\,n^{3/2}$ on; smaller ones (far below any error
    in writing down constants, far above round-off) may pass. When a probe fails, the
    entrywise criterion decides (`check_structure_constants`), so nothing it accepts is
    rejected.
    """
    n = C.shape[0]
    rng = np.random.default_rng(_JACOBI_SEED)
    X, Y, Z = rng.standard_normal((3, _JACOBI_PROBES, n))
    C2 = C.reshape(n, n * n)

    def bracket(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        # [u, v]_d = C_abd u_a v_b for each probe p: (p, n) x (n, n*n) -> (p, n, n), then b.
        return np.einsum("pbd,pb->pd", (u @ C2).reshape(-1, n, n), v)

    J = bracket(bracket(X, Y), Z) + bracket(bracket(Y, Z), X) + bracket(bracket(Z, X), Y)
    norms = np.linalg.norm(X, axis=1) * np.linalg.norm(Y, axis=1) * np.linalg.norm(Z, axis=1)
    return bool(np.all(np.max(np.abs(J), axis=1) <= tol * norms))


def _largest_jacobi_violation(C: np.ndarray) -> tuple[float, tuple[int, int, int, int]]:
    r"""$\max|J_{abce}|$ and where it is, over slices $J_{a_0:a_1}$ of at most
    `_JACOBI_SLICE_ENTRIES` entries (at least one $a$, $n^3$): memory $O(n^3)$, time $O(n^5)$.

    $J$ is totally antisymmetric in $(a, b, c)$, so its largest entry comes in six copies that
    differ only by round-off; the first in C order within `_TIE_RTOL` of the largest is named
    (the sorted triple), so the index does not depend on how the sums were ordered.
    """
    n = C.shape[0]
    step = max(1, _JACOBI_SLICE_ENTRIES // n**3)
    C_d = C.reshape(n, n * n)  # [d, (c e)]
    C_bc = C.reshape(n * n, n)  # [(b c), d]
    worst, where = -1.0, (0, 0, 0, 0)
    for a0 in range(0, n, step):
        a1 = min(n, a0 + step)
        k = a1 - a0
        Ca = C[a0:a1]  # [a, b, d]
        Cpa = C[:, a0:a1]  # [c, a, d] or [d, a, e]
        # C_abd C_dce: (a b, d) x (d, c e).
        J = (Ca.reshape(k * n, n) @ C_d).reshape(k, n, n, n)
        # C_bcd C_dae: (b c, d) x (d, a e) -> [b, c, a, e].
        J += (C_bc @ Cpa.reshape(n, k * n)).reshape(n, n, k, n).transpose(2, 0, 1, 3)
        # C_cad C_dbe: (c a, d) x (d, b e) -> [c, a, b, e].
        J += (Cpa.reshape(n * k, n) @ C_d).reshape(n, k, n, n).transpose(1, 2, 0, 3)
        A = np.abs(J)
        top = float(A.max())
        if top > worst * (1.0 + _TIE_RTOL):
            # The first entry of this slice tied with its largest; earlier slices are all
            # smaller, later ones replace it only when clearly larger.
            i = int(np.argmax(A >= top * (1.0 - _TIE_RTOL)))
            a, b, c, e = np.unravel_index(i, A.shape)
            worst, where = top, (int(a) + a0, int(b), int(c), int(e))
        worst = max(worst, top)
    return worst, where


def generic_corank(C: np.ndarray) -> int:
    r"""$n - \max_\mu \operatorname{rank} C_{abd}\mu_d$ over seeded random $\mu$: the number of
    independent Casimirs near a generic point."""
    mus = np.random.default_rng(0).normal(size=(4, C.shape[0]))
    best = 0
    for mu in mus:
        s = np.linalg.svd(C @ mu, compute_uv=False)  # (C mu)_ab = C_abd mu_d
        # relative 1e-9: constants carrying round-off (accepted up to 1e-10) keep their rank
        best = max(best, int(np.sum(s > 1e-9 * max(float(s[0]) if s.size else 0.0, 1.0))))
    return C.shape[0] - best
