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
    ys = it.splitting.Strang(BODY, h=0.1).rollout(y0, 500)
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
    ys = it.splitting.Strang(KIRCHHOFF, h=0.1).rollout([1, 1, 1, -1, 1, 2], 20)
    it.plot_diagnostics(it.diagnostics(ys, KIRCHHOFF, reference=gt.states[0]), tmp_path / "d.png", title="x")
    assert (tmp_path / "d.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "args, error, words",
    [
        ((np.ones((4, 2)),), ValueError, ["trajectory", "(4, 2)"]),
        ((np.full((4, 3), np.nan),), ValueError, ["trajectory", "start finite"]),
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


def test_integrals_against_numpy():
    # A hand-made path: I(t) = 1 + t^2 on a grid, so (I(t) - I(0)) / <I> in closed form.
    t = np.linspace(0.0, 2.0, 21)
    y = np.stack([np.sqrt(1.0 + t**2), np.zeros_like(t), np.zeros_like(t)], axis=-1)
    report = it.diagnostics(y, BODY, times=t, integrals={"I": lambda z: z[..., 0] ** 2})
    expected = (t**2) / np.mean(1.0 + t**2)
    # sqrt then square: a few roundings per value.
    np.testing.assert_allclose(report.integral_error_relative["I"], expected, rtol=0, atol=8 * EPS)
    assert report.max_integral_error("I") == pytest.approx(4.0 / np.mean(1.0 + t**2), rel=8 * EPS)
    assert "max_integral_error[I]" in report.summary()
    with pytest.raises(KeyError, match="no integral 'J'"):
        report.max_integral_error("J")
    with pytest.raises(TypeError, match="integrals"):
        it.diagnostics(y, BODY, integrals={"I": 3.0})


@pytest.mark.parametrize("k", [1, 7, 19])
def test_diverged_rollout_is_reported_up_to_the_first_non_finite_step(k):
    ys = np.array(it.splitting.Strang(BODY, h=0.1).rollout(np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4]]), 20))
    ref = ys.copy()
    ys[1, k:, 2] = np.inf
    ys[1, k + 1 :] = np.nan
    report = it.diagnostics(ys, BODY, reference=ref)
    clean = it.diagnostics(ys[:, :k], BODY, reference=ref[:, :k])
    assert report.diverged_at_step == k and report.summary()["diverged_at_step"] == k
    assert clean.diverged_at_step is None
    assert report.summary() | {"diverged_at_step": None} == clean.summary()
    np.testing.assert_array_equal(report.energy, clean.energy)


def test_non_finite_start_or_reference_raises():
    y = np.ones((2, 5, 3))
    y[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match=r"initial state at index \(1, 1\)"):
        it.diagnostics(y, BODY)
    ref = np.ones((5, 3))
    ref[3, 0] = np.inf
    with pytest.raises(ValueError, match="reference must be finite"):
        it.diagnostics(np.ones((5, 3)), BODY, reference=ref)


def test_error_growth_rate():
    t = np.linspace(0.0, 10.0, 101)
    # Noise-free exponential: the log-linear fit is exact up to round-off in log and polyfit.
    assert it.error_growth_rate(t, 1e-3 * np.exp(0.25 * t), (1.0, 10.0)) == pytest.approx(0.25, abs=1e-12)
    noisy = 1e-3 * np.exp(0.25 * t) * np.exp(np.random.default_rng(0).normal(0.0, 0.05, t.size))
    # 5% log-normal noise over 91 points: the slope's standard error is ~0.05/(sd(t) sqrt(91)) ~ 2e-3.
    assert abs(it.error_growth_rate(t, noisy, (1.0, 10.0)) - 0.25) < 1e-2
    ys = np.asarray(it.splitting.Strang(BODY, h=0.1).rollout(np.array([1.0, 0.5, 0.2]), 100))
    report = it.diagnostics(ys, BODY, reference=ys + 1e-6 * np.exp(0.3 * np.arange(101) * 0.1)[:, None],
                            times=0.1 * np.arange(101))
    # |y - ref| = sqrt(3) 1e-6 exp(0.3 t): the report's rate is that of the largest error.
    assert report.error_growth_rate((1.0, 10.0)) == pytest.approx(0.3, abs=1e-9)
    with pytest.raises(ValueError, match="t_min < t_max"):
        it.error_growth_rate(t, t + 1, (5.0, 1.0))
    with pytest.raises(ValueError, match="at least 2 points"):
        it.error_growth_rate(t, np.zeros_like(t), (1.0, 10.0))
    with pytest.raises(ValueError, match="same shape"):
        it.error_growth_rate(t, t[:5], (1.0, 10.0))
    with pytest.raises(ValueError, match="with a reference"):
        it.diagnostics(ys, BODY).error_growth_rate((1.0, 10.0))
