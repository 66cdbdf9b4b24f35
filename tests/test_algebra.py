"""LieAlgebra: structure constants against matrix representations, bracket/ad/ad*/B
consistency, Jacobi identity of B, orbit dimensions, batching and JAX transformations."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS, algebra, algebra_names, reference_poisson_tensor

import liepoisson as lp


def _hat(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]], dtype=float)


def _matrix_basis(name):
    """Faithful matrix representations, written from the textbook definitions."""
    E = np.eye(3)
    if name in ("so3", "generic_so3", "so3_spatial"):
        return [_hat(e) for e in E]
    if name == "se3":  # (A, b) -> [[hat A, b], [0, 0]]
        out = []
        for a in range(6):
            X = np.zeros((4, 4))
            if a < 3:
                X[:3, :3] = _hat(E[a])
            else:
                X[:3, 3] = E[a - 3]
            out.append(X)
        return out
    if name == "se2":  # theta -> rotation generator, x, y -> translations
        th = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 0.0]])
        x = np.zeros((3, 3)); x[0, 2] = 1
        y = np.zeros((3, 3)); y[1, 2] = 1
        return [th, x, y]
    if name == "sl2":
        return [np.array([[1, 0], [0, -1.0]]), np.array([[0, 1], [0, 0.0]]), np.array([[0, 0], [1, 0.0]])]
    if name == "heisenberg":
        X = [np.zeros((3, 3)) for _ in range(3)]
        X[0][0, 1], X[1][1, 2], X[2][0, 2] = 1, 1, 1
        return X
    raise KeyError(name)


@pytest.mark.parametrize("name", ["so3", "se3", "se2", "sl2", "heisenberg", "generic_so3"])
def test_structure_constants_match_matrix_commutators(name):
    """[E_a, E_b] = C_abd E_d for a faithful matrix representation (textbook basis)."""
    g = algebra(name)
    basis = _matrix_basis(name)
    C = g.structure_constants
    for a in range(g.dim):
        for b in range(g.dim):
            comm = basis[a] @ basis[b] - basis[b] @ basis[a]
            expected = sum(C[a, b, d] * basis[d] for d in range(g.dim))
            np.testing.assert_array_equal(comm, expected)


def test_direct_sum_is_block_diagonal():
    g = algebra("so3+heisenberg")
    C = g.structure_constants
    np.testing.assert_array_equal(C[:3, :3, :3], lp.levi_civita())
    np.testing.assert_array_equal(C[3:, 3:, 3:], lp.heisenberg().structure_constants)
    mask = np.zeros_like(C, dtype=bool)
    mask[:3, :3, :3] = mask[3:, 3:, 3:] = True
    assert np.all(C[~mask] == 0)
    assert g.dim == 6 and g.n_casimirs == 2


@algebra_names
def test_bracket_ad_ad_star_consistency(name):
    g = algebra(name)
    rng = np.random.default_rng(10)
    xi, eta, mu = rng.standard_normal((3, g.dim))
    br = np.asarray(g.bracket(xi, eta))
    C = g.structure_constants
    ref = np.array([sum(C[a, b, d] * xi[a] * eta[b] for a in range(g.dim) for b in range(g.dim)) for d in range(g.dim)])
    tol = 16 * EPS * g.dim**2  # sums of n^2 products of O(1) numbers
    np.testing.assert_allclose(br, ref, atol=tol)
    np.testing.assert_allclose(np.asarray(g.bracket(eta, xi)), -br, atol=tol)
    np.testing.assert_allclose(np.asarray(g.ad(xi)) @ eta, br, atol=tol)
    # <ad*_xi mu, eta> = <mu, [xi, eta]>
    assert abs(np.dot(np.asarray(g.ad_star(xi, mu)), eta) - np.dot(mu, br)) < tol * 4
    # B(mu) = sign * (<mu, [e_a, e_b]>)_ab, and B(mu) alpha = sign * ad*_alpha... in body form
    B = np.asarray(g.poisson_tensor(mu))
    np.testing.assert_allclose(B, reference_poisson_tensor(C, mu, g.sign), atol=tol)
    # {F, H} = -<mu, [dF, dH]> for linear F, H (docs/conventions.md, body sign)
    assert abs(xi @ B @ eta - g.sign * np.dot(mu, br)) < tol * 4
    # Jacobi identity of the bracket of the algebra: [x,[y,z]] + cyclic = 0
    z = rng.standard_normal(g.dim)
    jac = g.bracket(xi, g.bracket(eta, z)) + g.bracket(eta, g.bracket(z, xi)) + g.bracket(z, g.bracket(xi, eta))
    np.testing.assert_allclose(np.asarray(jac), 0.0, atol=tol * 8)


@pytest.mark.parametrize("name", ["so3", "generic_so3", "so3_spatial"])
def test_so3_is_the_cross_product_and_euler(name):
    g = algebra(name)
    rng = np.random.default_rng(11)
    x, y = rng.standard_normal((2, 3))
    np.testing.assert_allclose(np.asarray(g.bracket(x, y)), np.cross(x, y), atol=4 * EPS)
    # B(Pi) Omega = Pi x Omega for the body convention (Euler), minus for spatial
    B = np.asarray(g.poisson_tensor(x))
    np.testing.assert_allclose(B @ y, -g.sign * np.cross(x, y), atol=8 * EPS)


def _numerical_jacobi(B_fn, y):
    """max_ijk |sum_l B_il d_l B_jk + B_jl d_l B_ki + B_kl d_l B_ij| (JAX derivatives of B)."""
    B = B_fn(y)
    dB = jax.jacfwd(B_fn)(y)  # dB[j, k, l] = d_l B_jk
    t = jnp.einsum("il,jkl->ijk", B, dB)
    return float(jnp.max(jnp.abs(t + jnp.transpose(t, (1, 2, 0)) + jnp.transpose(t, (2, 0, 1)))))


@algebra_names
def test_poisson_tensor_antisymmetric_and_jacobi(name):
    g = algebra(name)
    rng = np.random.default_rng(12)
    for mu in rng.standard_normal((3, g.dim)):
        B = np.asarray(g.poisson_tensor(mu))
        np.testing.assert_array_equal(B, -B.T)
        assert _numerical_jacobi(g.poisson_tensor, jnp.asarray(mu)) < 64 * EPS


def test_numerical_jacobi_detects_a_non_poisson_tensor():
    """Sanity check of the checker: in 3-D, B_ij = eps_ijk v_k is Poisson iff v . curl v = 0;
    v = (y2, y3, y1) has v . curl v = -(y1 + y2 + y3)."""
    def bad(y):
        v = jnp.array([y[1], y[2], y[0]])
        return jnp.array([[0.0, v[2], -v[1]], [-v[2], 0.0, v[0]], [v[1], -v[0], 0.0]])
    assert _numerical_jacobi(bad, jnp.array([0.3, 0.7, 1.1])) > 0.1


def test_orbit_dimension():
    rng = np.random.default_rng(13)
    so3, se3 = algebra("so3"), algebra("se3")
    assert so3.orbit_dimension(rng.standard_normal(3)) == 2
    assert so3.orbit_dimension(np.zeros(3)) == 0
    assert so3.orbit_dimension(1e-6 * rng.standard_normal(3)) == 2
    assert se3.orbit_dimension(rng.standard_normal(6)) == 4
    # p = 0: orbits are spheres in Pi, dimension 2; the origin is a point
    assert se3.orbit_dimension(np.array([1.0, 2.0, 3.0, 0, 0, 0])) == 2
    assert se3.orbit_dimension(np.zeros(6)) == 0
    assert algebra("heisenberg").orbit_dimension(np.array([5.0, 1.0, 0.0])) == 0
    assert algebra("heisenberg").orbit_dimension(np.array([5.0, 1.0, 0.3])) == 2
    batch = so3.orbit_dimension(np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(batch, [2, 0])


def test_structure_constants_read_only():
    g = algebra("so3")
    with pytest.raises(ValueError):
        g.structure_constants[0, 1, 2] = 5.0


@algebra_names
def test_batching_and_transformations(name):
    g = algebra(name)
    rng = np.random.default_rng(14)
    mu = rng.standard_normal((2, 4, g.dim))
    B = np.asarray(g.poisson_tensor(mu))
    assert B.shape == (2, 4, g.dim, g.dim)
    for i in range(2):
        for j in range(4):
            np.testing.assert_array_equal(B[i, j], np.asarray(g.poisson_tensor(mu[i, j])))
    np.testing.assert_allclose(np.asarray(jax.jit(g.poisson_tensor)(mu)), B, atol=4 * EPS)
    np.testing.assert_allclose(np.asarray(jax.vmap(g.poisson_tensor)(mu[0])), B[0], atol=4 * EPS)
    assert g.bracket(mu, mu[::-1]).shape == (2, 4, g.dim)
    assert g.ad(mu).shape == (2, 4, g.dim, g.dim)
    assert g.ad_star(mu, mu).shape == (2, 4, g.dim)
    c = np.asarray(g.casimirs(mu))
    assert c.shape == (2, 4, g.n_casimirs)
    np.testing.assert_allclose(c[1, 2], np.asarray(g.casimirs(mu[1, 2])), atol=4 * EPS)
    assert g.casimir_gradients(mu).shape == (2, 4, g.n_casimirs, g.dim)
    # grad of a scalar function of the tensor: d/dmu sum(B(mu) w . v) = sign C_abd w_a v_b
    w, v = rng.standard_normal((2, g.dim))
    grad = np.asarray(jax.grad(lambda m: w @ g.poisson_tensor(m) @ v)(jnp.asarray(mu[0, 0])))
    ref = g.sign * np.einsum("abd,a,b->d", g.structure_constants, w, v)
    np.testing.assert_allclose(grad, ref, atol=16 * EPS)


def test_sign_convention_reverses_time():
    body, spatial = algebra("so3"), algebra("so3_spatial")
    rng = np.random.default_rng(15)
    a, mu = rng.standard_normal((2, 3))
    np.testing.assert_array_equal(np.asarray(spatial.poisson_tensor(mu)), -np.asarray(body.poisson_tensor(mu)))
    np.testing.assert_allclose(
        np.asarray(spatial.coadjoint_flow(a, 0.7, mu)), np.asarray(body.coadjoint_flow(a, -0.7, mu)), atol=4 * EPS
    )


def test_repr_and_names():
    g = algebra("se3")
    assert "se3" in repr(g) and g.basis_names == ("Pi1", "Pi2", "Pi3", "p1", "p2", "p3")
    assert algebra("so3+heisenberg").basis_names[3] == "heisenberg.mu_x"


# -- LieAlgebra.from_matrices ---------------------------------------------------------------
def test_from_matrices_gives_the_constants_of_so3_and_checks_its_input():
    # so(3) in the basis of hat maps: [hat(e_a), hat(e_b)] = eps_abd hat(e_d), the Levi-Civita
    # constants written out by hand.
    hat = np.zeros((3, 3, 3))
    for a, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        hat[a, i, j], hat[a, j, i] = -1.0, 1.0
    g = lp.LieAlgebra.from_matrices(hat, "so3 from matrices")
    eps = np.zeros((3, 3, 3))
    for a, b, d in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps[a, b, d], eps[b, a, d] = 1.0, -1.0
    # lstsq of an exact integer system: round-off of a few eps.
    np.testing.assert_allclose(g.structure_constants, eps, atol=16 * EPS)
    assert g.n_casimirs == 1 and g.name == "so3 from matrices"
    with pytest.raises(ValueError, match=r"linearly dependent"):
        lp.LieAlgebra.from_matrices(np.stack([hat[0], hat[1], hat[0] + hat[1]]))
    sym = np.zeros((2, 2, 2))
    sym[0] = [[1.0, 0.0], [0.0, -1.0]]
    sym[1] = [[0.0, 1.0], [1.0, 0.0]]  # [sym0, sym1] is antisymmetric: leaves the span
    with pytest.raises(ValueError, match=r"\[E_0, E_1\] is not in the span"):
        lp.LieAlgebra.from_matrices(sym)
    with pytest.raises(ValueError, match=r"basis must be an array \(n, m, m\).*\(3, 3\)"):
        lp.LieAlgebra.from_matrices(np.eye(3))
    with pytest.raises(TypeError, match=r"basis must be an array"):
        lp.LieAlgebra.from_matrices("so3")
    with pytest.raises(ValueError, match=r"basis must be finite"):
        lp.LieAlgebra.from_matrices(hat * np.nan)
