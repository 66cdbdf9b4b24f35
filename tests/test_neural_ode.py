"""learn.NeuralODE: the unstructured baseline that takes the step as an input."""

import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0))


def test_a_step_is_classical_runge_kutta_on_its_field():
    net = learn.NeuralODE(BODY, hidden=(8,), key=1, h=0.3, substeps=3)
    y = np.array([0.3, -0.5, 0.8])
    f = lambda z: np.asarray(net.vector_field(z))
    dt, z = 0.1, y.copy()
    for _ in range(3):
        k1 = f(z)
        k2 = f(z + 0.5 * dt * k1)
        k3 = f(z + 0.5 * dt * k2)
        k4 = f(z + dt * k3)
        z = z + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    # the same arithmetic in another order: a few roundings of the state's size
    np.testing.assert_allclose(np.asarray(net.step(y)), z, rtol=0, atol=16 * EPS)
    assert np.abs(z - y).max() > 1e-3  # a real step


@pytest.mark.slow  # a fit (~4 s); the step's Runge-Kutta property runs by default, and W2, W4 and W6 fit it (-m slow)
def test_it_learns_uneven_observations_and_conserves_no_casimir(tmp_path):
    y0 = np.random.default_rng(0).normal(size=(4, 3))
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    obs = it.observe(BODY, y0, it.uneven_times(4, 11, (0.05, 0.3), seed=1))
    net = learn.NeuralODE(BODY, hidden=(8, 8), activation="tanh", key=0)
    fitted, record = learn.fit(net, obs, optimiser=learn.LevenbergMarquardt(40), validation_fraction=0.0,
                               progress=False)
    assert record.train_loss < 1e-6  # measured 6.6e-9 (exact data)
    y = np.asarray(fitted.with_h(0.1).rollout(y0[0], 2000))
    drift = np.abs(np.sum(y**2, axis=-1) - 1.0).max()
    # |Pi|^2 is the rigid body's Casimir: no structure keeps it (measured 0.45 at t = 200)
    assert drift > 1e-3
    fitted.save(tmp_path / "node.h5")
    back = learn.load(tmp_path / "node.h5", BODY)
    assert type(back) is learn.NeuralODE and back.substeps == fitted.substeps
    np.testing.assert_array_equal(np.asarray(back.with_h(0.1).step(y0[0])), np.asarray(fitted.with_h(0.1).step(y0[0])))


def test_bad_neural_ode_arguments_are_refused():
    with pytest.raises(ValueError, match="substeps"):
        learn.NeuralODE(BODY, hidden=(4,), substeps=0)
    with pytest.raises(ValueError, match="h must be"):
        learn.NeuralODE(BODY, hidden=(4,), h=-0.1)
