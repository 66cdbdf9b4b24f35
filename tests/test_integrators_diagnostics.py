"""Diagnostics (Casimir drift, relative energy error, trajectory error, plot) and the Lyapunov
exponent from heyoka's variational equations."""

import numpy as np
import pytest

import integrators as it
import liepoisson as lp

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody()
KIRCHHOFF = lp.systems.Kirchhoff(inertia=(1, 2, 1), mass=(1, 2, 1))


def test_definitions_on_a_hand_made_path():
    # |Pi|^2 = 1, 4 ; H = Pi_1^2/2 = 0.5, 2 -> <E> = 1.25, <C> = 2.5
    path = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    ref = np.array([[1.0, 0.0, 0.0], [2.0, 3.0, 4.0]])
    r = it.diagnostics(path, BODY, reference=ref, times=[0.0, 0.5])
    np.testing.assert_allclose(r.casimir_drift[:, 0], [0.0, 3.0])
    np.testing.assert_allclose(r.casimir_drift_relative[:, 0], [0.0, 3.0 / 2.5])
    np.testing.assert_allclose(r.energy_error_relative, [0.0, 1.5 / 1.25])
    np.testing.assert_allclose(r.trajectory_error, [0.0, 5.0])
    assert r.max_trajectory_error == 5.0 and r["max_energy_error"] == pytest.approx(1.2)
    np.testing.assert_array_equal(r.times, [0.0, 0.5])


def test_ground_truth_and_strang():
    y0 = np.array([[1 / np.sqrt(2), -1 / np.sqrt(2), 1.0], [0.5, 1.0, -0.2]])
    gt = it.ground_truth(BODY, y0, 0.1, 500)
    r = it.diagnostics(gt, BODY)
    assert r.casimirs.shape == (2, 501, 1) and r.energy.shape == (2, 501)
    assert r.max_casimir_drift_relative < 1e3 * EPS and r.max_energy_error < 1e3 * EPS
    ys = it.splitting.Strang(BODY).rollout(y0, 0.1, 500)
    r = it.diagnostics(ys, BODY, reference=gt)
    assert r.trajectory_error.shape == (2, 501)
    assert r.max_casimir_drift_relative < 1e3 * EPS  # exact sub-flows: Casimir to round-off
    assert 1e-8 < r.max_energy_error < 1e-2  # but energy only to O(h^2)
    np.testing.assert_array_equal(r.times, gt.times)


def test_zero_casimir_safe_denominator():
    # Kirchhoff with Pi.p = 0 along the path: relative drift falls back to absolute
    gt = it.ground_truth(KIRCHHOFF, [1.0, 0.0, 0.0, 0.0, 1.0, 0.0], 0.1, 50)
    r = it.diagnostics(gt, KIRCHHOFF)
    assert np.all(np.isfinite(r.casimir_drift_relative)) and r.max_casimir_drift_relative < 1e-14


def test_plot(tmp_path):
    pytest.importorskip("matplotlib")
    gt = it.ground_truth(KIRCHHOFF, [1, 1, 1, -1, 1, 2], 0.1, 20)
    ys = it.splitting.Strang(KIRCHHOFF).rollout([1, 1, 1, -1, 1, 2], 0.1, 20)
    it.plot_diagnostics(it.diagnostics(ys, KIRCHHOFF, reference=gt.states[0]), tmp_path / "d.png", title="x")
    assert (tmp_path / "d.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "args, error, words",
    [
        ((np.ones((4, 2)),), ValueError, ["trajectory", "(4, 2)"]),
        ((np.full((4, 3), np.nan),), ValueError, ["trajectory", "finite"]),
        ((np.ones((4, 3)), np.ones((5, 3))), ValueError, ["reference", "(5, 3)"]),
    ],
)
def test_validation(args, error, words):
    with pytest.raises(error) as info:
        it.diagnostics(args[0], BODY, *args[1:])
    for w in words:
        assert w in str(info.value)


def test_lyapunov_kirchhoff_short_horizon():
    # The paper quotes error growth ~ exp(0.25 t) up to t = 10 for this trajectory; the
    # finite-time exponent over [0, 10] is that number (it decays towards 0 later on).
    lam = it.lyapunov_exponent(KIRCHHOFF, [1, 1, 1, -1, 1, 2], 10.0)
    assert 0.2 < lam < 0.3


def test_lyapunov_validation():
    with pytest.raises(ValueError, match="t_final"):
        it.lyapunov_exponent(BODY, [1.0, 0.0, 0.0], -1.0)
    with pytest.raises(ValueError, match="y0"):
        it.lyapunov_exponent(BODY, [1.0, 0.0], 1.0)


@pytest.mark.slow
def test_lyapunov_kirchhoff_long_horizon():
    # Over t = 1000 the estimate is ~log(t)/t: perturbations grow linearly, not exponentially.
    lam, _times, est = it.lyapunov_exponent(KIRCHHOFF, [1, 1, 1, -1, 1, 2], 1000.0, return_history=True)
    assert lam < 0.02 and est[9] > 0.2
