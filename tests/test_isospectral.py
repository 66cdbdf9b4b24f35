"""The generalized rigid body on so(N) and the isospectral integrators: against heyoka (observed
orders), against Euler's rigid body at N = 3, and Casimirs / spectrum over long runs."""

import numpy as np
import pytest

import integrators as it
import liepoisson as lp

EPS = np.finfo(np.float64).eps
J4 = (1.0, 1.3, 1.9, 2.6)


def test_generalized_rigid_body_at_n3_is_eulers_rigid_body():
    J = np.array([1.0, 1.5, 2.25])
    body = lp.systems.GeneralizedRigidBody(J)
    euler = lp.systems.RigidBody(inertia=(J[1] + J[2], J[0] + J[2], J[0] + J[1]))
    # (M12, M13, M23) = (-Pi3, Pi2, -Pi1)
    P = np.array([[0, 0, -1], [0, 1, 0], [-1, 0, 0]], dtype=float)
    Pi = np.random.default_rng(0).normal(size=(4, 3))
    np.testing.assert_allclose(np.asarray(body.vector_field(Pi @ P.T)), np.asarray(euler.vector_field(Pi)) @ P.T,
                               atol=8 * EPS)
    np.testing.assert_allclose(np.asarray(body.hamiltonian(Pi @ P.T)), np.asarray(euler.hamiltonian(Pi)), rtol=4 * EPS)


def test_velocity_matrix_is_minus_the_angular_velocity():
    body = lp.systems.GeneralizedRigidBody(J4)
    y = np.random.default_rng(1).normal(size=body.dim)
    M = body.algebra.matrix(y)
    Omega = np.asarray(body.algebra.matrix(body.hamiltonian_gradient(y)))
    np.testing.assert_allclose(np.asarray(body.velocity_matrix(M)), -Omega, atol=4 * EPS)
    J = np.diag(J4)
    np.testing.assert_allclose(J @ Omega + Omega @ J, np.asarray(M), atol=8 * EPS)
    # the isospectral methods' generic path (-matrix of the generator) agrees with the system's own
    np.testing.assert_allclose(np.asarray(lp.systems.LiePoissonSystem(body.algebra, body.hamiltonian_components)
                                          .velocity_matrix(M)), np.asarray(body.velocity_matrix(M)), atol=4 * EPS)


@pytest.mark.parametrize(("method", "order"), [(it.IsospectralMidpoint, 2), (it.IsospectralTripleJump, 4)])
def test_isospectral_methods_converge_at_their_order_against_heyoka(method, order):
    body = lp.systems.GeneralizedRigidBody(J4)
    y0 = np.random.default_rng(2).normal(size=(2, body.dim))
    conv = it.convergence(lambda h: method(body, h, tol=1e-14), body, y0, t_final=1.0, hs=[0.1, 0.05, 0.025])
    assert abs(conv.order - order) < 0.1


@pytest.mark.slow
def test_strang_splitting_of_the_generalized_rigid_body_against_heyoka():
    body = lp.systems.GeneralizedRigidBody(J4)
    y0 = np.random.default_rng(3).normal(size=(2, body.dim))
    conv = it.convergence(lambda h: it.splitting.Strang(body, h), body, y0, t_final=1.0, hs=[0.1, 0.05, 0.025])
    assert abs(conv.order - 2) < 0.1


@pytest.mark.parametrize("make", [lambda: lp.systems.GeneralizedRigidBody((1.0, 1.2, 1.7, 2.0, 3.1)),
                                  pytest.param(lambda: lp.systems.LiePoissonSystem(
                                      lp.u(3), lambda m, xp: sum((k + 1.0) * m[k] ** 2 for k in range(9)) / 2),
                                      marks=pytest.mark.slow)],
                         ids=["so5", "u3"])
def test_isospectral_midpoint_keeps_casimirs_and_spectrum_over_long_runs(make):
    system = make()
    g = system.algebra
    y0 = np.random.default_rng(4).normal(size=g.dim)
    # steps well inside the stability region: h |Omega| ~ 0.1 (u3's weights reach 9, so |Omega| ~ 27)
    method = it.IsospectralMidpoint(system, 0.05 if g.family == "so" else 0.004)
    ys = np.asarray(method.rollout(y0, 1000, save_every=20))
    c = np.asarray(g.casimirs(ys))
    s = np.asarray(g.spectrum(ys))
    # each step is a conjugation by a Cayley transform, unitary to a few eps: a random walk of
    # round-off over 1000 steps stays below 1e-13 of each Casimir's size sum_i |lambda_i|^k
    # (its value, for the even powers; an odd power's value may be much smaller)
    powers = [2 * k for k in range(1, g.n_casimirs + 1)] if g.family == "so" else range(1, g.n_casimirs + 1)
    size = np.array([np.sum(np.abs(s[0]) ** k) for k in powers]) / (2 if g.family == "so" else 1)
    assert (np.abs(c - c[0]) / size).max() < 1e-13
    assert np.abs(s - s[0]).max() < 1e-13 * np.abs(s[0]).max()
    # the energy is not exactly kept, but bounded: no drift over the run
    H = np.asarray(system.hamiltonian(ys))
    assert np.abs(H - H[0]).max() < 1e-3 * abs(H[0])
    mean, most = method.iterations_needed(y0, 10)
    assert 1 <= mean <= most < 30


