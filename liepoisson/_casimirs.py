r"""Automatic polynomial Casimirs of a Lie-Poisson bracket.

A polynomial $P$ is a Casimir iff $\{\mu_a, P\} = 0$ for every coordinate, i.e.
$\sum_{b,d} C_{abd}\,\mu_d\,\partial_b P(\mu) = 0$. For homogeneous $P$ of degree $k$ this is a
linear condition on its coefficients; the Lie-Poisson bracket preserves degree, so Casimirs can
be sought degree by degree. Products of Casimirs already found are projected out, and a
candidate is kept only if it is functionally independent of the ones kept (rank of the stacked
gradients at random points), stopping when their number reaches the generic corank of
$\mathbb{B}(\mu)$.

The conditions of degree $k$ form a sparse matrix ($n\binom{n+k-1}{k}$ rows, $\binom{n+k-1}{k}$
columns, $\binom{n+k-2}{k-1}$ entries per nonzero $C_{abd}$); its null space is computed block
by block (the connected components of its sparsity pattern, many small ones for the
constants of matrix bases). The search is for small algebras: before the work of a degree,
its memory and arithmetic are estimated and a `ValueError` says what to do instead when they
exceed `CASIMIR_SEARCH_MEMORY` or `CASIMIR_SEARCH_FLOPS`.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from threadpoolctl import threadpool_limits

from ._polynomial import Polynomial
from ._structure import generic_corank

# Null-space threshold relative to the largest singular value: the condition matrices have
# entries that are small integer multiples of the structure constants, so genuine null
# vectors sit at O(eps) and spurious ones far above 1e-9.
_NULL_TOL = 1e-9

# Budget of one degree of the search: bytes of the sparse conditions (before they are built)
# and of the largest dense block with its SVD factors.
CASIMIR_SEARCH_MEMORY = 500e6
# Budget of one degree's SVDs, sum over blocks of rows * columns * min(rows, columns): a few
# seconds on one core (BENCHMARKS.md, "Matrix Lie algebras": the Casimir search's budgets).
CASIMIR_SEARCH_FLOPS = 2e10

# Peak bytes per entry of the sparse conditions while they are built and split into blocks:
# row, column and value (24 B) in per-(a, b, d) pieces and concatenated, the CSR copy, its COO
# copy and the row-column graph; twice what tracemalloc measured (BENCHMARKS.md, "Matrix Lie
# algebras": the Casimir search's budgets).
_BYTES_PER_ENTRY = 128


def _rank_table(n: int, k: int) -> np.ndarray:
    r"""$F_{jx} = \sum_{v<x} \binom{n - v + r - 1}{r}$ with $r = k - j - 1$: the number of
    nondecreasing sequences in $[0, n)$ that have a value $v < x$ at position $j$ followed by
    $r$ values $\ge v$ (the continuations of a prefix, counted by `_rank`)."""
    F = np.zeros((k, n + 1), dtype=np.int64)
    for j in range(k):
        r = k - j - 1
        for x in range(1, n + 1):
            F[j, x] = F[j, x - 1] + math.comb(n - x + r, r)
    return F


def _rank(S: np.ndarray, F: np.ndarray) -> np.ndarray:
    r"""Index in `_monomials(n, k)` of the monomials $\mu_{s_1}\cdots\mu_{s_k}$, the rows of `S`
    ($s_1 \le \dots \le s_k$, any leading axes): their rank in the lexicographic order of
    `combinations_with_replacement`, $\sum_j F_{j, s_j} - F_{j, s_{j-1}}$ with $s_0 = 0$."""
    out = np.zeros(S.shape[:-1], dtype=np.int64)
    prev = np.zeros(S.shape[:-1], dtype=np.intp)
    for j in range(S.shape[-1]):
        out += F[j, S[..., j]] - F[j, prev]
        prev = S[..., j]
    return out


def _sorted_monomials(n: int, k: int) -> np.ndarray:
    """`(M, k)`: monomial $i$ of `_monomials(n, k)` as its sorted variable indices."""
    combos = list(itertools.combinations_with_replacement(range(n), k))
    return np.array(combos, dtype=np.intp).reshape(-1, k)


def _exponents(s: np.ndarray, n: int) -> tuple[int, ...]:
    return tuple(int(e) for e in np.bincount(s, minlength=n))


def _condition_matrix(C: np.ndarray, k: int, S: np.ndarray) -> scipy.sparse.csr_matrix:
    r"""The conditions $\{\mu_a, P\} = 0$ on the coefficients $p_j$ of a homogeneous $P$ of
    degree $k$ (monomials `S`): row $aM + i$ is the coefficient of monomial $i$ in
    $\sum_{b,d} C_{abd}\,\mu_d\,\partial_b P$. Monomial $m \ni \mu_b$ contributes $m_b C_{abd}$
    at $m - e_b + e_d$."""
    n = C.shape[0]
    M = S.shape[0]
    F = _rank_table(n, k)
    rows, cols, vals = [], [], []
    for b in range(n):
        ds = np.flatnonzero(np.any(C[:, b, :] != 0.0, axis=0))
        if ds.size == 0:
            continue
        hit = S == b
        js = np.flatnonzero(hit.any(axis=1))  # the monomials containing mu_b
        mult = hit[js].sum(axis=1).astype(np.float64)
        # Drop one mu_b (what remains of a sorted row stays sorted), then insert each mu_d.
        first = np.argmax(hit[js], axis=1)
        keep = np.ones((js.size, k), dtype=bool)
        keep[np.arange(js.size), first] = False
        rest = S[js][keep].reshape(js.size, k - 1)
        T = np.concatenate(
            [np.broadcast_to(rest[:, None, :], (js.size, ds.size, k - 1)),
             np.broadcast_to(ds[None, :, None], (js.size, ds.size, 1))],
            axis=2,
        )
        targets = _rank(np.sort(T, axis=2), F)  # (monomials with mu_b, ds)
        for i, d in enumerate(ds):
            for a in np.flatnonzero(C[:, b, d]):
                rows.append(a * M + targets[:, i])
                cols.append(js)
                vals.append(mult * C[a, b, d])
    if not rows:
        return scipy.sparse.csr_matrix((n * M, M))
    A = scipy.sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n * M, M)
    )  # duplicates summed, as the dense matrix accumulated them
    A.eliminate_zeros()  # sums that cancel must not join blocks
    return A


class _Block(NamedTuple):
    rows: np.ndarray  # rows of A (global)
    cols: np.ndarray  # columns of A (global)
    entries: tuple[np.ndarray, np.ndarray, np.ndarray]  # local row, local column, value

    def dense(self) -> np.ndarray:
        B = np.zeros((self.rows.size, self.cols.size))
        B[self.entries[0], self.entries[1]] = self.entries[2]  # unique: the CSR summed them
        return B


def _blocks(A: scipy.sparse.csr_matrix) -> list[_Block]:
    r"""The diagonal blocks of `A` up to permutation: the connected components of its bipartite
    row-column graph. A column without entries is a block of its own without rows.
    $\ker A$ is the direct sum of the blocks' null spaces; for the constants of matrix bases
    ($E_{ij} - E_{ji}$, ...) the conditions split into many small blocks (the bracket
    preserves a grading, e.g. the parities of the indices of so(N))."""
    used_rows = np.flatnonzero(np.diff(A.indptr))
    coo = A[used_rows].tocoo()  # rows without entries would be components of their own
    R, M = coo.shape
    graph = scipy.sparse.coo_matrix(
        (np.ones(coo.nnz, dtype=np.int8), (coo.row, R + coo.col)), shape=(R + M, R + M)
    )
    n_labels, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    # Group rows, columns and entries by label (every label has a column), and number the
    # rows and columns within their block.
    row_order = np.argsort(labels[:R], kind="stable")
    col_order = np.argsort(labels[R:], kind="stable")
    row_start = np.searchsorted(labels[row_order], np.arange(n_labels + 1))
    col_start = np.searchsorted(labels[R + col_order], np.arange(n_labels + 1))
    local = np.empty(R + M, dtype=np.intp)
    local[row_order] = np.arange(R) - row_start[labels[row_order]]
    local[R + col_order] = np.arange(M) - col_start[labels[R + col_order]]
    entry_labels = labels[R + coo.col]
    entry_order = np.argsort(entry_labels, kind="stable")
    entry_start = np.searchsorted(entry_labels[entry_order], np.arange(n_labels + 1))
    er, ec, ev = local[coo.row[entry_order]], local[R + coo.col[entry_order]], coo.data[entry_order]
    row_order = used_rows[row_order]
    blocks = []
    for lab in range(n_labels):
        e0, e1 = entry_start[lab], entry_start[lab + 1]
        cols = col_order[col_start[lab]:col_start[lab + 1]]
        if cols.size:
            blocks.append(_Block(row_order[row_start[lab]:row_start[lab + 1]], cols,
                                 (er[e0:e1], ec[e0:e1], ev[e0:e1])))
    return blocks


def _null_space(A: scipy.sparse.csr_matrix, blocks: list[_Block]) -> np.ndarray:
    r"""Orthonormal basis `(M, r)` of $\ker A$: the right singular vectors with
    $\sigma \le$ `_NULL_TOL` $\max(\sigma_{\max}(A), 1)$, block by block (as one SVD of $A$
    would give them). $\sigma_{\max}(A)$, the largest of the blocks', is known only at the
    end, so candidates are kept below the threshold of the bound
    $\sigma_{\max} \le \sqrt{\|A\|_1\|A\|_\infty}$ and filtered after."""
    M = A.shape[1]
    absA = abs(A)
    norm1 = np.max(np.asarray(absA.sum(axis=0)), initial=0.0)
    norm_inf = np.max(np.asarray(absA.sum(axis=1)), initial=0.0)
    loose = _NULL_TOL * max(float(np.sqrt(norm1 * norm_inf)), 1.0)
    smax = 0.0
    candidates: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (columns, sigma, V^T)
    # The blocks are small: OpenBLAS's threads cost more than they give on them (BENCHMARKS.md,
    # "Matrix Lie algebras": the Casimir search's budgets).
    with threadpool_limits(limits=1, user_api="blas"):
        for block in blocks:
            if block.rows.size == 0:
                candidates.append((block.cols, np.zeros(1), np.ones((1, 1))))
                continue
            B = block.dense()
            # All of V, without a U of rows^2 entries when the block is tall.
            _, s, vt = np.linalg.svd(B, full_matrices=B.shape[0] < B.shape[1])
            smax = max(smax, float(s[0]))
            s = np.concatenate([s, np.zeros(vt.shape[0] - s.size)])
            small = s <= loose
            if np.any(small):
                candidates.append((block.cols, s[small], vt[small]))
    tol = _NULL_TOL * max(smax, 1.0)
    vectors = []
    for cols, s, vt in candidates:
        for v in vt[s <= tol]:
            full = np.zeros(M)
            full[cols] = v
            vectors.append(full)
    return np.array(vectors).T if vectors else np.zeros((M, 0))


def _too_large(n: int, k: int, need: str, budget: str) -> ValueError:
    lower = (
        f"search lower degrees only (LieAlgebra(C, max_casimir_degree={k - 1}), or max_degree="
        f"{k - 1} of polynomial_casimirs), if the Casimirs of degree < {k} suffice; "
        if k > 1
        else ""
    )
    return ValueError(
        f"polynomial_casimirs: the search for Casimirs of degree {k} of this {n}-dimensional "
        f"algebra would need {need}, above {budget}. The automatic search is for small user "
        f"algebras (it solves for all {math.comb(n + k - 1, k)} coefficients of a polynomial of "
        f"degree {k} in {n} variables). Instead: pass the Casimirs in closed form "
        f"(LieAlgebra(C, casimirs=[...]), e.g. traces of powers of the matrix of mu); {lower}"
        "or use the matrix algebras, e.g. liepoisson.so(N), liepoisson.u(N), which know their "
        "Casimirs"
    )


def _check_conditions_budget(C: np.ndarray, k: int) -> None:
    """Before building degree k's conditions: their memory, from the count of their entries."""
    n = C.shape[0]
    entries = int(np.count_nonzero(C)) * math.comb(n + k - 2, k - 1)
    M = math.comb(n + k - 1, k)
    need = entries * _BYTES_PER_ENTRY + M * (k * 8 + 120)  # + the monomials (array and tuples)
    if need > CASIMIR_SEARCH_MEMORY:
        raise _too_large(
            n, k,
            f"{need / 1e9:.3g} GB for its {entries:.3g} sparse conditions on {M} coefficients",
            f"CASIMIR_SEARCH_MEMORY = {CASIMIR_SEARCH_MEMORY / 1e9:.3g} GB",
        )


