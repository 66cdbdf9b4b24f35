"""The neural ODE peer (`paper._neural_ode.fit_neural_ode`): it fits exact rigid-body
trajectories to 1e-4 (relative RMS of its rollouts), and its rule keeps the hidden-layer shape
of the lowest held-out rollout error. No pysindy needed."""

import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from paper._neural_ode import NeuralODEChoice, fit_neural_ode, rk4_flow
from paper._sindy import rollout_error

BODY = lp.systems.RigidBody(inertia=(1.0, 1.7, 2.6))


def _data(n: int, seed: int) -> it.Observations:
    """`n` exact trajectories of 9 observations at h = 0.1 from unit momenta."""
    y0 = np.random.default_rng(seed).normal(size=(n, 3))
    return it.observe(BODY, y0 / np.linalg.norm(y0, axis=1, keepdims=True), 0.1 * np.arange(9))


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_neural_ode_fits_exact_rigid_body_trajectories_to_1e_4():
    data = _data(2, 0)
    choice = fit_neural_ode(data, 1500, hidden=((8, 8),))
    assert isinstance(choice, NeuralODEChoice) and choice.hidden == (8, 8)
    # its rollouts (LSODA of the learned field) from each trajectory's first observation follow
    # the observations to 1e-4 relative RMS (L-BFGS-B, at most 1500 iterations)
    assert rollout_error(choice.field, list(data.times), list(data.states)) < 1e-4
    # and by its own step (RK4, 4 sub-steps of 0.025: their error is far below)
    assert rollout_error(choice.field, list(data.times), list(data.states), flow=rk4_flow) < 1e-4


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_the_rule_keeps_the_shape_of_the_lowest_held_out_error():
    choice = fit_neural_ode(_data(5, 1), 30, hidden=((2,), (8, 8)))
    assert set(choice.scores) == {(2,), (8, 8)} and all(np.isfinite(e) for e in choice.scores.values())
    assert choice.hidden == min(choice.scores, key=choice.scores.get)
    assert 1 <= choice.iterations <= 30 and "held-out errors" in choice.describe()


def test_bad_settings_are_refused():
    data = _data(2, 0)
    with pytest.raises(ValueError, match="hidden"):
        fit_neural_ode(data, 10, hidden=())
    with pytest.raises(ValueError, match="hidden"):
        fit_neural_ode(data, 10, hidden=((0,),))
    with pytest.raises(ValueError, match="iterations"):
        fit_neural_ode(data, 0)
