"""learn.IsospectralPolynomial: the isospectral midpoint of a learned polynomial of the
system's velocity operator (Zeitlin's model, the generalized rigid body)."""

import jax.numpy as jnp
import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps


def _spectrum(system, ys):
    W = np.asarray(system.algebra.matrix(jnp.asarray(ys)))
    return np.linalg.eigvalsh(1j * W)


@pytest.mark.slow
def test_theta_one_zero_is_the_classical_midpoint():
    z = lp.systems.Zeitlin(6)
    y = z.random_state(1)
    model = learn.IsospectralPolynomial(z, degree=3, h=0.05)
    classical = it.IsospectralMidpoint(z, 0.05)
    a, b = np.asarray(model.rollout(y, 5)), np.asarray(classical.rollout(y, 5))
    # theta = (1, 0, 0) adds exact zeros to S(W): the same floating-point operations
    assert np.max(np.abs(a - b)) <= 4 * EPS * np.max(np.abs(b))


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_any_theta_keeps_the_spectrum_to_round_off():
    z = lp.systems.Zeitlin(5)
    y = z.random_state(2)
    model = learn.IsospectralPolynomial(z, degree=3, theta=[0.8, -0.3, 0.2], h=0.1)
    ys = np.asarray(model.rollout(y, 300))
    spectrum = _spectrum(z, ys)
    drift = np.max(np.abs(spectrum - spectrum[0])) / np.max(np.abs(spectrum[0]))
    # a unitary conjugation a step: round-off random walk over 300 steps, ~ sqrt(300) * a few eps
    assert drift <= 200 * EPS
    # and the flow is not the classical one: theta changes the motion
    classical = np.asarray(it.IsospectralMidpoint(z, 0.1).rollout(y, 300))
    assert np.max(np.abs(ys - classical)) > 1e-3


@pytest.mark.slow  # a fit (~4 s); the step's oracles (theta = (c), the explicit polynomial) run by default
def test_fit_recovers_the_coefficients_that_made_the_data():
    z = lp.systems.Zeitlin(4)
    true = learn.IsospectralPolynomial(z, degree=2, theta=[1.3, 0.4], h=0.1, tol=1e-14)
    starts = np.stack([z.random_state(seed) for seed in range(6)])
    trajs = np.stack([np.asarray(true.rollout(y, 10)) for y in starts])
    y0, y1 = trajs[:, :-1].reshape(-1, z.dim), trajs[:, 1:].reshape(-1, z.dim)
    model = learn.IsospectralPolynomial(z, degree=2, h=0.1, tol=1e-14)
    fitted, _ = learn.fit(model, (y0, y1), h=0.1, progress=False)
    # noise-free data of the same family: the minimum is theta* itself, up to the stage
    # iteration's tolerance (1e-14) propagated through a well-conditioned least squares
    np.testing.assert_allclose(np.asarray(fitted.theta), [1.3, 0.4], rtol=1e-7)


def test_generalized_rigid_body_is_accepted_and_saved(tmp_path):
    body = lp.systems.GeneralizedRigidBody([1.0, 1.5, 2.0, 3.0])
    model = learn.IsospectralPolynomial(body, degree=2, theta=[1.1, 0.05], h=0.05)
    path = tmp_path / "iso.h5"
    model.save(path)
    loaded = learn.load(path)
    assert isinstance(loaded, learn.IsospectralPolynomial)
    np.testing.assert_array_equal(np.asarray(loaded.theta), [1.1, 0.05])
    y = np.random.default_rng(0).normal(size=body.dim)
    np.testing.assert_array_equal(np.asarray(loaded.step(y)), np.asarray(model.step(y)))


def test_bad_input():
    z = lp.systems.Zeitlin(4)
    with pytest.raises(TypeError, match="compact matrix algebra"):
        learn.IsospectralPolynomial(lp.systems.RigidBody(), degree=2)
    with pytest.raises(ValueError, match="theta has 1 coefficients but degree=2"):
        learn.IsospectralPolynomial(z, degree=2, theta=[1.0])
    with pytest.raises(ValueError, match="theta must be a non-empty finite 1-D array"):
        learn.IsospectralPolynomial(z, theta=[1.0, np.nan])
    with pytest.raises(ValueError, match="theta must be a non-empty finite 1-D array"):
        learn.IsospectralPolynomial(z, theta=[])
    with pytest.raises(ValueError, match="degree must be an integer >= 1; got 0"):
        learn.IsospectralPolynomial(z, degree=0)
    with pytest.raises(ValueError, match="h must be finite and > 0; got -0.1"):
        learn.IsospectralPolynomial(z, h=-0.1)
    with pytest.raises(ValueError, match="has no step size h yet"):
        learn.IsospectralPolynomial(z).step(z.random_state(0))


def test_the_degree_is_the_length_of_theta():
    z = lp.systems.Zeitlin(4)
    assert learn.IsospectralPolynomial(z, theta=[1.0, 0.2]).degree == 2
    assert learn.IsospectralPolynomial(z).degree == 3  # the default: (1, 0, 0)


def test_velocity_is_the_polynomial_of_the_systems_operator():
    z = lp.systems.Zeitlin(5)
    W = z.algebra.matrix(jnp.asarray(z.random_state(3)))
    theta = [0.9, -0.4, 0.25]
    model = learn.IsospectralPolynomial(z, theta=theta, h=0.1)
    S = z.velocity_matrix
    explicit = theta[0] * S(W) + theta[1] * S(S(W)) + theta[2] * S(S(S(W)))
    # the same linear operations in another order (Horner): agreement to round-off of S's scale
    np.testing.assert_allclose(np.asarray(model.velocity_matrix(W)), np.asarray(explicit),
                               atol=64 * EPS * float(jnp.max(jnp.abs(S(W)))))


def test_degree_one_is_the_classical_method_at_a_rescaled_step():
    # an independent oracle: theta = (c) at step h solves dW/dt = [c S(W), W], which is the
    # classical midpoint at step c h (same stage equation, the same Cayley transform)
    z = lp.systems.Zeitlin(6)
    y = z.random_state(4)
    a = np.asarray(learn.IsospectralPolynomial(z, theta=[1.3], h=0.05, tol=1e-14).rollout(y, 8))
    b = np.asarray(it.IsospectralMidpoint(z, 1.3 * 0.05, tol=1e-14).rollout(y, 8))
    # products rounded in another order (c S(W) h vs S(W) (c h)) over 8 steps
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))


def test_a_system_whose_velocity_is_not_linear_is_refused():
    # the polynomial of S is a Hamiltonian only when S is the linear gradient of a quadratic H
    quadratic = lp.systems.LiePoissonSystem(lp.so(3), lambda y, xp: 0.5 * (y[0] ** 2 + 0.5 * y[1] ** 2 + 0.3 * y[2] ** 2))
    learn.IsospectralPolynomial(quadratic, degree=2, h=0.1)  # accepted
    quartic = lp.systems.LiePoissonSystem(lp.so(3), lambda y, xp: 0.25 * (y[0] ** 4 + 2 * y[1] ** 4 + 3 * y[2] ** 4))
    with pytest.raises(ValueError, match="quadratic Hamiltonian"):
        learn.IsospectralPolynomial(quartic, degree=2, h=0.1)
