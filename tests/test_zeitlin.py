"""Zeitlin's model: the quantized Laplacian against its closed forms (spectrum -l(l+1), the
double commutator of the spin generators), the spherical-harmonic map, the Hamiltonian against
autodiff and the harmonic expansion, and the isospectral methods against heyoka."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from liepoisson import _quantized_sphere as qs

EPS = np.finfo(np.float64).eps


def _spin(N):
    s = (N - 1) / 2
    m = np.arange(-s, s)
    d = np.sqrt(s * (s + 1) - m * (m + 1))
    S3 = 1j * np.diag(np.arange(-s, s + 1))
    S1 = 0.5j * (np.diag(d, 1) + np.diag(d, -1))
    S2 = 0.5 * (np.diag(d, 1) - np.diag(d, -1))
    return S1, S2, S3


def _skew(N, seed):
    rng = np.random.default_rng(seed)
    W = rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N))
    return W - W.conj().T


def test_laplacian_is_the_double_commutator_with_spectrum_minus_l_l_plus_1():
    N = 6
    W = _skew(N, 0)
    comm = lambda A, B: A @ B - B @ A
    reference = sum(comm(S, comm(S, W)) for S in _spin(N))
    np.testing.assert_allclose(np.asarray(qs.laplacian(W)), reference, atol=64 * N * EPS * np.abs(W).max())
    L = np.stack([np.asarray(qs.laplacian(E.reshape(N, N))).ravel() for E in np.eye(N * N, dtype=complex)], axis=1)
    eigenvalues = np.sort(np.linalg.eigvals(L).real)
    expected = np.sort(np.concatenate([[-l * (l + 1)] * (2 * l + 1) for l in range(N)]))
    np.testing.assert_allclose(eigenvalues, expected, atol=1e3 * EPS * N * N)


@pytest.mark.parametrize("N", [2, pytest.param(3, marks=pytest.mark.slow), 17])  # the smallest and a large N by default
def test_poisson_solve_inverts_the_laplacian_on_traceless_matrices(N):
    W = _skew(N, N)
    P = np.asarray(qs.solve_poisson(W))
    scale = np.abs(W).max()
    np.testing.assert_allclose(np.asarray(qs.laplacian(P)), W - np.trace(W) / N * np.eye(N), atol=256 * N * EPS * scale)
    assert abs(np.trace(P)) < 64 * N * EPS * scale
    np.testing.assert_array_equal(P, -P.conj().T)
    # the identity (the Laplacian's kernel) is ignored
    np.testing.assert_allclose(np.asarray(qs.solve_poisson(W + 3j * np.eye(N))), P, atol=64 * N * EPS * scale)


def test_harmonic_basis_maps_and_eigenvectors():
    N = 7
    rng = np.random.default_rng(1)
    omega = rng.normal(size=N * N)
    W = qs.harmonics_to_matrix(omega, N)
    np.testing.assert_array_equal(W, -W.conj().T)
    np.testing.assert_allclose(qs.matrix_to_harmonics(W), omega, atol=32 * EPS)
    assert abs(np.linalg.norm(W) / np.sqrt(N) - np.linalg.norm(omega)) < 32 * EPS  # an isometry
    for l, m in [(0, 0), (1, 1), (3, -2), (6, 6)]:
        e = np.zeros(N * N)
        e[l * l + l + m] = 1.0
        T = qs.harmonics_to_matrix(e, N)
        np.testing.assert_allclose(np.asarray(qs.laplacian(T)), -l * (l + 1) * T, atol=256 * EPS)
    # T_{1,m} = sqrt(3) hbar S_a (quflow: X_a = hbar S_a; T_{1,1} ~ x, T_{1,-1} ~ y, T_{1,0} ~ z)
    for m, S in zip((1, -1, 0), _spin(N)):
        e = np.zeros(N * N)
        e[2 + m] = 1.0
        np.testing.assert_allclose(qs.harmonics_to_matrix(e, N), np.sqrt(3) * qs.hbar(N) * S, atol=16 * EPS)


def test_vorticity_of_a_single_harmonic_on_the_grid():
    N = 5
    e = np.zeros(N * N)
    e[2] = 1.0  # omega_{1,0}: sqrt(4 pi) Y_1^0 = sqrt(3) cos(theta)
    theta, phi, f = qs.vorticity_on_grid(qs.harmonics_to_matrix(e, N), 8, 6)
    np.testing.assert_allclose(f, np.sqrt(3) * np.cos(theta)[:, None] * np.ones(6), atol=64 * EPS)
    assert f.shape == (8, 6) and phi.shape == (6,)


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_zeitlin_hamiltonian_gradient_and_vector_field():
    z = lp.systems.Zeitlin(4)
    y = z.random_state(0)
    g = z.algebra
    H = float(z.hamiltonian(y))
    # H = tr(PW) / (2 hbar) = (N / hbar) * 1/2 sum omega_lm^2 / (l (l + 1))  (quflow's energy times N/hbar)
    omega = z.harmonics(y)
    ls = np.floor(np.sqrt(np.arange(z.N**2)))
    expansion = 0.5 * np.sum(omega[1:] ** 2 / (ls[1:] * (ls[1:] + 1)))
    assert abs(H - z.N / z.hbar * expansion) < 64 * EPS * H
    np.testing.assert_allclose(np.asarray(jax.grad(z.hamiltonian)(jnp.asarray(y))), np.asarray(z.hamiltonian_gradient(y)),
                               atol=64 * EPS * np.abs(np.asarray(z.hamiltonian_gradient(y))).max())
    W = g.matrix(y)
    P = z.stream_matrix(W)
    np.testing.assert_allclose(np.asarray(z.vector_field(y)), np.asarray(g.coordinates((P @ W - W @ P) / z.hbar)),
                               atol=64 * EPS * np.abs(np.asarray(z.vector_field(y))).max())
    comps = z.hamiltonian_components(list(y), lp.NUMPY)  # the quadratic form heyoka is built from
    assert abs(float(comps) - H) < 1e3 * EPS * H


def test_a_field_of_degree_one_is_steady():
    # P = -W / 2 on l = 1: [P, W] = 0 (solid-body rotation)
    z = lp.systems.Zeitlin(5)
    omega = np.zeros(25)
    omega[1:4] = [0.3, -0.5, 0.8]
    y = z.state_from_harmonics(omega)
    assert np.abs(np.asarray(z.vector_field(y))).max() < 64 * EPS


@pytest.mark.parametrize(("method", "order"), [pytest.param(it.IsospectralMidpoint, 2, marks=pytest.mark.slow),
                                               pytest.param(it.IsospectralTripleJump, 4, marks=pytest.mark.slow)])
def test_isospectral_methods_on_zeitlin_against_heyoka(method, order):
    z = lp.systems.Zeitlin(5)
    y0 = z.random_state(2)
    conv = it.convergence(lambda h: method(z, h, tol=1e-14), z, y0, t_final=1.0, hs=[0.1, 0.05, 0.025])
    assert abs(conv.order - order) < 0.1


@pytest.mark.slow
def test_zeitlin_rollout_keeps_the_spectrum_with_a_fixed_iteration_count():
    z = lp.systems.Zeitlin(8)
    y0 = z.random_state(3)
    adaptive = it.IsospectralMidpoint(z, 0.05, tol=1e-10)
    mean, most = adaptive.iterations_needed(y0, 20)
    assert 1 <= mean <= most
    fixed = it.IsospectralMidpoint(z, 0.05, tol=1e-10, iterations=most + 1)
    ys = np.asarray(fixed.rollout(y0, 200, save_every=50))
    s = np.asarray(z.algebra.spectrum(ys))
    assert np.abs(s - s[0]).max() < 1e-13 * np.abs(s[0]).max()
    ya = np.asarray(adaptive.rollout(y0, 200, save_every=50))
    np.testing.assert_allclose(ys, ya, atol=1e-8 * np.abs(ya).max())  # both converged to tol
    # too few iterations: the step is NaN, and the rollout says what to do
    with pytest.raises(it.RolloutDivergedError, match="iterations="):
        it.IsospectralMidpoint(z, 0.05, tol=1e-14, iterations=1).rollout(y0, 5)


def test_zeitlin_bad_input_and_file_round_trip():
    with pytest.raises((ValueError, TypeError), match="N"):
        lp.systems.Zeitlin(1)
    z = lp.systems.Zeitlin(4)
    with pytest.raises(ValueError, match="omega"):
        z.state_from_harmonics(np.zeros(15))
    with pytest.raises(ValueError, match="lmax"):
        z.random_state(lmax=4)
    assert lp.systems.from_name(z.name, z.params) == z
