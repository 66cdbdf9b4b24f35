"""Bounded structure checks and Casimir searches (issue 43): the Jacobi check without the n^4
tensor (randomized, then a sliced search naming the same (a, b, c) as the full tensor), and
the polynomial Casimir search within its memory and arithmetic budgets, with the clear error
beyond them; sparse, blockwise null spaces equal to the dense ones."""

import itertools
import re
import time
import tracemalloc

import numpy as np
import pytest

import liepoisson as lp
from liepoisson import _casimirs, _structure
from liepoisson._structure import check_structure_constants, generic_corank


def _so_basis(N: int) -> np.ndarray:
    basis = []
    for i, j in itertools.combinations(range(N), 2):
        E = np.zeros((N, N))
        E[i, j], E[j, i] = 1.0, -1.0
        basis.append(E)
    return np.array(basis)


def _so_constants(N: int) -> np.ndarray:
    """[E_a, E_b] = C_abd E_d for E_ij - E_ji (i < j): the coordinates of a skew matrix are its
    entries above the diagonal."""
    E = _so_basis(N)
    comm = np.einsum("aij,bjk->abik", E, E)
    comm = comm - comm.transpose(1, 0, 2, 3)
    iu = np.triu_indices(N, 1)
    return comm[:, :, iu[0], iu[1]]


def _jacobiator(C: np.ndarray) -> np.ndarray:
    """The full n^4 tensor, as the check formed it before issue 43 (the reference)."""
    return (
        np.einsum("abd,dce->abce", C, C)
        + np.einsum("bcd,dae->abce", C, C)
        + np.einsum("cad,dbe->abce", C, C)
    )


def _jacobi_message(C: np.ndarray) -> str:
    with pytest.raises(ValueError, match="Jacobi identity") as info:
        check_structure_constants(C)
    return str(info.value)


def _reported(message: str) -> tuple[float, tuple[int, ...], int]:
    m = re.search(
        r"violation is (\S+) at \(a, b, c\) = \((\d+), (\d+), (\d+)\) \(component (\d+)\)", message
    )
    assert m, message
    return float(m.group(1)), tuple(int(g) for g in m.group(2, 3, 4)), int(m.group(5))


# -- the Jacobi check ------------------------------------------------------------------------
def test_perturbed_constants_fail_the_randomized_check_at_the_brute_force_index():
    # so(4) with [E_01, E_02] changed by a dyadic amount on both sides: still antisymmetric,
    # no longer Jacobi. Dyadic entries make J exact, so the full tensor's first maximum (in C
    # order) is the reference, as the n^4 check reported it.
    C = _so_constants(4)
    C[0, 1, 5] += 0.5
    C[1, 0, 5] -= 0.5
    assert np.array_equal(C, -C.transpose(1, 0, 2))
    tol = _structure._STRUCTURE_RTOL * max(1.0, np.abs(C).max()) ** 2
    assert not _structure._jacobiator_small_on_probes(C, tol)
    J = np.abs(_jacobiator(C))
    idx = np.unravel_index(np.argmax(J), J.shape)
    value, abc, component = _reported(_jacobi_message(C))
    assert abc == tuple(int(i) for i in idx[:3]) and component == int(idx[3])
    assert value == pytest.approx(J.max(), rel=1e-3)


@pytest.mark.parametrize("n", [4, 6, 9])
def test_sliced_search_names_the_largest_entry_of_the_full_tensor(n, monkeypatch):
    # Random antisymmetric constants (no Lie algebra): the largest |J| comes in six copies
    # (J is antisymmetric in a, b, c) equal up to round-off; the first in C order is named.
    # Small slices, to exercise the search across them.
    monkeypatch.setattr(_structure, "_JACOBI_SLICE_ENTRIES", 2 * n**3)
    rng = np.random.default_rng(n)
    C = rng.standard_normal((n, n, n))
    C = C - C.transpose(1, 0, 2)
    J = np.abs(_jacobiator(C))
    idx = np.unravel_index(np.argmax(J >= J.max() * (1 - 1e-9)), J.shape)
    worst, where = _structure._largest_jacobi_violation(C)
    assert where == tuple(int(i) for i in idx)
    assert worst == pytest.approx(J.max(), rel=1e-12)
    value, abc, component = _reported(_jacobi_message(C))
    assert (abc, component) == (where[:3], where[3]) and value == pytest.approx(worst, rel=1e-2)


