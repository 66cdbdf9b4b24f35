"""An LPNet's lifted step: the configuration's motion along the Casimir gradients, which
momenta cannot fix, from a phase network fitted to configurations (`learn.fit_phase`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import integrators as it
import learn
import liepoisson as lp
from learn._training._phase import _turns, phase_rates

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody((2.0, 1.0, 2.0 / 3.0))


def _truth(system, n, steps, seed, h=0.1):
    rng = np.random.default_rng(seed)
    y0 = rng.normal(size=(n, system.dim))
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    g0 = Rotation.random(n, random_state=seed + 1).as_quat()
    if system.dim == 6:
        g0 = np.concatenate([g0, rng.normal(size=(n, 3))], axis=1)
    return it.ground_truth(system, y0, h, steps, g0=g0)


# Kirchhoff's poses with -m slow
@pytest.mark.parametrize("system", [BODY, pytest.param(lp.systems.Kirchhoff(), marks=pytest.mark.slow)],
                         ids=["rigid body", "Kirchhoff"])
def test_the_phase_rates_of_heyokas_pairs_rebuild_its_configurations(system):
    # g1 = g0 exp(h beta . grad C(mu0)) exp(h alpha) with alpha the pair's Casimir-projected
    # parameters and beta from their turn (`_turns`): heyoka's next configuration to 1e-11 (its own
    # tolerance, the parameters' Gauss-Newton and the group's log: ~1e3 roundings of a step)
    data = _truth(system, 3, 6, seed=0)
    net = learn.LPNet(system, hidden=(4,), key=0, h=0.1)
    group = system.group
    y0, y1 = data.states[:, :-1].reshape(-1, system.dim), data.states[:, 1:].reshape(-1, system.dim)
    g0 = data.configurations[:, :-1].reshape(-1, group.size)
    g1 = data.configurations[:, 1:].reshape(-1, group.size)
    alpha = np.asarray(net.params_from_pair(y0, y1, 0.1))
    grads = np.asarray(system.casimir_gradients(y0))
    rates, _, _ = _turns(group, g0, g1, alpha, 0.1, grads)
    phase = np.einsum("nk,nkd->nd", rates, grads)
    rebuilt = group.right_exp(group.right_exp(g0, 0.1 * phase), 0.1 * alpha)
    assert np.abs(np.asarray(group.difference(rebuilt, g1))).max() < 1e-11
    # ... and without the phase they are off by the rotation about the momentum: far more
    assert np.abs(np.asarray(group.difference(group.right_exp(g0, 0.1 * alpha), g1))).max() > 1e-3
    # phase_rates takes the turn against the net's own alpha (what its lifted step applies)
    states, own = phase_rates(net, data)
    np.testing.assert_array_equal(states, y0)
    alpha_net = np.asarray(jax.vmap(net.alpha)(jnp.asarray(y0)))
    np.testing.assert_allclose(own, _turns(group, g0, g1, alpha_net, 0.1, grads)[0], rtol=1e-12, atol=1e-14)


def test_a_lifted_lpnet_step_keeps_the_spatial_momentum_and_the_unit_quaternion_for_any_weights():
    for key in range(3):
        net = learn.LPNet(BODY, hidden=(8,), key=key, h=0.2,
                          phase=learn.AffineMLP(3, 1, (8,), key=key + 10, output_scaling=((0.5,), (2.0,))))
        g0 = Rotation.random(4, random_state=key).as_quat()
        y0 = np.random.default_rng(key).normal(size=(4, 3))
        g, y = net.lifted_rollout(g0, y0, 500)
        np.testing.assert_array_equal(y, net.rollout(y0, 500))  # the momentum part is the step
        J = np.asarray(BODY.spatial_momentum(g, y))
        # ~10 roundings a step at most, over 500 steps
        assert np.abs(J - J[:, :1]).max() <= 500 * 10 * EPS * np.abs(J).max()
        assert np.abs(np.linalg.norm(np.asarray(g), axis=-1) - 1.0).max() <= 500 * 4 * EPS


def test_without_a_phase_network_the_lifted_step_is_refused_and_says_how_to_fit_one():
    net = learn.LPNet(BODY, hidden=(4,), key=0, h=0.1)
    with pytest.raises(ValueError, match=r"no phase network.*learn.fit_phase"):
        net.lifted_step(np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.3, 0.4, 0.5]))


@pytest.mark.slow  # three fits: 10 s
@pytest.mark.parametrize("loss", ["alpha", "state"])
def test_the_fitted_phase_turns_the_attitude_as_heyoka_does_and_is_saved(tmp_path, loss):
    # the LPNet's alpha fitted to heyoka's momenta, then its phase to the configurations: the
    # attitude of held-out starts at t = 1 within what the momentum's own error allows, where
    # the phase at zero is 1.1 rad off (the rotation about the angular momentum at about
    # 2H/|Pi|^2 rad/s). On the state loss alpha has a component along the Casimir gradient
    # (nothing in the loss fixes it): the rates are taken against the net's own alpha
    data = _truth(BODY, 10, 30, seed=3)
    net, _ = learn.fit(learn.LPNet(BODY, hidden=(16,), key=0), data, loss=loss,
                       optimiser=learn.LevenbergMarquardt(300), progress=False)
    phased, record = learn.fit_phase(net, data, hidden=(8,), iterations=60)
    assert record.model == "LPNet phase" and record.train_loss < 1e-3  # in units of the rates' spread
    test = _truth(BODY, 4, 10, seed=7)
    g0, y0 = test.configurations[:, 0], test.states[:, 0]
    angle = lambda gs: np.asarray(lp.rotation_angle(np.asarray(gs)[:, -1], test.configurations[:, -1])).mean()
    with_phase = angle(phased.lifted_rollout(g0, y0, 10)[0])
    flat = learn.AffineMLP(3, 1, (8,), key=0, output_scaling=((0.0,), (1e-300,)))  # rates ~ 0
    without = angle(eqx.tree_at(lambda m: m.phase, phased, flat).lifted_rollout(g0, y0, 10)[0])
    momentum = np.abs(np.asarray(phased.rollout(y0, 10))[:, -1] - test.states[:, -1]).max()
    assert with_phase < 0.25 * without and with_phase < 2 * momentum + 0.02, (with_phase, without, momentum)
    phased.save(tmp_path / "net.h5")
    back = learn.load(tmp_path / "net.h5", system=BODY)
    g, y = back.lifted_step(jnp.asarray(g0[0]), jnp.asarray(y0[0]))
    g_, y_ = phased.lifted_step(jnp.asarray(g0[0]), jnp.asarray(y0[0]))
    np.testing.assert_array_equal(g, g_)
    np.testing.assert_array_equal(y, y_)


def test_a_phase_needs_a_parametrisation_that_carries_the_configuration():
    vehicle = lp.systems.Kirchhoff()
    with pytest.raises(ValueError, match="SE3RotationShear.*TestFlowParametrisation"):
        learn.LPNet(vehicle, hidden=(4,), parametrisation="SE3RotationShear", phase=learn.AffineMLP(6, 2, (4,)))
    with pytest.raises(ValueError, match=r"phase rate per Casimir \(phase=\)"):
        learn.LPNet(BODY, hidden=(4,), phase=learn.AffineMLP(3, 2, (4,)))
    data = _truth(vehicle, 2, 3, seed=0)
    with pytest.raises(ValueError, match="SE3RotationShear does not carry a configuration"):
        learn.fit_phase(learn.LPNet(vehicle, hidden=(4,), parametrisation="SE3RotationShear"), data)


def test_fit_phase_refuses_what_it_cannot_use():
    net = learn.LPNet(BODY, hidden=(4,), key=0)
    momenta = it.ground_truth(BODY, np.array([[0.3, 0.4, 0.5]]), 0.1, 3)
    with pytest.raises(ValueError, match="no configurations"):
        learn.fit_phase(net, momenta)
    one_time = it.Trajectories(np.zeros((1, 1, 3)) + 0.5, 0.1, BODY, configurations=np.array([[[0.0, 0, 0, 1]]]))
    with pytest.raises(ValueError, match="one time per trajectory"):
        learn.fit_phase(net, one_time)
    with pytest.raises(TypeError, match="net must be a learn.LPNet"):
        learn.fit_phase(learn.GLPNet(BODY, key=0), momenta)
    data = _truth(BODY, 2, 3, seed=0)
    with pytest.raises(ValueError, match=r"step h=0.2 differs from the data's h=0.1"):
        learn.fit_phase(eqx.tree_at(lambda m: m.h, net, 0.2, is_leaf=lambda v: v is None), data)
    # the configurations of another body with these momenta: no motion of this one
    other = it.ground_truth(lp.systems.RigidBody((1.0, 1.5, 3.0)), data.states[:, 0], 0.1, 3,
                            g0=data.configurations[:, 0])
    shuffled = it.Trajectories(data.states, 0.1, BODY, configurations=other.configurations)
    with pytest.raises(ValueError, match="moves off the directions its momenta allow"):
        learn.fit_phase(net, shuffled)


def test_noisy_pairs_are_not_refused_and_their_rates_are_the_least_squares_ones():
    # noisy configurations leave the Casimir directions by their noise: refused as a motion of
    # these momenta, taken with noisy=True, their rates the same least squares on the turns
    data = _truth(BODY, 2, 4, seed=0)
    rng = np.random.default_rng(5)
    noise = Rotation.from_rotvec(1e-3 * rng.normal(size=(data.configurations[..., 0].size, 3)))
    g = (Rotation.from_quat(data.configurations.reshape(-1, 4)) * noise).as_quat().reshape(
        data.configurations.shape)
    noisy = it.Trajectories(data.states, 0.1, BODY, configurations=g)
    net = learn.LPNet(BODY, hidden=(4,), key=0, h=0.1)
    with pytest.raises(ValueError, match="noisy=True"):
        phase_rates(net, noisy)
    _, rates = phase_rates(net, noisy, noisy=True)
    y0 = data.states[:, :-1].reshape(-1, 3)
    alpha = np.asarray(jax.vmap(net.alpha)(jnp.asarray(y0)))
    expected = _turns(BODY.group, g[:, :-1].reshape(-1, 4), g[:, 1:].reshape(-1, 4), alpha, 0.1,
                      np.asarray(BODY.casimir_gradients(y0)))[0]
    np.testing.assert_array_equal(rates, expected)
    # the noise moves the rates by about its size over the step (1e-3 rad / 0.1), not more
    assert 1e-4 < np.max(np.abs(rates - phase_rates(net, data)[1])) < 0.1
    # on exact pairs, noisy=True only skips the check: the same rates
    np.testing.assert_array_equal(phase_rates(net, data, noisy=True)[1], phase_rates(net, data)[1])
    fitted, _ = learn.fit_phase(net, noisy, noisy=True, iterations=2, progress=False)
    assert fitted.phase is not None
    with pytest.raises(TypeError, match="noisy must be True or False"):
        learn.fit_phase(net, noisy, noisy="yes")
