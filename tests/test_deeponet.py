"""The DeepONet baseline on body observations (`learn.fit_deeponet`): its data layout, its two
evaluation paths, a fit, and bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import integrators as it
import learn
import liepoisson as lp
from learn._training._deeponet import (
    OperatorFit,
    OperatorLoss,
    composed,
    continuous_quaternions,
    operator_data,
    relative,
)

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody((2.0, 1.0, 2.0 / 3.0))
VEHICLE = lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))


def body_observations(system=BODY, n=8, m=21, steps=(0.05, 0.3), measure=("configurations", "velocities")):
    rng = np.random.default_rng(0)
    y0 = rng.uniform(-1.0, 1.0, size=(n, system.dim))
    q = Rotation.random(n, random_state=1).as_quat()
    g0 = q if system.group.size == 4 else np.concatenate([q, rng.normal(size=(n, 3))], axis=1)
    return it.observe_body(system, y0, g0, it.uneven_times(n, m, steps, seed=2), seed=3, measure=measure)


def test_quaternion_signs_are_made_continuous_and_each_is_the_same_attitude():
    q = Rotation.from_rotvec(np.linspace(0.0, 1.0, 40)[:, None] * np.array([3.0, -2.0, 5.0])).as_quat()
    flips = np.where(np.random.default_rng(0).random(40) < 0.5, -1.0, 1.0)
    out = continuous_quaternions(lp.Rotations(), q * flips[:, None])
    assert out[0, 3] >= 0.0
    assert np.all(np.sum(out[1:] * out[:-1], axis=1) > 0.0)
    np.testing.assert_allclose(np.abs(np.sum(out * q, axis=1)), 1.0, rtol=0, atol=8 * EPS)  # +-q each


@pytest.mark.parametrize("system", [BODY, VEHICLE], ids=["rotations", "poses"])
def test_relative_configurations_compose_back_and_start_at_the_identity(system):
    obs = body_observations(system, n=2)
    group, g = system.group, obs.configurations[1]
    rel = relative(group, g[0], g)
    np.testing.assert_allclose(np.abs(rel[0]), group.identity(), atol=4 * EPS)
    back = composed(group, g[0], rel)
    # the same attitude (+-q) and position; rounding of a few products of unit quaternions
    np.testing.assert_allclose(np.abs(np.sum(back[:, :4] * g[:, :4], axis=1)), 1.0, atol=8 * EPS)
    np.testing.assert_allclose(back[:, 4:], g[:, 4:], atol=16 * EPS * np.max(np.abs(g[:, 4:]), initial=1.0))


def test_the_losss_shared_trunk_is_the_network_evaluated_trajectory_by_trajectory():
    args = operator_data(body_observations())
    n = int(args.u.shape[-1])
    net = learn.DeepONet(3, n, width=8, hidden=(16,), key=3)
    residuals = OperatorLoss().residuals(OperatorFit(net, 0.1), args)
    times = np.asarray(args.times)[np.asarray(args.index)]
    one_by_one = jax.vmap(net)(args.u0, jnp.asarray(times))
    np.testing.assert_allclose(residuals, (one_by_one - args.u) * args.mask[..., None], rtol=0, atol=64 * EPS)


@pytest.mark.slow  # a fit, ~7 s (mostly Adam's compilation); its loss and layout run by default above
def test_a_fitted_deeponet_follows_its_training_trajectories_on_the_group():
    obs = body_observations(n=8, m=21)
    model, record = learn.fit_deeponet(obs, width=16, hidden=(32, 32), epochs=1500, progress=False)
    history = np.asarray(record.history["train_loss"])
    assert history[-1] < 1e-2 * history[0]
    g, xi = model.predict(obs.configurations[0][0], obs.velocities[0][0], obs.times[0] - obs.times[0][0])
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=4 * EPS)  # projected onto the group
    angles = np.asarray(lp.rotation_angle(g, obs.configurations[0]))
    spread = np.asarray(lp.rotation_angle(obs.configurations[0], obs.configurations[0][:1]))
    # within its training data: attitude errors a small fraction of how far the body turned
    assert np.mean(angles) < 0.1 * np.mean(spread)
    assert np.sqrt(np.mean((xi - obs.velocities[0]) ** 2)) < 0.1 * np.sqrt(np.mean(obs.velocities[0] ** 2))


def test_fit_deeponet_refuses_what_it_cannot_map():
    with pytest.raises(TypeError, match="BodyObservations"):
        learn.fit_deeponet(it.Observations(BODY, [np.arange(3.0)], [np.ones((3, 3))]))
    with pytest.raises(ValueError, match="configurations and velocities"):
        learn.fit_deeponet(body_observations(measure="velocities"))
    with pytest.raises(ValueError, match="epochs"):
        learn.fit_deeponet(body_observations(), epochs=0)


def test_predict_refuses_shapes_that_are_not_one_state():
    model = learn.BodyDeepONet(learn.DeepONet(3, 7, width=4, hidden=(8,)), BODY)
    with pytest.raises(ValueError, match="xi0"):
        model.predict(np.array([0.0, 0.0, 0.0, 1.0]), np.ones(4), np.arange(3.0))
    with pytest.raises(ValueError, match="xi0"):
        model.predict(np.array([0.0, 0.0, 0.0, 1.0]), np.array([1.0, np.nan, 0.0]), np.arange(3.0))
    with pytest.raises(ValueError, match="g0"):
        model.predict(np.array([[0.0, 0.0, 0.0, 1.0]] * 2), np.ones(3), np.arange(3.0))