def test_small_violations_are_caught_by_the_probes():
    # A violation of 1e-6 (relative) is 1e4 times the tolerance: the O(n^3) probes see it.
    C = _so_constants(5)
    C[2, 3, 0] += 1e-6
    C[3, 2, 0] -= 1e-6
    tol = _structure._STRUCTURE_RTOL * max(1.0, np.abs(C).max()) ** 2
    assert not _structure._jacobiator_small_on_probes(C, tol)
    _jacobi_message(C)


def test_round_off_in_valid_constants_is_accepted():
    # so(5) in a random orthonormal basis: every constant carries round-off.
    C = _so_constants(5)
    Q = np.linalg.qr(np.random.default_rng(1).standard_normal((10, 10)))[0]
    C = np.einsum("ai,bj,ijk,dk->abd", Q, Q, C, Q)
    C = 0.5 * (C - C.transpose(1, 0, 2))
    out = check_structure_constants(C)
    assert np.array_equal(out, C) and not out.flags.writeable


def test_so_n_up_to_dimension_28_is_accepted_quickly_without_the_n4_tensor(monkeypatch):
    def brute_force(C):
        raise AssertionError("valid constants must pass the randomized check")

    monkeypatch.setattr(_structure, "_largest_jacobi_violation", brute_force)
    start = time.perf_counter()
    for N in range(2, 9):
        C = _so_constants(N)
        assert np.array_equal(check_structure_constants(C), C)
    assert time.perf_counter() - start < 2.0
    # so(12), n = 66: the n^4 tensor alone is 152 MB.
    C = _so_constants(12)
    tracemalloc.start()
    try:
        check_structure_constants(C)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 6 * C.nbytes  # 14 MB


@pytest.mark.parametrize(
    "C, error, message",
    [
        ("so3", TypeError, r"real array of shape \(n, n, n\)"),
        (np.zeros((2, 2, 2), dtype=complex), TypeError, "complex ndarray"),
        (np.zeros((2, 3, 2)), ValueError, r"shape \(n, n, n\) with n >= 1; got \(2, 3, 2\)"),
        (np.full((2, 2, 2), np.nan), ValueError, r"finite; found nan at \(a, b, d\) = \(0, 0, 0\)"),
        (np.ones((2, 2, 2)), ValueError,
         r"antisymmetric.*violation is 2 at \(a, b, d\) = \(0, 0, 0\)"),
    ],
)
def test_other_structure_errors_are_unchanged(C, error, message):
    with pytest.raises(error, match=message):
        check_structure_constants(C)


def test_generic_corank_of_so_n():
    # rank(so(N)) = floor(N / 2) independent Casimirs.
    assert [generic_corank(_so_constants(N)) for N in (3, 4, 5, 6)] == [1, 2, 2, 3]


# -- the Casimir search ------------------------------------------------------------------------
def test_monomial_ranks_are_the_enumeration_order():
    for n, k in [(1, 3), (3, 2), (5, 4), (7, 3)]:
        S = _casimirs._sorted_monomials(n, k)
        assert np.array_equal(_casimirs._rank(S, _casimirs._rank_table(n, k)), np.arange(len(S)))


def _dense_conditions(C: np.ndarray, k: int) -> np.ndarray:
    n = C.shape[0]
    combos = itertools.combinations_with_replacement(range(n), k)
    monos = [tuple(np.bincount(s, minlength=n)) for s in combos]
    index = {m: j for j, m in enumerate(monos)}
    A = np.zeros((n * len(monos), len(monos)))
    for j, m in enumerate(monos):
        for a, b, d in np.argwhere(C != 0.0):
            if m[b]:
                e = list(m)
                e[b] -= 1
                e[d] += 1
                A[a * len(monos) + index[tuple(e)], j] += m[b] * C[a, b, d]
    return A


@pytest.mark.parametrize("name", ["se3", "so3+heisenberg", "so4", "so4 rotated"])
def test_blockwise_null_spaces_equal_the_dense_ones(name):
    if name.startswith("so4"):
        C = _so_constants(4)
        if name.endswith("rotated"):
            Q = np.linalg.qr(np.random.default_rng(2).standard_normal((6, 6)))[0]
            C = np.einsum("ai,bj,ijk,dk->abd", Q, Q, C, Q)
    elif name == "se3":
        C = lp.se3().structure_constants
    else:
        C = lp.direct_sum(lp.so3(), lp.heisenberg()).structure_constants
    for k in (1, 2, 3):
        S = _casimirs._sorted_monomials(C.shape[0], k)
        A = _casimirs._condition_matrix(C, k, S)
        dense = _dense_conditions(C, k)
        np.testing.assert_allclose(A.toarray(), dense, atol=1e-14)
        blocks = _casimirs._blocks(A)
        assert sorted(np.concatenate([b.cols for b in blocks])) == list(range(S.shape[0]))
        N = _casimirs._null_space(A, blocks)
        _, s, vt = np.linalg.svd(dense)
        ref = vt[int(np.sum(s > 1e-9 * max(s[0], 1.0))):].T
        assert N.shape == ref.shape
        if N.shape[1]:  # the same subspace: orthonormal bases related by an orthogonal map
            np.testing.assert_allclose(np.linalg.svd(ref.T @ N, compute_uv=False), 1.0, atol=1e-10)


