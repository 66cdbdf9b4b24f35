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


@pytest.mark.slow
def test_plot(tmp_path):
    pytest.importorskip("matplotlib")
    gt = it.ground_truth(KIRCHHOFF, [1, 1, 1, -1, 1, 2], 0.1, 20)
    ys = it.splitting.Strang(KIRCHHOFF, h=0.1).rollout([1, 1, 1, -1, 1, 2], 20)
    it.plot_diagnostics(it.diagnostics(ys, KIRCHHOFF, reference=gt.states[0]), tmp_path / "d.png", title="x")
    assert (tmp_path / "d.png").stat().st_size > 1000


def test_plot_has_a_panel_per_integral(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, path, **kw: saved.append(fig))
    ys = it.splitting.Strang(BODY, h=0.1).rollout([1.0, 0.5, 0.2], 20)
    r = it.diagnostics(ys, BODY, integrals={"I": lambda z: z[..., 0] + 1.0})
    it.plot_diagnostics(r, tmp_path / "d.png")
    labels = [ax.get_ylabel() for ax in saved[0].axes]
    assert labels == ["relative energy error", "relative Casimir drift", "relative error of I"]


@pytest.mark.parametrize(
    "args, error, words",
    [
        ((np.ones((4, 2)),), ValueError, ["trajectory", "(4, 2)"]),
        ((np.full((4, 3), np.nan),), ValueError, ["trajectory", "start finite", "component 0 = nan"]),
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
    with pytest.raises(ValueError, match=r"integrals\['I'\] must return one value per state, shape \(21,\)"):
        it.diagnostics(y, BODY, integrals={"I": lambda z: z[..., :2]})


def test_integrals_of_many_trajectories_against_numpy():
    # Per trajectory time means; the second has <I> = 0, so its error falls back to I(t) - I(0).
    rng = np.random.default_rng(1)
    y = rng.normal(size=(2, 6, 3))
    y[0, :, 0] = [2.0, 2.5, 3.0, 3.5, 4.0, 4.5]  # <I> = 3.25, largest error 2.5/3.25
    y[1, :, 0] = [1.0, -2.0, 3.0, -1.0, 2.0, -3.0]  # <I> = 0, largest error |-3 - 1| = 4
    report = it.diagnostics(y, BODY, integrals={"I": lambda z: z[..., 0], "J": lambda z: z[..., 1] * z[..., 2]})
    I, J = y[..., 0], y[..., 1] * y[..., 2]
    expected_I = np.stack([(I[0] - I[0, 0]) / I[0].mean(), I[1] - I[1, 0]])
    expected_J = (J - J[:, :1]) / J.mean(axis=1, keepdims=True)
    np.testing.assert_array_equal(report.integrals["I"], I)
    np.testing.assert_allclose(report.integral_error_relative["I"], expected_I, rtol=4 * EPS, atol=0)
    np.testing.assert_allclose(report.integral_error_relative["J"], expected_J, rtol=16 * EPS, atol=0)
    assert report.max_integral_error("I") == 4.0
    assert report["max_integral_error[J]"] == pytest.approx(np.abs(expected_J).max(), rel=16 * EPS)


@pytest.mark.slow
def test_charged_particle_integral_is_conserved_by_the_ground_truth():
    # E4's second integral: heyoka at its tightest tolerance keeps it to round-off, Strang does not.
    system = lp.systems.ChargedParticle()
    y0 = np.array([0.1, 0.2, 1.0, 0.5])
    gt = it.ground_truth(system, y0, 0.1, 200)
    integrals = {"I": system.angular_integral}
    r = it.diagnostics(gt, system, integrals=integrals)
    np.testing.assert_allclose(r.integrals["I"], np.asarray(system.angular_integral(gt.states)), rtol=0, atol=0)
    assert r.max_integral_error("I") < 1e3 * EPS
    r = it.diagnostics(it.splitting.Strang(system, h=0.1).rollout(y0, 200), system, integrals=integrals)
    assert r.max_integral_error("I") > 1e-8


@pytest.mark.parametrize("k", [pytest.param(1, marks=pytest.mark.slow), 7, pytest.param(19, marks=pytest.mark.slow)])
def test_diverged_rollout_is_reported_up_to_the_first_non_finite_step(k):
    ys = np.array(it.splitting.Strang(BODY, h=0.1).rollout(np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4]]), 20))
    ref = it.ground_truth(BODY, ys[:, 0], 0.1, 20)
    clean_states = ys.copy()
    ys[1, k:, 2] = np.inf
    ys[1, k + 1 :] = np.nan
    ys[0, k + 1 :, 0] = np.nan  # a later divergence of another trajectory does not matter
    integrals = {"I": lambda z: z[..., 0] + 2.0}
    report = it.diagnostics(ys, BODY, reference=ref, integrals=integrals)
    # The independent figure: the same function on the finite prefix, cut by hand.
    clean = it.diagnostics(clean_states[:, :k], BODY, reference=ref.states[:, :k], times=ref.times[:k],
                           integrals=integrals)
    assert report.diverged_at_step == k and report.summary()["diverged_at_step"] == k
    assert clean.diverged_at_step is None
    # Where: the first non-finite step, the trajectory that got there first, its last finite state.
    assert report.divergence.trajectory == 1
    np.testing.assert_array_equal(report.divergence.state, clean_states[1, k - 1])
    assert f"step {k} (trajectory 1; last finite state, at step {k - 1}: [" in str(report.divergence)
    # The divergence policy: every figure is infinite, never that of the finite steps alone...
    figures = {key: v for key, v in report.summary().items() if key != "diverged_at_step"}
    assert figures and all(v == np.inf for v in figures.values()), figures
    assert report.max_integral_error("I") == report.max_energy_error == np.inf
    # ...which the report of the steps before the divergence still gives.
    assert report.before_divergence().summary() == clean.summary()
    for field in ("times", "casimirs", "casimir_drift_relative", "energy", "energy_error_relative",
                  "trajectory_error"):
        np.testing.assert_array_equal(report[field], clean[field])
    assert report.times.shape == (k,) and report.trajectory_error.shape == (2, k)
    np.testing.assert_array_equal(report.integral_error_relative["I"], clean.integral_error_relative["I"])


