"""Matrix Lie algebras (so(N), u(N), su(N), sp(2N), gl(N), sl(N), and the semidirect products
se(N), gl(N) x R^N, sl(N) x R^N, u(N) x C^N): bracket, Lie-Poisson
structure, Casimirs and coadjoint flows against independent references (structure constants
formed from the matrices, finite differences, the so(3) of structure constants)."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import liepoisson as lp
from benchmarks.composition_drift import casimir_change

EPS = np.finfo(np.float64).eps
# Every family at a small size by default (real and complex, compact and not, traceless); the
# other sizes under -m slow.
_DEFAULT = [lp.so(4), lp.u(3), lp.sl(3), lp.semidirect(lp.sl(3))]
_MORE = [lp.semidirect(lp.u(2)), lp.so(3), lp.so(5), lp.u(2), lp.su(3), lp.sp(1), lp.sp(2), lp.gl(3), lp.se(3), lp.se(4), lp.se(5),
         lp.semidirect(lp.gl(3)), lp.semidirect(lp.sl(2)), lp.semidirect(lp.sl(4)), lp.semidirect(lp.u(3)),
         lp.semidirect(lp.u(4)), lp.semidirect(lp.su(3)), lp.semidirect(lp.su(4)), lp.semidirect(lp.sp(1)),
         lp.semidirect(lp.sp(2)), lp.semidirect(lp.sp(3))]
SMALL = _DEFAULT + _MORE
ALGEBRAS = [pytest.param(g, id=g.name) for g in _DEFAULT] + [
    pytest.param(g, id=g.name, marks=pytest.mark.slow) for g in _MORE]


def algebras(default):
    """ALGEBRAS with only the families named in `default` (e.g. {"u3"}) in the default run."""
    return [pytest.param(g, id=g.name, marks=() if g.name in default else pytest.mark.slow) for g in SMALL]


def _vectors(g, seed, k=1):
    return np.random.default_rng(seed).normal(size=(k, g.dim))


@pytest.mark.parametrize("g", ALGEBRAS)
def test_dimensions_and_rank(g):
    expected = {"so": g.N * (g.N - 1) // 2, "u": g.N**2, "su": g.N**2 - 1, "sp": 2 * g.N**2 + g.N,
                "gl": g.N**2, "sl": g.N**2 - 1, "se": g.N * (g.N + 1) // 2, "aff": g.N**2 + g.N,
                "saff": g.N**2 - 1 + g.N, "uaff": g.N**2 + 2 * g.N, "suaff": g.N**2 - 1 + 2 * g.N,
                "spaff": 2 * g.N**2 + 3 * g.N}[g.family]
    assert g.dim == expected
    mu = _vectors(g, 0)[0]
    # generic corank = number of Casimirs (the rank of the algebra)
    assert g.orbit_dimension(mu) == g.dim - g.n_casimirs


@pytest.mark.parametrize("g", ALGEBRAS)
def test_basis_is_orthonormal_and_coordinates_project(g):
    E = np.asarray(g.matrix(np.eye(g.dim)))
    gram = g.kappa * np.real(np.einsum("aij,bij->ab", E.conj(), E))
    np.testing.assert_allclose(gram, np.eye(g.dim), atol=4 * EPS)
    x = _vectors(g, 1)[0]
    np.testing.assert_allclose(np.asarray(g.coordinates(g.matrix(x))), x, atol=8 * EPS)
    # a matrix outside the algebra: its residual after projection is orthogonal to the basis
    rng = np.random.default_rng(2)
    Z = rng.normal(size=(g.size, g.size)) + (1j * rng.normal(size=(g.size, g.size)) if g.complex else 0)
    R = Z - np.asarray(g.matrix(g.coordinates(Z)))
    assert np.abs(g.kappa * np.real(np.einsum("aij,ij->a", E.conj(), R))).max() < 32 * EPS


@pytest.mark.parametrize("g", ALGEBRAS)
def test_structure_constants_are_a_lie_algebra_and_give_the_same_operations(g):
    C = g.structure_constants
    # LieAlgebra checks antisymmetry and Jacobi of the constants formed from the matrices.
    h = lp.LieAlgebra(C, casimirs=[])
    xi, eta, mu = _vectors(g, 3, 3)
    scale = np.abs(xi).max() * np.abs(mu).max()
    # ad* and the Poisson tensor by matrix products against the structure-constant formulas;
    # each entry is a sum of n products of O(1) numbers: a few n eps.
    tol = 4 * g.dim * EPS * scale
    np.testing.assert_allclose(np.asarray(g.ad_star(xi, mu)), np.asarray(h.ad_star(xi, mu)), atol=tol)
    np.testing.assert_allclose(np.asarray(g.bracket(xi, eta)), np.asarray(h.bracket(xi, eta)), atol=tol)
    np.testing.assert_allclose(np.asarray(g.poisson_tensor(mu)), np.asarray(h.poisson_tensor(mu)), atol=tol)
    np.testing.assert_allclose(np.asarray(g.poisson_action(mu, xi)), np.asarray(h.poisson_tensor(mu) @ xi), atol=tol)


@pytest.mark.parametrize("g", ALGEBRAS)
@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_jacobi_identity(g, seed):
    x, y, z = _vectors(g, seed, 3)
    J = g.bracket(g.bracket(x, y), z) + g.bracket(g.bracket(y, z), x) + g.bracket(g.bracket(z, x), y)
    size = np.abs(x).max() * np.abs(y).max() * np.abs(z).max()
    # two nested products of m x m matrices of O(1) entries: O(m^2) round-off terms
    assert np.abs(np.asarray(J)).max() <= 64 * g.size**2 * EPS * size


# so(4)'s Casimirs are checked by value by default (test_so3_casimir_is_the_squared_angular_momentum_and_so4_has_two)
@pytest.mark.parametrize("g", [p for p in algebras({"u3", "sl3", "saff3", "uaff2", "suaff3", "spaff2"})
                               if p.values[0].n_casimirs])
def test_casimirs_are_casimirs(g):
    mu = _vectors(g, 4, 5)
    B = np.asarray(g.poisson_tensor(mu))
    G = np.asarray(g.casimir_gradients(mu))
    assert G.shape == (5, g.n_casimirs, g.dim)
    scale = np.abs(B).max() * np.abs(G).max()
    assert np.abs(np.einsum("kab,kjb->kja", B, G)).max() < 64 * g.dim * EPS * scale
    # gradients are independent at a generic point (each row scaled to unit length: the
    # semidirect products' Casimirs are of very different degrees)
    assert all(np.linalg.matrix_rank(Gk / np.linalg.norm(Gk, axis=1, keepdims=True)) == g.n_casimirs for Gk in G)
    # against central finite differences of casimirs (step 1e-6: error ~ 1e-12 relative)
    e = np.eye(g.dim)[0]
    fd = (np.asarray(g.casimirs(mu[0] + 1e-6 * e)) - np.asarray(g.casimirs(mu[0] - 1e-6 * e))) / 2e-6
    np.testing.assert_allclose(fd, G[0, :, 0], rtol=1e-6, atol=1e-6 * np.abs(G[0]).max())


def test_so3_casimir_is_the_squared_angular_momentum_and_so4_has_two():
    Pi = np.array([0.3, -1.1, 0.8])
    assert abs(float(lp.so(3).casimirs(Pi)[0]) - Pi @ Pi) < 4 * EPS
    c = np.asarray(lp.so(4).casimirs(np.arange(1.0, 7.0)))
    # -tr M^2 / 2 is the sum of the squared entries above the diagonal; the Pfaffian
    # M01 M23 - M02 M13 + M03 M12 (components in the order 01, 02, 03, 12, 13, 23)
    np.testing.assert_allclose(c, [np.sum(np.arange(1.0, 7.0) ** 2), 1 * 6 - 2 * 5 + 3 * 4], rtol=8 * EPS)


def _pfaffian_by_expansion(A):
    """Pf(A) by expansion along the first row (n!! terms: small n only)."""
    n = A.shape[0]
    if n == 0:
        return 1.0
    return sum((-1) ** (j + 1) * A[0, j] * _pfaffian_by_expansion(A[np.ix_(*[[k for k in range(n) if k not in (0, j)]] * 2)])
               for j in range(1, n))


@pytest.mark.parametrize("n", [pytest.param(2, marks=pytest.mark.slow), 4, pytest.param(6, marks=pytest.mark.slow), 8])
def test_pfaffian_against_its_expansion_and_its_gradient_against_the_minors(n):
    import jax

    from liepoisson._pfaffian import pfaffian

    rng = np.random.default_rng(n)
    X = rng.normal(size=(n, n))
    A = X - X.T
    value = _pfaffian_by_expansion(A)
    # Householder reduction: backward stable, a few eps of the size prod |A| ~ |A|^(n/2)
    assert abs(float(pfaffian(A)) - value) < 64 * n * EPS * np.abs(A).max() ** (n // 2) * 3 ** n
    assert abs(float(pfaffian(A)) ** 2 - np.linalg.det(A)) < 1e-10 * abs(np.linalg.det(A)) + 1e-12
    # d Pf / d A_ij (A_ji = -A_ij moving with it) is the signed Pfaffian of the minor without i, j
    G = np.asarray(jax.jit(jax.grad(pfaffian))(A))
    for i, j in [(0, 1), (0, n - 1), (n - 2, n - 1)] + ([(1, 4), (2, 3)] if n >= 6 else []):
        rest = [k for k in range(n) if k not in (i, j)]
        minor = (-1) ** (i + j + 1) * _pfaffian_by_expansion(A[np.ix_(rest, rest)])
        assert abs((G[i, j] - G[j, i]) - minor) < 1e-12 * max(1.0, abs(minor)) * 3 ** n


def test_pfaffian_gradient_where_the_pfaffian_vanishes():
    import jax

    from liepoisson._pfaffian import pfaffian

    # rank 2 (Pf = 0, det's gradient 0): d Pf = A01 dA23, exactly, no NaN from the reduced columns
    A = np.zeros((4, 4))
    A[0, 1], A[1, 0] = 2.5, -2.5
    gradient = jax.jit(jax.grad(pfaffian))
    G = np.asarray(gradient(A))
    expected = np.zeros((4, 4))
    expected[2, 3], expected[3, 2] = 1.25, -1.25  # half of d/dA23 on each of A23, A32
    assert float(pfaffian(A)) == 0.0
    np.testing.assert_allclose(G, expected, atol=4 * EPS)
    assert np.all(np.asarray(gradient(np.zeros((4, 4)))) == 0.0)
    with pytest.raises(ValueError, match="even"):
        pfaffian(np.zeros((3, 3)))


def test_so4_casimirs_tell_apart_the_orbits_that_traces_confuse():
    # so(4) = so(3) x so(3): M and its image under the reflection diag(-1, 1, 1, 1) have the same
    # traces of powers but Pfaffians of opposite sign: different orbits of SO(4)
    g = lp.so(4)
    mu = np.array([0.3, -1.2, 0.7, 2.0, 0.4, -0.9])
    R = np.diag([-1.0, 1.0, 1.0, 1.0])
    nu = np.asarray(g.coordinates(R @ np.asarray(g.matrix(mu)) @ R))
    M, N = np.asarray(g.matrix(mu)), np.asarray(g.matrix(nu))
    assert abs(np.trace(np.linalg.matrix_power(M, 4)) - np.trace(np.linalg.matrix_power(N, 4))) < 64 * EPS
    c, d = np.asarray(g.casimirs(mu)), np.asarray(g.casimirs(nu))
    assert abs(c[0] - d[0]) < 8 * EPS * c[0] and abs(c[1] + d[1]) < 8 * EPS * abs(c[1]) and abs(c[1]) > 0.1


# complex and non-compact by default; so(4)'s flow (compact, real) with -m slow
@pytest.mark.parametrize("g", algebras({"u3", "sl3", "saff3", "uaff2"}))
def test_coadjoint_flow_is_generated_by_the_poisson_tensor(g):
    alpha, mu = _vectors(g, 5, 2)
    h = 1e-5  # central difference: truncation h^2 |d^3 mu| ~ 1e-10, round-off eps/h ~ 1e-11
    fd = (np.asarray(g.coadjoint_flow(alpha, h, mu)) - np.asarray(g.coadjoint_flow(alpha, -h, mu))) / (2 * h)
    np.testing.assert_allclose(fd, np.asarray(g.poisson_action(mu, alpha)), atol=1e-8)
    # zero rotation: the identity, up to the round trip through the matrix (factors 1/sqrt(2))
    np.testing.assert_allclose(np.asarray(g.coadjoint_flow(np.zeros(g.dim), 1.0, mu)), mu, rtol=0,
                               atol=4 * EPS * np.abs(mu).max())


# complex and non-compact by default; so(4)'s flow (compact, real) with -m slow
@pytest.mark.parametrize("g", algebras({"u3", "sl3", "saff3", "uaff2"}))
def test_coadjoint_flow_is_a_poisson_map(g):
    alpha, mu = _vectors(g, 6, 2)
    alpha *= 0.5
    flow = lambda m: g.coadjoint_flow(alpha, 0.7, m)
    D = np.asarray(jax.jacfwd(flow)(mu))
    lhs = D @ np.asarray(g.poisson_tensor(mu)) @ D.T
    rhs = np.asarray(g.poisson_tensor(flow(mu)))
    assert np.abs(lhs - rhs).max() < 256 * g.dim * EPS * np.abs(rhs).max()


# u(4) by default; the others (sp(2) non-compact: its flow by default through sl(3)'s above) with -m slow
@pytest.mark.parametrize("g", [pytest.param(lp.so(5), marks=pytest.mark.slow), lp.u(4),
                               pytest.param(lp.su(3), marks=pytest.mark.slow), pytest.param(lp.sp(2), marks=pytest.mark.slow),
                               pytest.param(lp.semidirect(lp.u(3)), marks=pytest.mark.slow),
                               pytest.param(lp.semidirect(lp.sl(3)), marks=pytest.mark.slow)],
                         ids=lambda g: g.name)
def test_casimirs_and_spectrum_kept_over_a_long_composition(g):
    rng = np.random.default_rng(7)
    mu0 = rng.normal(size=g.dim)
    alphas = rng.normal(size=(1000, g.dim))
    compact = g.family in ("so", "u", "su")
    if g.family == "uaff":  # translations are not compact
        alphas[:, -2 * g.N:] *= 0.05
    elif not compact:
        alphas *= 0.05  # non-compact: keep exp(t alpha) moderate so the orbit stays bounded

    def body(mu, a):
        return g._coadjoint_flow(a, np.asarray(0.3), mu), None

    mu1, _ = jax.lax.scan(body, mu0, alphas)
    c0, c1 = np.asarray(g.casimirs(mu0)), np.asarray(g.casimirs(mu1))
    rel = np.abs(c1 - c0) / np.abs(c0)
    # 1000 conjugations, each exact to a few eps: a random walk of round-off, <= ~1e3 eps
    assert rel.max() < 2e3 * EPS * g.size
    if compact:
        s0, s1 = np.asarray(g.spectrum(mu0)), np.asarray(g.spectrum(mu1))
        assert np.abs(s1 - s0).max() < 2e3 * EPS * g.size * np.abs(s0).max()


@pytest.mark.slow  # the matrices' convention by default in test_manakov_body_as_a_lie_poisson_system_on_so4
def test_so3_of_matrices_is_so3_of_structure_constants():
    # so(3)'s components (M12, M13, M23) are (-Pi3, Pi2, -Pi1) for M = hat(Pi).
    P = np.array([[0, 0, -1], [0, 1, 0], [-1, 0, 0]], dtype=float)
    g, h = lp.so(3), lp.so3()
    rng = np.random.default_rng(8)
    Pi, A = rng.normal(size=(2, 3))
    M = np.asarray(g.matrix(P @ Pi))
    hat = np.array([[0, -Pi[2], Pi[1]], [Pi[2], 0, -Pi[0]], [-Pi[1], Pi[0], 0]])
    np.testing.assert_array_equal(M, hat)
    np.testing.assert_allclose(P @ np.asarray(h.coadjoint_flow(A, 0.9, Pi)),
                               np.asarray(g.coadjoint_flow(P @ A, 0.9, P @ Pi)), atol=8 * EPS)
    np.testing.assert_allclose(P @ np.asarray(h.poisson_tensor(Pi)) @ P.T, np.asarray(g.poisson_tensor(P @ Pi)), atol=0)


@pytest.mark.parametrize("g", [pytest.param(lp.so(4), marks=pytest.mark.slow), lp.su(2)], ids=lambda g: g.name)
def test_flow_parameters_invert_the_flow(g):
    alpha, mu = _vectors(g, 9, 2)
    mu1 = np.asarray(g.coadjoint_flow(0.3 * alpha, 1.0, mu))
    a = g.coadjoint_flow_parameters(mu, mu1, 1.0)
    np.testing.assert_allclose(np.asarray(g.coadjoint_flow(a, 1.0, mu)), mu1, atol=1e-12)
    # orthogonal to the Casimir gradients at mu (the paper's eq. (26))
    assert np.abs(np.asarray(g.casimir_gradients(mu)) @ a).max() < 1e-12


def test_large_algebras_build_without_a_structure_constant_tensor():
    for g in (lp.so(64), lp.u(64)):
        assert g.dim in (2016, 4096)
        with pytest.raises(ValueError, match="structure-constant tensor"):
            _ = g.structure_constants
        x = np.random.default_rng(10).normal(size=g.dim)
        np.testing.assert_allclose(np.asarray(g.coordinates(g.matrix(x))), x, atol=8 * EPS)


def test_definitions_round_trip_and_bad_input():
    for g in SMALL:
        back = lp.algebra_from_definition(g.definition())
        assert back == g and hash(back) == hash(g)
    assert lp.so(3) != lp.so(3, sign=1)
    with pytest.raises(ValueError, match="family"):
        lp.MatrixLieAlgebra("so3", 3)
    with pytest.raises(ValueError, match="N must be >= 2"):
        lp.so(1)
    with pytest.raises(TypeError, match="N must be an integer"):
        lp.u(2.5)
    with pytest.raises(ValueError, match="sign"):
        lp.sl(3, sign=0)
    with pytest.raises(ValueError, match="not a valid matrix Lie algebra"):
        lp.algebra_from_definition({"kind": "MatrixLieAlgebra", "family": "so"})
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 6\)"):
        lp.so(4).coadjoint_flow(np.zeros(5), 1.0, np.zeros(6))
    with pytest.raises(ValueError, match="finite"):
        lp.u(2).casimirs([np.nan, 0, 0, 0])


def test_semidirect_products_by_hand_and_bad_input():
    assert lp.semidirect(lp.so(3)) == lp.se(3)
    assert lp.semidirect(lp.u(2, sign=1)).sign == 1
    # sl(2) x R^2 as [[a, b, p1], [c, -a, p2], [0, 0, 0]]: its Casimir det[p, Ap] by hand,
    # A p = (a p1 + b p2, c p1 - a p2)
    g = lp.semidirect(lp.sl(2))
    mu = np.random.default_rng(11).normal(size=g.dim)
    M = np.asarray(g.matrix(mu))
    (a, b), (c, _), p = M[0, :2], M[1, :2], M[:2, 2]
    Ap = np.array([a * p[0] + b * p[1], c * p[0] - a * p[1]])
    np.testing.assert_allclose(np.asarray(g.casimirs(mu)), [p[0] * Ap[1] - p[1] * Ap[0]], rtol=8 * EPS)
    # u(2) x C^2: |p|^2 and Re tr iK, K = (|p|^2 - p p^dagger) A
    h = lp.semidirect(lp.u(2))
    mu = np.random.default_rng(12).normal(size=h.dim)
    M = np.asarray(h.matrix(mu))
    A, p = M[:2, :2], M[:2, 2]
    K = (np.vdot(p, p) * np.eye(2) - np.outer(p, p.conj())) @ A
    np.testing.assert_allclose(np.asarray(h.casimirs(mu)), [np.vdot(p, p).real, np.trace(1j * K).real], rtol=16 * EPS)
    with pytest.raises(ValueError, match=r"orbits are not isospectral"):
        h.spectrum(mu)
    with pytest.raises(ValueError, match=r"so, gl, sl, u, su and sp; got se3, itself a semidirect product"):
        lp.semidirect(lp.se(3))
    # sp(2) = sl(2): sp(1) x R^2 is sl(2) x R^2 in another basis, and its Casimir p^T S p =
    # -p^T J A p is -det[p, Ap]
    a, b = lp.semidirect(lp.sp(1)), lp.semidirect(lp.sl(2))
    mu = np.random.default_rng(14).normal(size=a.dim)
    same = np.asarray(b.coordinates(a.matrix(mu)))
    np.testing.assert_allclose(np.asarray(a.casimirs(mu)), -np.asarray(b.casimirs(same)), rtol=16 * EPS)
    # su(2) x C^2: |p|^2 alone (one Casimir)
    k = lp.semidirect(lp.su(2))
    mu = np.random.default_rng(13).normal(size=k.dim)
    p = np.asarray(k.matrix(mu))[:2, 2]
    np.testing.assert_allclose(np.asarray(k.casimirs(mu)), [np.vdot(p, p).real], rtol=8 * EPS)
    # at p = 0 every Casimir and gradient is zero, not NaN (su's K is a polynomial, no 1/|p|)
    for g in (h, lp.semidirect(lp.su(4))):
        assert np.all(np.asarray(g.casimirs(np.zeros(g.dim))) == 0.0)
        assert np.all(np.asarray(g.casimir_gradients(np.zeros(g.dim))) == 0.0)
    with pytest.raises(TypeError, match="MatrixLieAlgebra"):
        lp.semidirect(lp.so3())
    assert np.asarray(lp.semidirect(lp.gl(2)).casimirs(np.ones((3, 6)))).shape == (3, 0)


def test_non_compact_overflow_is_reported():
    g = lp.gl(2)
    with pytest.raises(FloatingPointError, match="overflowed"):
        g.coadjoint_flow(np.array([400.0, 0, 0, -400.0]), 2.0, np.ones(4))


def test_manakov_body_as_a_lie_poisson_system_on_so4():
    # H = sum_{i<j} M_ij^2 / (2 (J_i + J_j)): dM/dt = [M, Omega], M = J Omega + Omega J.
    J = np.array([1.0, 1.3, 1.9, 2.6])
    g = lp.so(4)
    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    inertia = np.array([J[i] + J[j] for i, j in pairs])
    body = lp.systems.LiePoissonSystem(g, lambda m, xp: sum(m[a] * m[a] / (2 * inertia[a]) for a in range(6)))
    y = np.random.default_rng(11).normal(size=6)
    M = np.asarray(g.matrix(y))
    Omega = np.zeros((4, 4))
    for a, (i, j) in enumerate(pairs):
        Omega[i, j], Omega[j, i] = y[a] / inertia[a], -y[a] / inertia[a]
    np.testing.assert_allclose(J[:, None] * Omega + Omega * J[None, :], M, atol=4 * EPS)
    np.testing.assert_allclose(np.asarray(body.vector_field(y)), np.asarray(g.coordinates(M @ Omega - Omega @ M)),
                               atol=8 * EPS)
    assert body.n_casimirs == 2
    back = lp.systems.LiePoissonSystem.from_params(body.name, body.params)
    np.testing.assert_allclose(np.asarray(back.vector_field(y)), np.asarray(body.vector_field(y)), atol=0)


# -- direct sums with matrix algebras ---------------------------------------------------------------
@pytest.mark.slow  # the default run keeps the coupled bodies below (a DirectSum against heyoka)
def test_direct_sum_of_matrix_algebras_is_blockwise_and_matches_structure_constants():
    parts = [lp.so(3), lp.u(2), lp.sp(1)]
    g = lp.direct_sum(*parts)
    assert isinstance(g, lp.DirectSum) and g.dim == 3 + 4 + 3 and g.n_casimirs == 1 + 2 + 1
    # the same sum written with structure constants (LieAlgebra blocks)
    h = lp.direct_sum(*[lp.LieAlgebra(p.structure_constants, casimirs=[]) for p in parts])
    rng = np.random.default_rng(12)
    xi, mu = rng.normal(size=(2, g.dim))
    tol = 64 * g.dim * EPS * np.abs(xi).max() * np.abs(mu).max()
    np.testing.assert_allclose(np.asarray(g.ad_star(xi, mu)), np.asarray(h.ad_star(xi, mu)), atol=tol)
    np.testing.assert_allclose(np.asarray(g.poisson_tensor(mu)), np.asarray(h.poisson_tensor(mu)), atol=tol)
    np.testing.assert_allclose(np.asarray(g.poisson_action(mu, xi)), np.asarray(h.poisson_tensor(mu) @ xi), atol=tol)
    np.testing.assert_allclose(np.asarray(g.coadjoint_flow(0.3 * xi, 0.7, mu)),
                               np.asarray(h.coadjoint_flow(0.3 * xi, 0.7, mu)), atol=1e-13)
    np.testing.assert_array_equal(g.structure_constants, h.structure_constants)
    # each summand's Casimirs are kept, and they annihilate the block Poisson tensor
    c0, c1 = np.asarray(g.casimirs(mu)), np.asarray(g.casimirs(g.coadjoint_flow(xi, 0.9, mu)))
    assert (np.abs(c1 - c0) / np.abs(c0)).max() < 64 * EPS
    G = np.asarray(g.casimir_gradients(mu))
    assert G.shape == (4, g.dim) and np.abs(G @ np.asarray(g.poisson_tensor(mu))).max() < tol
    back = lp.algebra_from_definition(g.definition())
    assert back == g
    with pytest.raises(ValueError, match="sign"):
        lp.direct_sum(lp.so(3), lp.so(3, sign=1))
    with pytest.raises(TypeError, match="argument 1"):
        lp.direct_sum(lp.so(3), "so3")


def test_two_coupled_bodies_on_a_direct_sum_keep_each_casimir():
    # two rigid bodies on so(3) + so(3) coupled through Pi_1 . Pi_2: each |Pi_i|^2 is kept
    g = lp.direct_sum(lp.so(3), lp.so(3))
    body = lp.systems.LiePoissonSystem(
        g, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 / 2 + m[2] ** 2 / 3 + m[3] ** 2 + m[4] ** 2 + m[5] ** 2)
        + 0.3 * (m[0] * m[3] + m[1] * m[4] + m[2] * m[5]))
    y0 = np.random.default_rng(13).normal(size=6)
    import integrators as it

    truth = np.asarray(it.ground_truth(body, y0, h=0.5, n_steps=4).states[0])
    c = np.asarray(body.casimirs(truth))
    assert (np.abs(c - c[0]) / np.abs(c[0])).max() < 1e-13
    ys = np.asarray(it.RK4(body, 0.01).rollout(y0, 200))
    assert np.abs(ys[-1] - truth[-1]).max() < 1e-8


def test_rank_with_round_off_in_the_constants_and_conversions_check_shapes():
    noisy = lp.so(4).structure_constants + 1e-14 * np.random.default_rng(14).normal(size=(6, 6, 6))
    noisy = 0.5 * (noisy - noisy.transpose(1, 0, 2))
    assert lp.LieAlgebra(noisy).n_casimirs == 2  # constants with round-off keep their Casimirs
    with pytest.raises(ValueError, match=r"x must have shape \(\.\.\., 3\)"):
        lp.so(3).matrix(np.ones(2))
    with pytest.raises(ValueError, match=r"X must have shape \(\.\.\., 3, 3\)"):
        lp.so(3).coordinates(np.ones((4, 4)))
    assert lp.systems.LiePoissonSystem(lp.u(12), lambda m, xp: m[0] ** 2).group is None  # no constants formed


@pytest.mark.parametrize("n", [4, pytest.param(6, marks=pytest.mark.slow)])
def test_pfaffian_second_derivatives_against_the_expansion_also_where_it_degenerates(n):
    import jax
    import jax.numpy as jnp

    from liepoisson._pfaffian import pfaffian

    upper = np.triu_indices(n, 1)

    def on_entries(f):
        def g(x):
            A = jnp.zeros((n, n)).at[upper].set(x)
            return f(A - A.T)
        return g

    X = np.random.default_rng(10 + n).normal(size=(n, n))
    points = {
        "generic": X - X.T,
        "rank 2 (Pf = 0)": np.outer(X[0], X[1]) - np.outer(X[1], X[0]),
        "reduced columns": np.where(np.abs(X - X.T) > 1.2, X - X.T, 0.0),
        "zero": np.zeros((n, n)),
    }
    hessian = jax.jit(jax.hessian(on_entries(pfaffian)))
    expected_hessian = jax.jit(jax.hessian(on_entries(_pfaffian_by_expansion)))
    for name, A in points.items():
        x = jnp.asarray(A[upper])
        # the expansion is a polynomial written in jnp: JAX's derivatives of it are exact
        H = np.asarray(hessian(x))
        expected = np.asarray(expected_hessian(x))
        assert not np.isnan(H).any(), name
        np.testing.assert_allclose(H, expected, atol=64 * EPS * max(1.0, np.abs(A).max()) ** (n // 2 - 2), err_msg=name)


def test_se3_of_matrices_is_se3_of_structure_constants():
    # components (M12, M13, M23) = (-Pi3, Pi2, -Pi1) as for so(3), p as it is
    P = np.zeros((6, 6))
    P[:3, :3] = [[0, 0, -1], [0, 1, 0], [-1, 0, 0]]
    P[3:, 3:] = np.eye(3)
    g, h = lp.se(3), lp.se3()
    rng = np.random.default_rng(11)
    mu, alpha = rng.normal(size=(2, 6))
    # both are sums of a few O(1) products: a few eps
    np.testing.assert_allclose(P @ np.asarray(h.poisson_tensor(mu)) @ P.T, np.asarray(g.poisson_tensor(P @ mu)),
                               atol=8 * EPS)
    np.testing.assert_allclose(P @ np.asarray(h.coadjoint_flow(alpha, 0.8, mu)),
                               np.asarray(g.coadjoint_flow(P @ alpha, 0.8, P @ mu)), atol=64 * EPS)
    Pi, p = mu[:3], mu[3:]
    np.testing.assert_allclose(np.asarray(g.casimirs(P @ mu)), [p @ p, -(Pi @ p)], rtol=16 * EPS)


@pytest.mark.parametrize("N", [4, pytest.param(5, marks=pytest.mark.slow), pytest.param(6, marks=pytest.mark.slow)])
def test_se_casimirs_are_casimirs_kept_by_every_flow(N):
    g = lp.se(N)
    assert g.n_casimirs == 1 + (N - 1) // 2 and g.dim == N * (N + 1) // 2
    rng = np.random.default_rng(12 + N)
    mu = rng.normal(size=(3, g.dim))
    B, G = np.asarray(g.poisson_tensor(mu)), np.asarray(g.casimir_gradients(mu))
    # B grad C = 0: sums of dim products of O(|B||G|) terms
    assert np.abs(np.einsum("kab,kjb->kja", B, G)).max() < 64 * g.dim * EPS * np.abs(B).max() * np.abs(G).max()
    assert all(np.linalg.matrix_rank(Gk) == g.n_casimirs for Gk in G)
    assert g.orbit_dimension(mu[0]) == g.dim - g.n_casimirs
    # a finite flow (rotations and translations at once) keeps them to round-off of their size
    c0 = np.asarray(g.casimirs(mu[0]))
    c1 = np.asarray(g.casimirs(g.coadjoint_flow(rng.normal(size=g.dim), 0.7, mu[0])))
    scale = np.linalg.norm(G[0], axis=-1) * np.linalg.norm(mu[0])
    assert (np.abs(c1 - c0) / scale).max() < 1e3 * EPS
    with pytest.raises(ValueError, match="not isospectral"):
        g.spectrum(mu[0])


@pytest.mark.parametrize("g", [lp.u(3), pytest.param(lp.su(3), marks=pytest.mark.slow), lp.sl(3), lp.se(4)],
                         ids=lambda g: g.name)
def test_a_long_composition_of_flows_has_no_rounding_bias(g):
    # entries 1/sqrt2 (u, su), sqrt2 (se) and Helmert's (su, sl): coordinates(matrix(x)) rounds them with a
    # gain of one sign, ~1 eps a flow, a drift of the Casimirs linear in the number of flows
    # (~4000 eps here); unbiased, the round-off is a random walk, ~sqrt(4000) eps ~ 60 eps
    alpha_scale = 1.0 if g.family in ("u", "su", "se") else 0.02  # sl: non-compact, orbits unbounded
    assert casimir_change(g, 4000, seed=16, alpha_scale=alpha_scale).max() < 400 * EPS


@pytest.mark.parametrize("g", algebras({"so4", "u3", "su3"}))
def test_poisson_lstsq_is_the_pseudo_inverse(g):
    # so, u, su solve B(mu) xi = v in the eigenbasis of mu, the others through the dense
    # pseudo-inverse: both must be that pseudo-inverse (the minimum-norm least-squares solution),
    # also at mu = 0 (B = 0: xi = 0, no division) and where eigenvalues repeat.
    from liepoisson._abstract_algebra import AbstractLieAlgebra

    rng = np.random.default_rng(7)
    mu = rng.normal(size=(4, g.dim))
    v = rng.normal(size=(4, g.dim))  # not in the image of B: the least-squares part matters
    mu[0] = 0.0
    M = np.asarray(g.matrix(mu[1]))
    mu[2] = np.asarray(g.coordinates(M @ M @ M - M))  # for so, u: stays in the algebra
    if g.family in ("u", "su") and g.size >= 3:  # two equal eigenvalues: a stabiliser larger than generic
        Q = np.linalg.qr(rng.normal(size=(g.size, g.size)))[0]
        D = np.diag(np.r_[1.0, 1.0, np.arange(2.0, g.size)])
        mu[3] = np.asarray(g.coordinates(1j * Q @ D @ Q.T))
    got = np.asarray(g.poisson_lstsq(mu, v))
    dense = np.asarray(AbstractLieAlgebra.poisson_lstsq(g, mu, v))
    assert np.all(np.isfinite(got))
    np.testing.assert_array_equal(got[0], 0.0)
    # both backward stable: errors of a few eps times the largest |1/(m_k - m_j)| (O(1) here)
    np.testing.assert_allclose(got, dense, rtol=0, atol=256 * EPS * np.abs(dense).max())
    # and it is a least-squares solution: the residual is orthogonal to the image of B
    B = np.asarray(g.poisson_tensor(mu))
    r = v - np.einsum("...ab,...b->...a", B, got)
    # B^T r to round-off of B xi and of v, times |B| (mu[2] has large entries)
    size = np.abs(B).max(axis=(1, 2)) * (np.abs(v).max(axis=1) + np.abs(B).max(axis=(1, 2)) * np.abs(got).max(axis=1))
    assert np.all(np.abs(np.einsum("...ab,...a->...b", B, r)).max(axis=1) <= 256 * EPS * size)


# the semidirect products' gradients are reverse mode itself: nothing to compare
@pytest.mark.parametrize("g", [p for p in algebras({"u3", "sl3"}) if not p.values[0].is_semidirect])
def test_casimir_gradients_in_closed_form_equal_reverse_mode(g):
    # the closed form s p <(c X^(p-1))^dagger, E_a>/kappa against jax.jacrev of the values (and
    # se's, which is jacrev itself); round-off of the powers, O(1) entries
    import jax

    mu = np.random.default_rng(4).normal(size=(3, g.dim))
    mu[1] = 0.0  # every power vanishes: the gradients of tr X^p (p > 1) are zero, not NaN
    got = np.asarray(g.casimir_gradients(mu))
    reference = np.asarray(jax.vmap(jax.jacrev(g._casimir_values))(mu))
    assert got.shape == (3, g.n_casimirs, g.dim)
    np.testing.assert_allclose(got, reference, rtol=0, atol=64 * EPS * np.abs(reference).max())