@pytest.mark.parametrize("N, degrees", [(4, [2, 2]), (5, [2, 4])])
def test_so4_and_so5_from_matrices_find_two_casimirs(N, degrees):
    start = time.perf_counter()
    g = lp.LieAlgebra.from_matrices(_so_basis(N), f"so{N}")
    assert time.perf_counter() - start < 3.0  # so(5) took 6.7 s (31 s on a busy machine) before
    assert sorted(p.degree for p in g.casimir_polynomials) == degrees
    C = g.structure_constants
    for p in g.casimir_polynomials:
        for mu in np.random.default_rng(3).standard_normal((3, g.dim)):
            grad = np.array([float(q.evaluate(mu)) for q in p.gradient()])
            assert np.abs(np.einsum("abd,d,b->a", C, mu, grad)).max() < 1e-12 * np.abs(grad).max()


def test_so6_finishes_in_seconds():
    start = time.perf_counter()
    assert [p.degree for p in lp.polynomial_casimirs(_so_constants(6))] == [2, 3, 4]
    assert time.perf_counter() - start < 5.0


def test_over_the_memory_budget_the_search_says_which_degree_and_what_to_do(monkeypatch):
    # so(5): degree 3 needs ~0.45 MB, degree 4 ~1.8 MB (its Casimirs are of degree 2 and 4).
    monkeypatch.setattr(_casimirs, "CASIMIR_SEARCH_MEMORY", 1e6)
    with pytest.raises(ValueError) as info:
        lp.LieAlgebra.from_matrices(_so_basis(5), "so5")
    message = str(info.value)
    parts = ["Casimirs of degree 4", "10-dimensional", "CASIMIR_SEARCH_MEMORY",
             "small user algebras", "casimirs=[...]", "max_casimir_degree=3", "liepoisson.so(N)"]
    for part in parts:
        assert part in message, (part, message)
    # Degrees that fit are unaffected: so(4)'s Casimirs are quadratic.
    assert [p.degree for p in lp.polynomial_casimirs(_so_constants(4))] == [2, 2]


def test_over_the_arithmetic_budget_the_search_stops_before_its_svds(monkeypatch):
    # so(5), degree 2: 16 blocks, sum of rows x columns x min(rows, columns) ~7e3.
    monkeypatch.setattr(_casimirs, "CASIMIR_SEARCH_FLOPS", 1e3)
    solved = []
    null_space = _casimirs._null_space

    def recorded(A, blocks):
        solved.append(A.shape[1])
        return null_space(A, blocks)

    monkeypatch.setattr(_casimirs, "_null_space", recorded)
    with pytest.raises(ValueError, match=r"degree 2 .*CASIMIR_SEARCH_FLOPS.*casimirs=\[\.\.\.\]"):
        lp.polynomial_casimirs(_so_constants(5))
    assert solved == [10]  # degree 1 only


def test_a_dense_basis_over_the_budget_fails_before_forming_its_block(monkeypatch):
    # so(5) in a random orthonormal basis: no sparsity, the degree-4 conditions are one dense
    # 7150 x 715 block (so(6)'s, 45900 x 3060, were the old search's 20 GB), here over a
    # budget of 50 MB. Refused before the block is formed.
    monkeypatch.setattr(_casimirs, "CASIMIR_SEARCH_MEMORY", 50e6)
    formed = []
    dense = _casimirs._Block.dense

    def recorded(block):
        formed.append(block.cols.size)
        return dense(block)

    monkeypatch.setattr(_casimirs._Block, "dense", recorded)
    C = _so_constants(5)
    Q = np.linalg.qr(np.random.default_rng(4).standard_normal((10, 10)))[0]
    C = np.einsum("ai,bj,ijk,dk->abd", Q, Q, C, Q)
    with pytest.raises(ValueError, match=r"degree 4 .*dense 7150 x 715 block"):
        lp.polynomial_casimirs(C)
    assert formed == [10, 55, 220]  # degrees 1-3, one block each