def test_single_diverged_trajectory():
    # the first 10 steps of the 20-step rollout compiled for test_plot_has_a_panel_per_integral
    y = np.array(it.splitting.Strang(BODY, h=0.1).rollout(np.array([1.0, 0.5, 0.2]), 20))[:11]
    y[4, 1] = -np.inf
    report = it.diagnostics(y, BODY, times=np.linspace(0.0, 1.0, 11))
    assert report.diverged_at_step == 4 and report.energy.shape == (4,)
    np.testing.assert_array_equal(report.times, np.linspace(0.0, 1.0, 11)[:4])
    finite = it.diagnostics(y[:4], BODY)
    assert finite.diverged_at_step is None and finite.summary()["diverged_at_step"] is None


@pytest.mark.filterwarnings("error")  # no numpy overflow or invalid-value warning on the way
@pytest.mark.parametrize("overflows", ["energy", "integral"])
def test_finite_states_whose_energy_or_integral_overflows_count_as_diverged(overflows):
    # A rollout on its way out: every state finite, but at step 5 of trajectory 1 a component of
    # 1e160 makes |Pi|^2 (energy and Casimir) overflow to inf; or only the integral, a cube of
    # 1e110, overflows. The series end at step 5, as for a non-finite state.
    # the first 9 steps of the 20-step rollout compiled for the test above
    ys = np.array(it.splitting.Strang(BODY, h=0.1).rollout(np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4]]), 20))[:, :10]
    clean_states = ys[:, :5].copy()
    ys[1, 5:, 0] = 1e160 if overflows == "energy" else 1e110
    assert np.all(np.isfinite(ys))
    integrals = {"I": lambda z: z[..., 0] ** 3}
    report = it.diagnostics(ys, BODY, integrals=integrals)
    clean = it.diagnostics(clean_states, BODY, integrals=integrals)
    assert report.diverged_at_step == 5 and report.divergence.trajectory == 1
    np.testing.assert_array_equal(report.divergence.state, clean_states[1, 4])
    assert report.max_energy_error == report.max_integral_error("I") == np.inf
    assert report.before_divergence().summary() == clean.summary()
    np.testing.assert_array_equal(report.energy_error_relative, clean.energy_error_relative)


def test_initial_state_with_an_overflowing_energy_raises():
    y = np.ones((2, 4, 3))
    y[1, 0, 0] = 1e200
    with pytest.raises(ValueError, match=r"must start with a finite energy, Casimirs and integrals; the initial "
                                         r"state \[1e\+200, 1.0, 1.0\] of trajectory 1 has energy inf, a non-finite Casimir"):
        it.diagnostics(y, BODY)
    with pytest.raises(ValueError, match=r"of trajectory 0 has integral 'I' nan$"):
        it.diagnostics(np.ones((4, 3)), BODY, integrals={"I": lambda z: np.sqrt(z[..., 0] - 2.0)})


