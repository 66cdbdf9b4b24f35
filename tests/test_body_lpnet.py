"""`learn.BodyLPNet`: an LPNet fitted on body records (momenta latent): its start is the Lie-Euler
step of the weak-form quadratic, every step keeps the latent Casimirs, the gyroscope reads K mu,
files, and a fit on gyroscope records lowers the loss."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS

import integrators as it
import learn
from liepoisson.systems import RigidBody

BODY = RigidBody((1.0, 1.9, 2.1))


@functools.cache
def _records():
    omega = np.array([[0.1, 8.0, 0.2], [0.3, -9.0, 0.1], [-0.2, 10.0, 0.3]])
    return it.observe_body(BODY, omega * BODY.inertia, np.tile([0, 0, 0, 1.0], (3, 1)), np.arange(31) * 0.01,
                           measure="velocities", noise=1e-3, seed=3)


def _start(**kwargs) -> learn.BodyLPNet:
    A, b, _ = learn.weak_form_quadratic(_records(), linear=True, diagonal=False)
    return learn.BodyLPNet.at_quadratic(BODY, A, b, **kwargs)


def test_start_is_the_lie_euler_step_of_the_weak_form_quadratic():
    model = _start(h=0.01)
    A, b, _ = learn.weak_form_quadratic(_records(), linear=True, diagonal=False)
    mu = jnp.asarray([0.3, 9.0, -0.2])
    # alpha = A mu + b exactly (the network starts at zero): one test flow of it
    expected = np.asarray(BODY.test_flow(A @ np.asarray(mu) + b, 0.01, mu))
    np.testing.assert_allclose(np.asarray(model.step(mu)), expected, rtol=0, atol=64 * EPS * 9.0)
    np.testing.assert_allclose(np.asarray(model.body_velocity(mu)), 0.5 * (A + A.T) @ np.asarray(mu), rtol=1e-14)


def test_steps_keep_the_latent_casimirs_and_files_round_trip(tmp_path):
    model = _start(h=0.01, key=2)
    ys = np.asarray(model.rollout(jnp.asarray([0.3, 9.0, -0.2]), 500))
    C = np.asarray(BODY.casimirs(ys))[:, 0]
    # 500 test flows: a random walk of roundings of |Pi|^2 ~ 81
    assert np.abs(C - C[0]).max() <= 500 * EPS * C[0]
    model.save(tmp_path / "m.h5")
    back = learn.load(tmp_path / "m.h5")
    assert isinstance(back, learn.BodyLPNet)
    # the readout is a weight: saved and read back with the network
    np.testing.assert_array_equal(np.asarray(back.readout), np.asarray(model.readout))
    np.testing.assert_array_equal(np.asarray(back.step(jnp.asarray(ys[3]))), np.asarray(model.step(jnp.asarray(ys[3]))))


def test_bad_input():
    with pytest.raises(TypeError, match="learn.LPNet"):
        learn.BodyLPNet("net")
    with pytest.raises(ValueError, match=r"readout must be a finite \(3, 3\)"):
        learn.BodyLPNet(learn.LPNet(BODY), np.eye(2))
    with pytest.raises(ValueError, match=r"A must have shape \(3, 3\)"):
        learn.BodyLPNet.at_quadratic(BODY, np.eye(2), np.zeros(3))


@pytest.mark.slow  # ~30 s: Levenberg-Marquardt on the network, the readout and the latent starts
def test_fit_on_gyroscope_records_lowers_the_loss():
    model = _start(hidden=(8,))
    _, record = learn.fit(model, _records(), loss=learn.BodyLoss(max_step=0.005),
                               optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(40)), progress=False)
    before = record.stages[-1].details["train_loss_before"]  # the start's loss: KeepIfBetter records it
    after = float(np.asarray(record.history["train_loss"])[-1])
    # from the quadratic's Lie-Euler step (first order at h|xi| ~ 0.1) to the noise's floor
    assert after < 0.1 * before
