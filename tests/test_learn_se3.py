"""learn.SE3RotationShear: the closed-form rotation + shear step of se(3)* (Kirchhoff)."""

import numpy as np
import pytest

import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
H = 0.1


@pytest.fixture
def system():
    return lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))


def _exact_pairs(system, rng, n=16):
    """Pairs one step of the exact Kirchhoff flow apart (heyoka; shares no code with the
    parametrisation), from states near the paper's (1, 1, 1, -1, 1, 2)."""
    import integrators as it

    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0]) + rng.uniform(-0.5, 0.5, size=(n, 6))
    traj = it.ground_truth(system, y0, h=H, n_steps=1)
    return traj.states[:, 0], traj.states[:, 1]


@pytest.mark.slow  # the round trip from parameters by default below and in test_inverse_flows.py
def test_round_trip_on_exact_flow_pairs(system):
    param = learn.SE3RotationShear(system)
    y0, y1 = _exact_pairs(system, np.random.default_rng(0))
    alpha = param.params_from_pair(y0, y1, H)
    stepped = np.stack([np.asarray(param.step(a, y, H)) for a, y in zip(alpha, y0)])
    # closed form: a few tens of ulps of |y| (atan2, cross products, one division by |p|^2)
    np.testing.assert_allclose(stepped, y1, rtol=0, atol=100 * EPS * np.max(np.abs(y1)))


def test_round_trip_from_parameters(system):
    """params -> step -> params recovers the minimum-norm parameters (A _|_ p0, b _|_ pf)."""
    param = learn.SE3RotationShear(system)
    rng = np.random.default_rng(1)
    y0 = rng.normal(size=(8, 6))
    p0 = y0[:, 3:]
    A = rng.normal(size=(8, 3))
    A -= np.einsum("ia,ia->i", A, p0)[:, None] * p0 / np.sum(p0 * p0, -1)[:, None]
    A *= 0.8 / (H * np.linalg.norm(A, axis=-1, keepdims=True))  # angle 0.8 < pi: shortest rotation
    b = rng.normal(size=(8, 3))
    y1 = []
    for a, bb, y in zip(A, b, y0):
        rotated = np.asarray(param.step(np.concatenate([a, np.zeros(3)]), y, H))
        pf = rotated[3:]
        bb = bb - (bb @ pf) * pf / (pf @ pf)
        y1.append(np.asarray(param.step(np.concatenate([a, bb]), y, H)))
        b[len(y1) - 1] = bb
    found = param.params_from_pair(y0, np.stack(y1), H)
    np.testing.assert_allclose(
        found, np.concatenate([A, b], -1), rtol=0, atol=1e3 * EPS * np.max(np.abs(b))
    )


def test_casimirs_exact_for_any_parameters(system):
    param = learn.SE3RotationShear(system)
    rng = np.random.default_rng(2)
    y = rng.normal(size=(32, 6))
    alpha = 5.0 * rng.normal(size=(32, 6))
    y1 = np.stack([np.asarray(param.step(a, v, H)) for a, v in zip(alpha, y)])
    C0, C1 = np.asarray(system.casimirs(y)), np.asarray(system.casimirs(y1))
    # a handful of roundings of |p|^2 and Pi.p (entries O(|y|^2) ~ 10)
    np.testing.assert_allclose(C1, C0, rtol=0, atol=100 * EPS * np.max(np.abs(C0)) + 100 * EPS)


def test_degenerate_p_parallel(system):
    """p0 = pf: no rotation (A = 0 exactly, no NaN); the shear alone carries Pi."""
    param = learn.SE3RotationShear(system)
    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    b = np.array([0.3, 0.7, -0.2])
    b -= (b @ y0[3:]) * y0[3:] / (y0[3:] @ y0[3:])
    y1 = np.asarray(param.step(np.concatenate([np.zeros(3), b]), y0, H))
    assert np.array_equal(y1[3:], y0[3:])
    alpha = param.params_from_pair(y0, y1, H)
    assert np.all(np.isfinite(alpha)) and np.all(alpha[:3] == 0.0)
    np.testing.assert_allclose(alpha[3:], b, rtol=0, atol=100 * EPS)
    assert np.all(param.params_from_pair(y0, y0, H) == 0.0)


def test_rejects_mismatched_casimirs_and_bad_input(system):
    param = learn.SE3RotationShear(system)
    y0 = np.array([[1.0, 1.0, 1.0, -1.0, 1.0, 2.0], [1.0, 1.0, 1.0, -1.0, 1.0, 2.0]])
    y1 = y0.copy()
    y1[1, 0] += 1e-6  # changes Pi . p only
    # lp.se3()'s Casimirs are (|p|^2, Pi . p): Casimir 1 is Pi . p
    with pytest.raises(ValueError, match=r"pair 1: Casimir 1 "):
        param.params_from_pair(y0, y1, H)
    y1 = y0.copy()
    y1[0, 5] += 1e-6  # changes |p|
    with pytest.raises(ValueError, match="pair 0: Casimir 0 "):
        param.params_from_pair(y0, y1, H)
    with pytest.raises(ValueError, match="se\\(3\\)"):
        learn.SE3RotationShear(lp.systems.RigidBody())


def test_errors_name_the_arguments_y0_y1(system):
    param = learn.SE3RotationShear(system)
    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="y1"):
        param.params_from_pair(y0, y0[:5], H)


@pytest.mark.slow  # a training run (~4 s); the Casimirs for any parameters are tested by default above
def test_lpnet_with_se3_rotation_shear(system):
    """An LPNet on this parametrisation trains a few epochs and conserves the Casimirs."""
    import integrators as it

    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0]) + np.random.default_rng(3).uniform(
        -0.1, 0.1, (4, 6)
    )
    data = it.ground_truth(system, y0, h=H, n_steps=10)
    net = learn.LPNet(system, hidden=(8,), parametrisation=learn.SE3RotationShear(system), key=0)
    # no validation split: one shape of the loss to compile, not two (the best weights are then
    # those of the lowest training loss)
    net, record = learn.fit(net, data, optimiser=learn.Adam(5), validation_fraction=0.0, progress=False)
    assert np.all(np.isfinite(record.history["train_loss"]))  # gradients through the parametrisation
    y = np.asarray(net.rollout(y0, 20))
    C = np.asarray(system.casimirs(y))
    np.testing.assert_allclose(
        C, np.broadcast_to(C[:, :1], C.shape), rtol=0, atol=1e3 * EPS * np.max(np.abs(C))
    )
