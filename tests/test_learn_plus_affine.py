"""`learn.PlusAffine`: a network plus a fixed affine map, the least-squares fit of the data.
The fit is checked against an exactly affine target (recovered to round-off), the sum against
its definition, the file round trip, the group-averaging order and the bad inputs."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS

import integrators as it
import learn
import liepoisson as lp
from liepoisson.systems import sign_symmetries

RB = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
RNG = np.random.default_rng(3)
X = RNG.normal(size=(200, 3))
B = np.array([[1.0, -2.0, 0.5], [0.0, 3.0, 1.0], [2.0, 0.0, -1.0]])
C = np.array([0.3, -0.7, 1.1])


def plus(key=0, **kw):
    return learn.PlusAffine(learn.AffineMLP(3, 3, hidden=(8, 8), key=key), **kw)


def test_an_affine_target_is_recovered_and_the_network_scaled_to_the_rest():
    wiggle = 1e-3 * np.sin(X)
    net = plus().rescaled(X, C + X @ B.T + wiggle)
    # 200 well-conditioned samples of O(1): least squares lands within a few hundred roundings
    # of (C, B), up to the part of the wiggle an affine map explains (< its size, 1e-3)
    assert np.abs(np.asarray(net.linear) - B).max() < 1e-3
    assert np.abs(np.asarray(net.shift) - C).max() < 1e-3
    exact = plus().rescaled(X, C + X @ B.T)
    assert np.abs(np.asarray(exact.linear) - B).max() < 100 * EPS * np.abs(B).max()
    assert np.abs(np.asarray(exact.shift) - C).max() < 100 * EPS * np.abs(B).max()
    # the inner network is scaled to the residuals (the wiggle, std ~ 7e-4), not to the outputs
    residual_std = np.std(wiggle - (net.shift + X @ np.asarray(net.linear).T - C - X @ B.T), axis=0)
    np.testing.assert_allclose(net.network.output_scale, residual_std, rtol=1e-12)


def test_the_output_is_the_affine_part_plus_the_network():
    net = plus(key=4, shift=C, linear=B)
    y = jnp.asarray(X[0])
    np.testing.assert_allclose(np.asarray(net(y)), C + B @ X[0] + np.asarray(net.network(y)), rtol=0, atol=10 * EPS)
    # unset, the affine part is zero: the inner network alone
    bare = plus(key=4)
    np.testing.assert_array_equal(np.asarray(bare(y)), np.asarray(bare.network(y)))
    # the affine part is not trained: the LPNet's parameters are the inner network's
    assert learn.LPNet(RB, network=net).n_parameters == learn.LPNet(RB, network=net.network).n_parameters


def test_a_constant_input_component_gives_a_finite_fit():
    x = X.copy()
    x[:, 1] = 2.0  # no information on that column: the minimum-norm fit puts nothing there
    net = plus().rescaled(x, C + x @ B.T)
    assert np.all(np.isfinite(net.linear)) and np.all(np.isfinite(net.shift))
    predicted = np.asarray(net.shift) + x @ np.asarray(net.linear).T
    assert np.abs(predicted - (C + x @ B.T)).max() < 1e3 * EPS * np.abs(C + x @ B.T).max()


def test_an_lpnet_on_it_trains_saves_and_loads(tmp_path):
    data = it.ground_truth(RB, X[:8] / np.linalg.norm(X[:8], axis=1, keepdims=True), h=0.1, n_steps=10,
                           progress=False)
    net, record = learn.fit(learn.LPNet(RB, network=plus()), data, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(30)),
                            normalise=True, validation_fraction=0.0, progress=False)
    # normalise=True fitted the affine part to the first-order alphas (Casimir-projected, so not
    # affine in y) and scaled the inner network to what is left: a third to two thirds of their
    # spread here; unfitted, it would be all of it
    S = np.asarray(data.states)
    estimate = net.parametrisation.params_estimate(S[:, :-1].reshape(-1, 3), S[:, 1:].reshape(-1, 3), 0.1)
    assert np.all(np.asarray(net.network.network.output_scale) < 0.8 * np.std(np.asarray(estimate), axis=0))
    assert record.train_loss < 1e-6
    net.save(tmp_path / "plus.h5")
    back = learn.load(tmp_path / "plus.h5")
    assert back.hyperparameters()["network"]["kind"] == "PlusAffine"
    y = np.asarray(data.states[:, 0])
    rollout = np.asarray(net.rollout(y, 200))  # one compiled rollout for both checks
    np.testing.assert_array_equal(np.asarray(back.rollout(y, 200)), rollout)
    assert net.reinitialised(7).network.linear == net.network.linear
    C0 = RB.casimirs(rollout)
    # 200 steps of a few roundings each on |y| = 1: the step stays on the coadjoint orbit
    assert np.abs(C0 - C0[:, :1]).max() < 200 * 64 * EPS


def test_group_averaging_goes_outside():
    group = sign_symmetries(RB)
    inside = learn.GroupAveraged(plus(shift=C, linear=B), group)
    y = jnp.asarray(X[1])
    for s in inside.group:
        s = jnp.asarray(s)
        np.testing.assert_allclose(np.asarray(inside(s * y)), np.asarray(s * inside(y)), rtol=0, atol=100 * EPS)
    with pytest.raises(ValueError, match="wrap the other way round: learn.GroupAveraged"):
        learn.PlusAffine(learn.GroupAveraged(learn.AffineMLP(3, 3, hidden=(8,), key=0), group))


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"shift": [1.0, 2.0]}, ValueError, r"PlusAffine.shift must have shape \(3,\); got \(2,\)"),
        ({"linear": np.eye(2)}, ValueError, r"PlusAffine.linear must have shape \(3, 3\); got \(2, 2\)"),
        ({"shift": [np.nan, 0.0, 0.0]}, ValueError, "PlusAffine.shift must be finite"),
        ({"linear": "abc"}, TypeError, "PlusAffine.linear must be numbers"),
    ],
)
def test_bad_affine_parts_are_refused(kwargs, error, words):
    with pytest.raises(error, match=words):
        plus(**kwargs)


def test_bad_networks_and_data_are_refused():
    with pytest.raises(TypeError, match="network must be a learn.AbstractNetwork"):
        learn.PlusAffine(lambda y: y)
    with pytest.raises(ValueError, match="as many inputs as outputs"):
        plus().rescaled(X, X[:10])
    with pytest.raises(ValueError, match="non-finite"):
        plus().rescaled(np.full_like(X, np.inf), X)