def test_non_finite_start_or_reference_raises():
    y = np.ones((2, 5, 3))
    y[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match=r"initial state has trajectory 1, component 1 = nan"):
        it.diagnostics(y, BODY)
    with pytest.raises(ValueError, match=r"initial state has component 2 = inf"):
        it.diagnostics(np.array([[1.0, 0.0, np.inf], [1.0, 0.0, 0.0]]), BODY)
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
    ys = np.asarray(it.splitting.Strang(BODY, h=0.1).rollout(np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4]]), 100))
    grid = 0.1 * np.arange(101)
    offset = np.stack([1e-6 * np.exp(0.3 * grid), 1e-7 * np.exp(0.1 * grid)])[..., None]
    report = it.diagnostics(ys, BODY, reference=ys + offset, times=grid)
    # |y - ref| = sqrt(3) 1e-6 exp(0.3 t) > sqrt(3) 1e-7 exp(0.1 t): the report's rate is that of
    # the largest error at each time (the mean's would be ~0.02 lower).
    assert report.error_growth_rate((1.0, 10.0)) == pytest.approx(0.3, abs=1e-9)
    with pytest.raises(ValueError, match="t_min < t_max"):
        it.error_growth_rate(t, t + 1, (5.0, 1.0))
    with pytest.raises(ValueError, match="at least 2 points"):
        it.error_growth_rate(t, np.zeros_like(t), (1.0, 10.0))
    with pytest.raises(ValueError, match="same shape"):
        it.error_growth_rate(t, t[:5], (1.0, 10.0))
    with pytest.raises(ValueError, match="1-D"):
        it.error_growth_rate(t[None], t[None] + 1, (1.0, 10.0))
    with pytest.raises(ValueError, match="window must be a pair"):
        it.error_growth_rate(t, t + 1, (1.0, 5.0, 10.0))
    with pytest.raises(TypeError, match="window must be a pair of numbers"):
        it.error_growth_rate(t, t + 1, ("a", "b"))
    with pytest.raises(ValueError, match="1 times lie in the window"):
        it.error_growth_rate(t, t + 1, (2.01, 2.1))
    # Only the points inside the window count: a jump outside it does not change the rate.
    jumped = np.where(t < 1.0, 1e3, 1e-3 * np.exp(0.25 * t))
    assert it.error_growth_rate(t, jumped, (1.0, 10.0)) == pytest.approx(0.25, abs=1e-12)
    with pytest.raises(ValueError, match="with a reference"):
        it.diagnostics(ys, BODY).error_growth_rate((1.0, 10.0))


def test_per_state_values_are_the_unpadded_ones_to_the_bit():
    from integrators._diagnostics import MIN_BUCKET, per_state

    rng = np.random.default_rng(5)
    for system in (lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)), lp.systems.Kirchhoff()):
        for shape in ((1, system.dim), (7, system.dim), (3, 301, system.dim), (MIN_BUCKET, system.dim)):
            y = rng.normal(size=shape)
            np.testing.assert_array_equal(per_state(system.casimirs, y), np.asarray(system.casimirs(y)))
            np.testing.assert_array_equal(per_state(system.hamiltonian, y), np.asarray(system.hamiltonian(y)))


def test_figures_of_rollouts_of_many_lengths_compile_once_per_bucket():
    from helpers import compilations

    body = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    m = it.splitting.Strang(body, h=0.1)
    y0 = np.array([[1.0, 0.2, -0.3]])
    reference = it.ground_truth(body, y0, h=0.1, n_steps=120)
    it.rollout_figures(m, m.rollout(y0, 120), reference)
    with compilations() as seen:  # every length within the first bucket (256 states): nothing new
        for n in (17, 40, 77, 101, 119):
            it.rollout_figures(m, m.rollout(y0, n), reference.states[:, : n + 1])
    assert seen["traces"] == 0


def test_save_figure_is_atomic_and_takes_its_format_from_the_suffix(tmp_path, monkeypatch):
    """`save_figure` writes the format its suffix names (matplotlib's default, suffix added,
    when there is none), and a drawing that fails leaves the file it replaces whole, with no
    temporary beside it."""
    matplotlib = pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    from integrators.internals import figure, save_figure

    fig = figure()
    fig.add_subplot().plot([0, 1], [1, 0])
    assert save_figure(fig, tmp_path / "a.svg") == tmp_path / "a.svg"
    assert (tmp_path / "a.svg").read_text().lstrip().startswith("<?xml")
    with matplotlib.rc_context({"savefig.format": "png"}):
        assert save_figure(fig, tmp_path / "b") == tmp_path / "b.png"
    assert (tmp_path / "b.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # format= wins over the suffix, as in savefig; an upper-case suffix is its format
    assert save_figure(fig, tmp_path / "c.png", format="svg") == tmp_path / "c.png"
    assert (tmp_path / "c.png").read_text().lstrip().startswith("<?xml")
    save_figure(fig, tmp_path / "D.PNG")
    assert (tmp_path / "D.PNG").read_bytes()[:4] == b"\x89PNG"
    (tmp_path / "c.png").unlink()
    (tmp_path / "D.PNG").unlink()
    # a format matplotlib cannot write: refused by name, before any folder is made
    with pytest.raises(ValueError, match="format 'txt' is not one of matplotlib's"):
        save_figure(fig, tmp_path / "new" / "x.txt")
    assert not (tmp_path / "new").exists()
    before = (tmp_path / "b.png").read_bytes()

    def broken(self, path, **kwargs):
        with open(path, "wb") as f:
            f.write(b"half a fig")
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(Figure, "savefig", broken)
    with pytest.raises(RuntimeError, match="drawing failed"):
        save_figure(fig, tmp_path / "b.png")
    assert (tmp_path / "b.png").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.svg", "b.png"]
