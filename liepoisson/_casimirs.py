r"""Automatic polynomial Casimirs of a Lie-Poisson bracket.

A polynomial $P$ is a Casimir iff $\{\mu_a, P\} = 0$ for every coordinate, i.e.
$\sum_{b,d} C_{abd}\,\mu_d\,\partial_b P(\mu) = 0$. For homogeneous $P$ of degree $k$ this is a
linear condition on its coefficients; the Lie-Poisson bracket preserves degree, so Casimirs can
be sought degree by degree. Products of Casimirs already found are projected out, and a
candidate is kept only if it is functionally independent of the ones kept (rank of the stacked
gradients at random points), stopping when their number reaches the generic corank of
$\mathbb{B}(\mu)$.
"""

from __future__ import annotations

import itertools

import numpy as np

from ._polynomial import Polynomial

# Null-space threshold relative to the largest singular value: the condition matrices have
# entries that are small integer multiples of the structure constants, so genuine null
# vectors sit at O(eps) and spurious ones far above 1e-9.
_NULL_TOL = 1e-9


def _monomials(n: int, k: int) -> list[tuple[int, ...]]:
    out = []
    for combo in itertools.combinations_with_replacement(range(n), k):
        e = [0] * n
        for i in combo:
            e[i] += 1
        out.append(tuple(e))
    return out


def _condition_matrix(C: np.ndarray, monomials: list[tuple[int, ...]]) -> np.ndarray:
    n = C.shape[0]
    index = {m: j for j, m in enumerate(monomials)}
    rows = n * len(monomials)
    A = np.zeros((rows, len(monomials)))
    nz = np.argwhere(C != 0.0)
    for j, m in enumerate(monomials):
        for a, b, d in nz:
            if m[b] == 0:
                continue
            e = list(m)
            e[b] -= 1
            e[d] += 1
            A[a * len(monomials) + index[tuple(e)], j] += m[b] * C[a, b, d]
    return A


def _null_space(A: np.ndarray) -> np.ndarray:
    if A.size == 0:
        return np.eye(A.shape[1])
    _, s, vt = np.linalg.svd(A)
    smax = s[0] if s.size else 0.0
    rank = int(np.sum(s > _NULL_TOL * max(smax, 1.0)))
    return vt[rank:].T


def _rref(N: np.ndarray) -> np.ndarray:
    """Reduced row echelon form of the rows of N.T: the cleanest basis of the null space."""
    R = N.T.copy()
    rows, cols = R.shape
    r = 0
    for c in range(cols):
        if r == rows:
            break
        p = r + int(np.argmax(np.abs(R[r:, c])))
        if abs(R[p, c]) < 1e-10:
            continue
        R[[r, p]] = R[[p, r]]
        R[r] /= R[r, c]
        for i in range(rows):
            if i != r:
                R[i] -= R[i, c] * R[r]
        r += 1
    R[np.abs(R) < 1e-12] = 0.0
    return R[:r]


def _gradient_rank(polys: list[Polynomial], points: np.ndarray) -> int:
    if not polys:
        return 0
    ranks = []
    for mu in points:
        G = np.array([[float(g.evaluate(mu)) for g in p.gradient()] for p in polys])
        s = np.linalg.svd(G, compute_uv=False)
        ranks.append(int(np.sum(s > 1e-8 * max(s[0], 1e-300))))
    return max(ranks)


def generic_corank(C: np.ndarray, rng: np.random.Generator | None = None) -> int:
    """$n - \\max_\\mu \\operatorname{rank}\\mathbb{B}(\\mu)$ at random points."""
    rng = np.random.default_rng(0) if rng is None else rng
    n = C.shape[0]
    best = 0
    for mu in rng.standard_normal((5, n)):
        B = np.einsum("abd,d->ab", C, mu)
        s = np.linalg.svd(B, compute_uv=False)
        best = max(best, int(np.sum(s > 1e-9 * max(s[0], 1.0))))
    return n - best


def polynomial_casimirs(C: np.ndarray, max_degree: int = 4) -> tuple[Polynomial, ...]:
    """A functionally independent basis of polynomial Casimirs up to `max_degree`.

    Returns an empty tuple for an algebra without polynomial Casimirs (e.g. the affine
    algebra $[e_1, e_2] = e_2$).
    """
    C = np.asarray(C, dtype=np.float64)
    n = C.shape[0]
    rng = np.random.default_rng(12345)
    target = generic_corank(C, rng)
    points = rng.standard_normal((3, n))
    found: list[Polynomial] = []
    if target == 0:
        return ()
    for k in range(1, max_degree + 1):
        monomials = _monomials(n, k)
        N = _null_space(_condition_matrix(C, monomials))
        if N.shape[1] == 0:
            continue
        # Project out products of lower-degree Casimirs of total degree k.
        products = []
        for r in range(2, k + 1):
            for combo in itertools.combinations_with_replacement(found, r):
                if sum(p.degree for p in combo) == k:
                    prod = combo[0]
                    for q in combo[1:]:
                        prod = prod * q
                    products.append(prod)
        if products:
            index = {m: j for j, m in enumerate(monomials)}
            P = np.zeros((len(monomials), len(products)))
            for j, prod in enumerate(products):
                for c, e in prod.terms:
                    P[index[e], j] += c
            Q, s, _ = np.linalg.svd(P, full_matrices=False)
            Q = Q[:, s > 1e-10 * s[0]]
            N = N - Q @ (Q.T @ N)
            u, s, _ = np.linalg.svd(N, full_matrices=False)
            N = u[:, s > 1e-8]
            if N.shape[1] == 0:
                continue
        for coeffs in _rref(N):
            cand = Polynomial.from_coefficients(n, monomials, coeffs)
            if _gradient_rank(found + [cand], points) > len(found):
                found.append(cand)
            if len(found) == target:
                return tuple(found)
    return tuple(found)
