"""Automatic polynomial Casimirs: counts, degrees, zero bracket with every coordinate, span
equal to the closed forms; the pendulum's Casimir over 10^4 composed test flows."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS, algebra, algebra_names, system

import liepoisson as lp


def _poisson_tensor(C, mu):
    return -np.einsum("abd,d->ab", C, mu)


def _grad(p: lp.Polynomial, mu):
    return np.array([float(g.evaluate(list(mu))) for g in p.gradient()])


def _assert_casimir(C, p, n_points=5, seed=0):
    """{mu_a, P} = (B(mu) grad P)_a = 0 at random points (exact polynomial identity, so the
    residual is round-off: entries of B grad P are sums of ~n^2 products of O(1) numbers)."""
    rng = np.random.default_rng(seed)
    n = C.shape[0]
    for mu in rng.standard_normal((n_points, n)):
        g = _grad(p, mu)
        assert np.linalg.norm(g) > 1e-3  # not trivially zero
        r = _poisson_tensor(C, mu) @ g
        assert np.max(np.abs(r)) < 64 * n * n * EPS * max(1.0, np.max(np.abs(g))), r


def _span_equal(ps, qs, n, degree, seed=0):
    """The homogeneous polynomials ps and qs span the same space (coefficient vectors)."""
    monos = {}
    for k in range(degree + 1):
        for combo in itertools.combinations_with_replacement(range(n), k):
            e = [0] * n
            for i in combo:
                e[i] += 1
            monos.setdefault(tuple(e), len(monos))

    def vec(p):
        v = np.zeros(len(monos))
        for c, e in p.terms:
            v[monos[e]] += c
        return v

    P = np.array([vec(p) for p in ps])
    Q = np.array([vec(q) for q in qs])
    r = np.linalg.matrix_rank
    return r(P) == r(Q) == r(np.vstack([P, Q]))


CATALOGUE = {
    "so3": (1, [2]),
    "se3": (2, [2, 2]),
    "se2": (1, [2]),
    "sl2": (1, [2]),
    "heisenberg": (1, [1]),
}


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_automatic_casimirs_of_the_catalogue(name):
    g = algebra(name)
    auto = lp.polynomial_casimirs(g.structure_constants)
    count, degrees = CATALOGUE[name]
    assert len(auto) == count
    assert sorted(p.degree for p in auto) == degrees
    for p in auto:
        _assert_casimir(g.structure_constants, p)
    # closed forms in the catalogue are Casimirs too, and span the same space
    assert g.n_casimirs == count
    for p in g.casimir_polynomials:
        _assert_casimir(g.structure_constants, p)
    assert _span_equal(auto, g.casimir_polynomials, g.dim, max(degrees))


def test_se3_automatic_casimirs_span_p2_and_pi_dot_p():
    auto = lp.polynomial_casimirs(algebra("se3").structure_constants)
    p2 = lp.Polynomial(6, ((1.0, (0, 0, 0, 2, 0, 0)), (1.0, (0, 0, 0, 0, 2, 0)), (1.0, (0, 0, 0, 0, 0, 2))))
    pip = lp.Polynomial(6, ((1.0, (1, 0, 0, 1, 0, 0)), (1.0, (0, 1, 0, 0, 1, 0)), (1.0, (0, 0, 1, 0, 0, 1))))
    assert _span_equal(auto, [p2, pip], 6, 2)


def test_generic_lie_algebra_computes_casimirs():
    g = algebra("generic_so3")
    assert g.n_casimirs == 1 and g.casimir_polynomials[0].degree == 2
    mu = np.array([0.3, -1.2, 2.0])
    c = float(g.casimirs(mu)[0])
    # proportional to |mu|^2 (the only quadratic Casimir of so(3))
    c_unit = float(g.casimirs(np.array([1.0, 0.0, 0.0]))[0])
    assert abs(c - c_unit * np.dot(mu, mu)) < 8 * EPS * abs(c)


def test_affine_algebra_has_no_polynomial_casimirs():
    C = np.zeros((2, 2, 2))
    C[0, 1, 1], C[1, 0, 1] = 1.0, -1.0  # [e1, e2] = e2
    assert lp.polynomial_casimirs(C) == ()
    g = lp.LieAlgebra(C)
    assert g.n_casimirs == 0
    assert g.casimirs(np.ones(2)).shape == (0,)
    assert g.casimir_gradients(np.ones((5, 2))).shape == (5, 0, 2)


def test_so3_plus_so3_gives_two_quadratics():
    C = lp.direct_sum(lp.so3(), lp.so3()).structure_constants
    auto = lp.polynomial_casimirs(C)
    assert [p.degree for p in auto] == [2, 2]
    for p in auto:
        _assert_casimir(C, p)
    a = lp.Polynomial(6, tuple((1.0, tuple(2 * (i == j) for i in range(6))) for j in range(3)))
    b = lp.Polynomial(6, tuple((1.0, tuple(2 * (i == j) for i in range(6))) for j in range(3, 6)))
    assert _span_equal(auto, [a, b], 6, 2)


def test_gl2_has_a_linear_and_a_quadratic_casimir():
    C = np.zeros((4, 4, 4))
    C[:3, :3, :3] = lp.sl2().structure_constants  # gl(2) = sl(2) + R (identity is central)
    auto = lp.polynomial_casimirs(C)
    assert sorted(p.degree for p in auto) == [1, 2]
    for p in auto:
        _assert_casimir(C, p)


def _sl3():
    """sl(3, R) in the basis E_ij (i != j), H1 = E11 - E22, H2 = E22 - E33; constants from
    matrix commutators, Casimirs tr(X^2), tr(X^3) under the trace pairing."""
    basis = []
    for i in range(3):
        for j in range(3):
            if i != j:
                E = np.zeros((3, 3)); E[i, j] = 1.0
                basis.append(E)
    basis.append(np.diag([1.0, -1.0, 0.0]))
    basis.append(np.diag([0.0, 1.0, -1.0]))
    B = np.array([b.reshape(-1) for b in basis]).T  # 9 x 8
    C = np.zeros((8, 8, 8))
    for a, b in itertools.product(range(8), repeat=2):
        comm = basis[a] @ basis[b] - basis[b] @ basis[a]
        C[a, b] = np.linalg.lstsq(B, comm.reshape(-1), rcond=None)[0]
    return np.round(C, 12)


def test_higher_degree_sl3_has_a_cubic_casimir():
    C = _sl3()
    g = lp.LieAlgebra(C, name="sl3")  # validates antisymmetry and Jacobi on the way
    assert sorted(p.degree for p in g.casimir_polynomials) == [2, 3]
    for p in g.casimir_polynomials:
        _assert_casimir(C, p)


@algebra_names
def test_casimir_gradients_match_autodiff_and_kernel(name):
    g = algebra(name)
    rng = np.random.default_rng(20)
    mu = rng.standard_normal(g.dim)
    G = np.asarray(g.casimir_gradients(mu))
    J = np.asarray(jax.jacfwd(g.casimirs)(jnp.asarray(mu)))
    np.testing.assert_allclose(G, J, atol=8 * EPS * max(1.0, np.max(np.abs(G))))
    # gradients are in the kernel of B and independent at a generic point
    np.testing.assert_allclose(np.asarray(g.poisson_tensor(mu)) @ G.T, 0.0, atol=64 * EPS)
    assert np.linalg.matrix_rank(G) == g.n_casimirs == g.dim - g.orbit_dimension(mu)


# -- the pendulum's Casimir over 10^4 composed test flows --------------------------------------
def test_pendulum_casimir_over_composed_test_flows():
    sys = system("ExtendedPendulum")
    rng = np.random.default_rng(21)
    N = 10_000
    alphas = jnp.asarray(rng.uniform(-1, 1, (N, 3)))
    y0 = jnp.array([0.3, 1.0, 2.5])

    def step(y, a):
        y = sys.test_flow(a, 0.05, y)
        return y, y

    _, ys = jax.jit(lambda y, a: jax.lax.scan(step, y, a))(y0, alphas)
    ys = np.asarray(ys)
    c = np.asarray(sys.casimirs(ys))[:, 0]
    c0 = float(sys.casimirs(y0)[0])
    # r is rebuilt from the conserved C each step (r = C + u^2 + v^2), so each step errs by
    # ~2 eps (u^2 + v^2 + |C|); bounded linearly in N, 4 N eps max(u^2 + v^2 + |C|).
    size = np.max(ys[:, 0] ** 2 + ys[:, 1] ** 2) + abs(c0)
    assert np.max(np.abs(c - c0)) <= 4 * N * EPS * size
    assert np.max(np.abs(ys[-1] - np.asarray(y0))) > 0.1


def test_casimir_scale_is_gradient_norm_times_state_norm():
    """so(3): the Casimir is c |Pi|^2, its gradient 2 c Pi, so the scale |grad C| |Pi| is 2 |C(Pi)|."""
    from liepoisson.internals import casimir_scale

    body = lp.systems.RigidBody()
    y = np.random.default_rng(0).normal(size=(5, 4, 3))
    scale = casimir_scale(np.asarray(body.casimir_gradients(y)), y)
    assert scale.shape == (5, 4, 1)
    np.testing.assert_allclose(scale, 2 * np.abs(np.asarray(body.casimirs(y))), rtol=4 * EPS)


@pytest.mark.parametrize("name", ["so3", "se3", "sl2"])
def test_system_and_algebra_evaluate_casimirs_alike(name):
    """A Lie-Poisson system's Casimirs and their gradients are its algebra's, to the bit."""
    g = algebra(name)
    s = lp.systems.LiePoissonSystem(g, lambda y, xp: 0.5 * sum(v * v for v in y))
    y = np.random.default_rng(1).normal(size=(7, g.dim))
    np.testing.assert_array_equal(np.asarray(s.casimirs(y)), np.asarray(g.casimirs(y)))
    np.testing.assert_array_equal(np.asarray(s.casimir_gradients(y)), np.asarray(g.casimir_gradients(y)))