def _check_blocks_budget(n: int, k: int, blocks: list[_Block]) -> None:
    """Before the SVDs of degree k: the largest dense block and the arithmetic of them all."""
    shapes = [(b.rows.size, b.cols.size) for b in blocks if b.rows.size]
    if not shapes:
        return
    r, c = max(shapes, key=lambda rc: rc[0] * rc[1])
    block_bytes = 8 * (2 * r * c + 2 * c * c)  # the block, U (or the QR of a tall one) and V
    if block_bytes > CASIMIR_SEARCH_MEMORY:
        raise _too_large(
            n, k,
            f"{block_bytes / 1e9:.3g} GB for the SVD of a dense {r} x {c} block of its conditions",
            f"CASIMIR_SEARCH_MEMORY = {CASIMIR_SEARCH_MEMORY / 1e9:.3g} GB",
        )
    flops = float(sum(r * c * min(r, c) for r, c in shapes))
    if flops > CASIMIR_SEARCH_FLOPS:
        raise _too_large(
            n, k,
            f"SVDs of {len(shapes)} blocks of its conditions (up to {max(c for _, c in shapes)} "
            f"columns), {flops:.3g} rows x columns x min(rows, columns) in all",
            f"CASIMIR_SEARCH_FLOPS = {CASIMIR_SEARCH_FLOPS:.3g} (a few seconds)",
        )


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


