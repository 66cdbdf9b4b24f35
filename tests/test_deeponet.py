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
    continuous_quaternions,
    operator_data,
    relative_states,
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
def test_relative_configurations_are_left_invariant_and_compose_back(system):
    # the same momenta from two first configurations: the motions differ by a left translation,
    # so their configurations relative to the first are one (to heyoka's tolerance, ~1e-13)
    group, rng = system.group, np.random.default_rng(1)
    mu0 = rng.uniform(-1.0, 1.0, size=(1, system.dim))
    q = Rotation.random(2, random_state=4).as_quat()
    g0 = q if group.size == 4 else np.concatenate([q, rng.normal(size=(2, 3))], axis=1)
    a, b = (it.ground_truth(system, mu0, 0.1, 20, g0=g0[k]) for k in range(2))
    xi = np.asarray(system.body_velocity(a.states[0]))
    ra, rb = relative_states(group, a.configurations[0], xi), relative_states(group, b.configurations[0], xi)
    np.testing.assert_allclose(ra[0, : group.size], group.identity(), atol=4 * EPS)
    np.testing.assert_allclose(ra, rb, atol=1e-11)
    assert np.abs(a.configurations[0] - b.configurations[0]).max() > 0.1  # not the same motion
    # g0 (g0^-1 g) = g: the same attitude (+-q, rounding of two quaternion products) and position
    back = np.asarray(group.compose(jnp.asarray(a.configurations[0, :1]), jnp.asarray(ra[:, : group.size])))
    g = a.configurations[0]
    np.testing.assert_allclose(np.abs(np.sum(back[:, :4] * g[:, :4], axis=1)), 1.0, atol=8 * EPS)
    np.testing.assert_allclose(back[:, 4:], g[:, 4:], atol=16 * EPS * max(1.0, np.abs(g[:, 4:]).max(initial=0.0)))


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_the_losss_shared_trunk_is_the_network_on_each_trajectory_padding_counted_out():
    obs = body_observations()
    short = it.BodyObservations(BODY, [obs.times[0][:3], *obs.times[1:]],
                                [obs.configurations[0][:3], *obs.configurations[1:]],
                                [obs.velocities[0][:3], *obs.velocities[1:]])
    args = operator_data(short)
    n = int(args.u.shape[-1])
    present = np.asarray(args.mask) > 0
    net = learn.DeepONet(3, n, width=8, hidden=(16,), key=3).rescaled(
        args.u0, np.asarray(args.times)[np.asarray(args.index)[present]], np.asarray(args.u)[present])
    assert net.output_scale != (1.0,) * n
    residuals = np.asarray(OperatorLoss().residuals(OperatorFit(net, 0.1), args))
    times = np.asarray(args.times)[np.asarray(args.index)]
    one_by_one = np.asarray(jax.vmap(net)(args.u0, jnp.asarray(times)))
    expected = (one_by_one - np.asarray(args.u)) / np.asarray(net.output_scale) * np.asarray(args.mask)[..., None]
    # the same products summed in another order (einsum over the width): a few roundings
    np.testing.assert_allclose(residuals, expected, rtol=0, atol=64 * EPS)
    assert np.all(residuals[0, 3:] == 0.0)  # the short trajectory's padding
    assert OperatorLoss().count(OperatorFit(net, 0.1), args) == (3 + 7 * 21) * n  # present observations

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
    with pytest.raises(ValueError, match="at least two trajectories"):
        learn.fit_deeponet(body_observations(n=1))
    with pytest.raises(ValueError, match="epochs"):
        learn.fit_deeponet(body_observations(), epochs=0)
    with pytest.raises(TypeError, match="key must be an int"):
        learn.fit_deeponet(body_observations(), key=jax.random.PRNGKey(0))


def test_a_body_deeponet_refuses_a_network_of_other_sizes_and_inputs_that_are_not_one_state():
    with pytest.raises(ValueError, match="4 configuration components and 3 velocities"):
        learn.BodyDeepONet(learn.DeepONet(3, 5, width=4, hidden=(8,)), BODY)
    with pytest.raises(TypeError, match="learn.DeepONet"):
        learn.BodyDeepONet(object(), BODY)
    model = learn.BodyDeepONet(learn.DeepONet(3, 7, width=4, hidden=(8,)), BODY)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="xi0"):
        model.predict(q, np.ones(4), np.arange(3.0))
    with pytest.raises(ValueError, match="xi0"):
        model.predict(q, np.array([1.0, np.nan, 0.0]), np.arange(3.0))
    with pytest.raises(ValueError, match="g0"):
        model.predict(np.array([q] * 2), np.ones(3), np.arange(3.0))
    for t in (1.0, np.ones((2, 3)), [0.0, np.nan]):
        with pytest.raises(ValueError, match="t must be a 1-D array of finite times"):
            model.predict(q, np.ones(3), t)
    with pytest.raises(TypeError, match="t must be real numbers"):
        model.predict(q, np.ones(3), "abc")


def test_a_poses_prediction_is_on_the_group_and_starts_from_its_first_pose():
    # a vehicle's network, any weights: predictions are poses (unit quaternion, position), g0
    # times a relative pose that between() recovers
    model = learn.BodyDeepONet(learn.DeepONet(6, 13, width=4, hidden=(8,), key=1), VEHICLE)
    g0 = np.array([0.0, 0.6, 0.0, 0.8, 1.0, -2.0, 0.5])
    g, xi = model.predict(g0, np.ones(6), np.arange(3.0))
    assert g.shape == (3, 7) and xi.shape == (3, 6)
    np.testing.assert_allclose(np.linalg.norm(g[:, :4], axis=1), 1.0, atol=4 * EPS)
    rel = np.asarray(VEHICLE.group.between(jnp.asarray(g0), jnp.asarray(g)))
    np.testing.assert_allclose(np.asarray(VEHICLE.group.compose(jnp.asarray(g0), jnp.asarray(rel))), g, atol=16 * EPS)
