"""Weak SINDy (`paper._sindy.WeakSINDyModel`, pysindy's weak-form library) on exact
observations of the rigid body: it recovers Euler's equations and its simulation follows heyoka.
Skipped without pysindy (extra `peers`)."""

import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from paper._sindy import PolynomialField, WeakSINDyModel  # imports pysindy only when fitting

pytest.importorskip("pysindy")

INERTIA = (2.0, 1.0, 2.0 / 3.0)


def _sphere(n: int, seed: int) -> np.ndarray:
    y = np.random.default_rng(seed).normal(size=(n, 3))
    return y / np.linalg.norm(y, axis=1, keepdims=True)


def _euler_coefficients() -> np.ndarray:
    """Euler's equations in pysindy's degree-2 monomials: Pi1' = (1/I3 - 1/I2) Pi2 Pi3 and cyclic."""
    i1, i2, i3 = INERTIA
    xi = np.zeros((3, 10))  # monomials 1, x0, x1, x2, x0^2, x0 x1, x0 x2, x1^2, x1 x2, x2^2
    xi[0, 8], xi[1, 6], xi[2, 5] = 1 / i3 - 1 / i2, 1 / i1 - 1 / i3, 1 / i2 - 1 / i1
    return xi


def test_weak_sindy_recovers_euler_equations_and_follows_heyoka():
    body = lp.systems.RigidBody(inertia=INERTIA)
    model = WeakSINDyModel()
    # regular: 6 trajectories x 41 exact observations at h = 0.05 (t in [0, 2])
    data = it.observe(body, _sphere(6, 0), 0.05 * np.arange(41))
    fitted = model.fit(body, data)
    field = fitted.step_map.model
    assert isinstance(field, PolynomialField)
    assert field.names == ("1", "x0", "x1", "x2", "x0^2", "x0 x1", "x0 x2", "x1^2", "x1 x2", "x2^2")
    assert field.coefficient(0, (0, 1, 1)) == pytest.approx(0.5, abs=1e-6)
    # every other term is thresholded to exactly zero; the three products to ~5e-8
    assert np.max(np.abs(field.coefficients - _euler_coefficients())) < 1e-6
    # simulated (LSODA) from held-out states over t = 2 against heyoka: the coefficients' error
    y0 = _sphere(3, 1)
    reference = it.ground_truth(body, y0, 0.1, 20).states
    states = model.simulate(fitted, y0, 20, 0.1)
    assert states.shape == reference.shape
    assert np.max(np.abs(states - reference)) < 1e-6

    # uneven (steps from [0.05, 0.3]), each trajectory on its own grid: the same terms, the
    # piecewise-linear quadrature's error on the coarser steps
    uneven = it.observe(body, _sphere(6, 0), it.uneven_times(6, 21, (0.05, 0.3), seed=0))
    assert not uneven.is_regular() and model.accepts(uneven)
    field = model.fit(body, uneven).step_map.model
    assert np.array_equal(field.coefficients != 0, _euler_coefficients() != 0)
    assert np.max(np.abs(field.coefficients - _euler_coefficients())) < 1e-3


def test_weak_sindy_refuses_trajectories_too_short_for_a_test_function():
    body = lp.systems.RigidBody(inertia=INERTIA)
    short = it.Observations(body, [np.array([0.0, 0.1, 0.2])], [np.tile([0.6, 0.0, 0.8], (3, 1))])
    model = WeakSINDyModel()
    assert not model.accepts(short)
    with pytest.raises(ValueError, match="at least 4 observations"):
        model.fit(body, short)
    with pytest.raises(ValueError, match="window"):
        WeakSINDyModel(window=1)