def polynomial_casimirs(C: np.ndarray, max_degree: int = 4) -> tuple[Polynomial, ...]:
    """A functionally independent basis of polynomial Casimirs up to `max_degree`.

    Returns an empty tuple for an algebra without polynomial Casimirs (e.g. the affine
    algebra $[e_1, e_2] = e_2$). `ValueError` when a degree still needed exceeds the budget of
    the search (`CASIMIR_SEARCH_MEMORY`, `CASIMIR_SEARCH_FLOPS`), checked before its work.
    """
    C = np.asarray(C, dtype=np.float64)
    n = C.shape[0]
    rng = np.random.default_rng(12345)
    target = generic_corank(C)
    points = rng.standard_normal((3, n))
    found: list[Polynomial] = []
    if target == 0:
        return ()
    for k in range(1, max_degree + 1):
        _check_conditions_budget(C, k)
        S = _sorted_monomials(n, k)
        A = _condition_matrix(C, k, S)
        blocks = _blocks(A)
        _check_blocks_budget(n, k, blocks)
        N = _null_space(A, blocks)
        del A, blocks
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
            F = _rank_table(n, k)
            P = np.zeros((S.shape[0], len(products)))
            for j, prod in enumerate(products):
                for c, e in prod.terms:
                    P[int(_rank(np.repeat(np.arange(n), e), F)), j] += c
            Q, s, _ = np.linalg.svd(P, full_matrices=False)
            Q = Q[:, s > 1e-10 * s[0]]
            N = N - Q @ (Q.T @ N)
            u, s, _ = np.linalg.svd(N, full_matrices=False)
            N = u[:, s > 1e-8]
            if N.shape[1] == 0:
                continue
        for coeffs in _rref(N):
            nz = np.flatnonzero(coeffs)
            cand = Polynomial.from_coefficients(n, [_exponents(S[j], n) for j in nz], coeffs[nz])
            if _gradient_rank(found + [cand], points) > len(found):
                found.append(cand)
            if len(found) == target:
                return tuple(found)
    return tuple(found)
