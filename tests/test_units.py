"""Units: a fit to observations learns the same motion whatever the units of time and state
(docs/conventions.md, "Units")."""

import numpy as np
import pytest

import integrators as it
import learn
from liepoisson.systems import ExtendedPendulum, RigidBody

BODY = RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0))


@pytest.mark.parametrize("time, size", [(1e-3, 1.0), (3600.0, 1.0), (1.0, 1e3), (0.25, 7.0)])
def test_terms_in_units_move_scaled_states_as_the_originals_move_unit_states(time, size):
    # The G-LPNet of terms.in_units(T, Y) maps Y z over T tau to Y times the original's image of
    # z over tau: the bracket is linear, the inputs <alpha_s, y> unchanged, the rates / T.
    terms = learn.RidgeTerms(3, 3, key=4, linear_term=True)
    net = learn.GLPNet(BODY, terms=terms, method=it.splitting.TripleJump())
    scaled = learn.GLPNet(BODY, terms=terms.in_units(time, size), method=it.splitting.TripleJump())
    z = np.array([[0.6, -0.3, 0.74], [-0.2, 0.9, 0.1]])
    unit = np.asarray(net.with_h(0.13).rollout(z, 5))
    moved = np.asarray(scaled.with_h(0.13 * time).rollout(size * z, 5)) / size
    # 5 steps of about 30 flops each per component, O(1) values: a few hundred ulps
    np.testing.assert_allclose(moved, unit, rtol=0, atol=500 * np.finfo(float).eps)


def test_terms_in_time_units_on_a_poisson_system_that_is_not_lie_poisson():
    # With size 1 the change of units is the change of the unit of time, on any Poisson system.
    system = ExtendedPendulum()
    terms = learn.RidgeTerms(system.dim, system.dim, key=1, linear_term=True)
    net = learn.GLPNet(system, terms=terms, method=it.splitting.Strang())
    scaled = learn.GLPNet(system, terms=terms.in_units(1e-3, 1.0), method=it.splitting.Strang())
    y = np.array([[0.3, -0.2, 0.1, 0.05]])[:, : system.dim]
    np.testing.assert_allclose(np.asarray(scaled.with_h(0.1e-3).rollout(y, 4)),
                               np.asarray(net.with_h(0.1).rollout(y, 4)), rtol=0, atol=500 * np.finfo(float).eps)


def test_in_units_refuses_a_scale_that_is_not_positive():
    terms = learn.RidgeTerms(3, 3)
    with pytest.raises(ValueError, match="time"):
        terms.in_units(0.0, 1.0)
    with pytest.raises(TypeError, match="size"):
        terms.in_units(1.0, "1")


@pytest.mark.slow
def test_one_data_set_in_seconds_milliseconds_hours_and_scaled_states_gives_one_motion():
    rng = np.random.default_rng(3)
    y0 = rng.normal(size=(3, 3))
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    data = it.observe(BODY, y0, it.uneven_times(3, 6, steps=(0.05, 0.3), seed=3), noise=1e-3, seed=3)
    test = np.array([[0.48, 0.6, -0.64]])
    reference = it.ground_truth(BODY, test, 0.05, 40).states[:, -1]  # t = 2 s
    errors = {}
    for name, per_second, size in (("s", 1.0, 1.0), ("ms", 1e3, 1.0), ("h", 1 / 3600, 1.0), ("x1e3", 1.0, 1e3)):
        scaled = it.Observations(BODY, [t * per_second for t in data.times], [y * size for y in data.states])
        net, _ = learn.fit_splitting(BODY, scaled, activation="identity", iterations=20, validation_fraction=0.0,
                                     progress=False)
        final = np.asarray(net.with_h(0.05 * per_second).rollout(size * test, 40))[:, -1] / size
        errors[name] = float(np.linalg.norm(final - reference))
    # the fit in seconds learns the motion (noise 1e-3 over 2 s), and the others the same
    assert errors["s"] < 2e-2, errors
    for name, error in errors.items():
        assert abs(error - errors["s"]) <= 0.1 * errors["s"], errors