@pytest.mark.slow  # the benchmark measures it for N = 3..10 (BENCHMARKS.md)
def test_strang_keeps_the_casimirs_of_so4():
    body = lp.systems.GeneralizedRigidBody(J4)
    y0 = np.random.default_rng(5).normal(size=body.dim)
    ys = np.asarray(it.splitting.Strang(body, 0.05).rollout(y0, 500, save_every=50))
    c = np.asarray(body.casimirs(ys))
    assert (np.abs(c - c[0]) / np.abs(c[0])).max() < 1e-13


def test_bad_input():
    with pytest.raises(TypeError, match="compact matrix algebra"):
        it.IsospectralMidpoint(lp.systems.RigidBody(), 0.1)
    with pytest.raises(TypeError, match="compact matrix algebra"):
        it.IsospectralMidpoint(lp.systems.LiePoissonSystem(lp.gl(2), lambda m, xp: m[0] ** 2), 0.1)
    body = lp.systems.GeneralizedRigidBody(J4)
    for h in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="h"):
            it.IsospectralMidpoint(body, h)
    with pytest.raises(ValueError, match="tol"):
        it.IsospectralMidpoint(body, 0.1, tol=0.0)
    with pytest.raises(ValueError, match="N >= 3"):
        lp.systems.GeneralizedRigidBody((1.0, 2.0))
    with pytest.raises(ValueError, match="J"):
        lp.systems.GeneralizedRigidBody((1.0, -2.0, 3.0))
    # a step too large for the fixed-point iteration: NaN, which a rollout reports
    with pytest.raises(it.RolloutDivergedError):
        it.IsospectralMidpoint(body, 50.0, max_iter=5).rollout(10 * np.ones(body.dim), 3)


def test_generalized_rigid_body_round_trips_through_its_name():
    body = lp.systems.GeneralizedRigidBody(J4)
    back = lp.systems.from_name(body.name, body.params)
    assert back == body and back.dim == 6


@pytest.mark.slow  # ~3.5 s; the methods' orders and long runs by default above
def test_a_rollout_with_a_fixed_iteration_count_is_reverse_differentiable():
    import jax

    body = lp.systems.GeneralizedRigidBody(J4)
    method = it.IsospectralMidpoint(body, 0.05, tol=1e-8, iterations=6)
    y0 = np.random.default_rng(6).normal(size=body.dim)

    def final_energy(y):
        c = method.carry(y)
        for _ in range(3):
            c = method.step_carry(c)
        return body.hamiltonian(method.uncarry(c))

    g = np.asarray(jax.grad(final_energy)(y0))
    e = np.eye(body.dim)[0] * 1e-6
    fd = (float(final_energy(y0 + e)) - float(final_energy(y0 - e))) / 2e-6
    assert np.all(np.isfinite(g)) and abs(g[0] - fd) < 1e-6 * max(1.0, abs(fd))


def test_predictor_extrapolates_polynomials_exactly_through_the_ring():
    import jax.numpy as jnp

    from integrators._isospectral import (
        PREDICTOR_DEGREE,
        PREDICTOR_POINTS,
        _counted,
        _predict,
        _push,
    )

    M = PREDICTOR_POINTS
    # increments D_n = p(n) 1 for a polynomial p of degree PREDICTOR_DEGREE: once k points are
    # in the ring, the prediction of D_k is exact for degree min(k - 1, PREDICTOR_DEGREE); the
    # ring wraps around (3 M pushes) and the count stays bounded
    coefficients = np.random.default_rng(7).normal(size=PREDICTOR_DEGREE + 1)
    history, count = jnp.zeros((M, 2, 2)), jnp.asarray(0)
    for n in range(3 * M):
        exact = np.polyval(coefficients, n)
        predicted = float(_predict(history, count)[0, 0])
        if n > PREDICTOR_DEGREE:
            # round-off of a least-squares fit through values up to ~|p(3M)|
            assert abs(predicted - exact) < 1e3 * EPS * abs(np.polyval(np.abs(coefficients), 3 * M))
        history, count = _push(history, exact * jnp.eye(2), count), _counted(count)
        assert int(count) < 2 * M


def test_iteration_forms_the_cayley_conjugation_and_the_frozen_stage():
    import jax.numpy as jnp

    body = lp.systems.GeneralizedRigidBody(J4)
    method = it.IsospectralMidpoint(body, 0.1)
    rng = np.random.default_rng(8)
    W = np.asarray(body.algebra.matrix(rng.normal(size=body.dim)))
    Wt = W + 0.05 * np.asarray(body.algebra.matrix(rng.normal(size=body.dim)))
    dW, G, moved = method._iterate(jnp.asarray(W), 0.1, jnp.asarray(Wt))
    B = 0.05 * np.asarray(body.velocity_matrix(Wt))
    X = np.linalg.inv(np.eye(4) - B)
    Q = X @ (np.eye(4) + B)
    scale = np.abs(W).max()
    # against the definitions, by numpy's own solve: a few eps of |W| (Q, X well conditioned)
    np.testing.assert_allclose(W + np.asarray(dW), Q @ W @ Q.T, atol=32 * EPS * scale)
    np.testing.assert_allclose(np.asarray(G), X @ W @ X.T, atol=32 * EPS * scale)
    assert float(moved) == np.abs(np.asarray(G) - Wt).sum(axis=1).max()
