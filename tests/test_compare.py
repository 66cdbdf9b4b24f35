"""integrators.compare: learned and classical step maps measured side by side against heyoka."""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import system

import integrators as it
import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
Y0S = np.array([[1 / np.sqrt(2), -1 / np.sqrt(2), 1.0], [0.5, 1.0, -0.2]])


@pytest.mark.slow  # four maps compiled (~3.5 s); compare on a diverging map and rollout_figures run by default
def test_compare_measures_every_map_against_the_same_reference(tmp_path):
    body = system("RigidBody")
    maps = {
        "Strang h": it.splitting.Strang(body, h=0.1),
        "Strang h/2": it.splitting.Strang(body, h=0.05),
        "RK4": it.RK4(body, h=0.1),
        "G-LPNet": learn.GLPNet(body, n_modules=3, h=0.1),
    }
    c = it.compare(maps, body, Y0S, t_final=10.0, n_outputs=20, timing_seconds=0.01)  # timing: see test_step_timing
    rows = {r.label: r for r in c.rows}
    assert [r.label for r in c.rows] == list(maps)
    assert rows["Strang h/2"].n_steps == 200 and rows["Strang h"].n_steps == 100
    # Strang has order 2: halving h divides the error at T by ~4 (3.9-4.1 measured).
    assert 3.5 < rows["Strang h"].error_final / rows["Strang h/2"].error_final < 4.5
    # The reference is heyoka at the output times; the errors are those of the maps' rollouts.
    y = np.asarray(maps["RK4"].rollout(Y0S, 100, save_every=5))
    assert rows["RK4"].error_final == pytest.approx(np.max(np.linalg.norm(y[:, -1] - c.reference[:, -1], axis=-1)),
                                                    rel=1e-12)
    # Splittings and G-LPNets are Poisson maps on the orbit; RK4 is neither.
    for label in ("Strang h", "Strang h/2", "G-LPNet"):
        assert rows[label].casimir_drift_max < 1e3 * EPS and rows[label].poisson_defect_max < 1e3 * EPS
    assert rows["RK4"].casimir_drift_max > 1e-10
    assert all(r.seconds_per_step > 0 and r.flops_per_step > 0 for r in c.rows)
    assert c.table().count("\n") == 2 + len(maps)
    it.plot_work_precision(c, tmp_path / "wp.png")
    it.plot_energy(c, tmp_path / "energy.png")
    assert (tmp_path / "wp.png").stat().st_size > 0 and (tmp_path / "energy.png").stat().st_size > 0
    # A row holds its map's RolloutFigures, not a copy of their fields; the reports are the rows'.
    strang = rows["Strang h"]
    assert isinstance(strang.figures, it.RolloutFigures)
    assert strang.error_final == strang.figures.error_final and strang.divergence is strang.figures.divergence
    assert c.reports["Strang h"] is strang.figures.report
    own = {f.name for f in dataclasses.fields(it.ComparisonRow)}
    assert not own & {f.name for f in dataclasses.fields(it.RolloutFigures)}
    with pytest.raises(TypeError, match="comparison must be an integrators.Comparison"):
        it.plot_energy(c.rows, tmp_path / "no.png")


class Expanding(it.AbstractStepMap):
    r"""$y \mapsto (1 + h)\,y$, and NaN once $\max_i |y_i|$ exceeds `limit`: from $\max_i|y_{0,i}| = 1$
    at $h = 0.1$ the first NaN is at step 33 ($1.1^{31} < 21 < 1.1^{32}$), from 1/2 at step 41."""

    system: lp.systems.AbstractPoissonSystem
    h: float
    limit: float = 21.0

    def step(self, y):
        return jnp.where(jnp.max(jnp.abs(y)) > self.limit, jnp.nan, (1.0 + self.h) * y)

    @property
    def exact_flows_per_step(self):
        return 0


# Trajectory 0 stops being finite at step 33 (last finite state 1.1^32 y0), trajectory 1 at 41, 2 at 70.
Y0_EXPANDING = np.array([[1 / np.sqrt(2), -1 / np.sqrt(2), 1.0], [0.5, 0.5, -0.2], [0.01, 0.02, 0.03]])


def _expanded(y0, k):
    """y0 after k steps of Expanding at h = 0.1, the same roundings."""
    for _ in range(k):
        y0 = 1.1 * y0
    return y0


@pytest.mark.slow
def test_compare_reports_a_map_that_diverges_with_infinite_errors_and_its_step():
    body = system("RigidBody")
    maps = {"Strang": it.splitting.Strang(body, h=0.1), "expanding": Expanding(body, h=0.1)}
    # Outputs every 5 steps: the rollout is first non-finite at output 7 (step 35), between them
    c = it.compare(maps, body, Y0_EXPANDING, t_final=10.0, n_outputs=20, timing_seconds=0.01)
    strang, expanding = c.rows
    assert strang.divergence is None and strang.diverged_at_step is None and math.isfinite(strang.energy_error_max)
    # Infinite, not the figures of its finite steps.
    assert expanding.error_final == expanding.error_max == math.inf
    assert expanding.energy_error_max == expanding.casimir_drift_max == math.inf
    # The first non-finite step of the map, not of the outputs, and the state before it.
    assert expanding.diverged_at_step == 33 and expanding.divergence.trajectory == 0
    np.testing.assert_allclose(expanding.divergence.state, _expanded(Y0_EXPANDING[0], 32), rtol=4 * EPS)
    assert np.isfinite(expanding.poisson_defect_max) and expanding.seconds_per_step > 0
    # The reports keep the time series up to the last finite output (step 30).
    assert c.reports["expanding"].times[-1] == pytest.approx(3.0)
    table = c.table()
    lines = table.splitlines()
    assert lines[0].endswith("| diverged at step |")
    row = next(line for line in lines if line.startswith("| expanding "))
    assert row.count("| inf ") == 4 and row.endswith("| 33 |")
    assert next(line for line in lines if line.startswith("| Strang ")).endswith("| — |")
    note = next(line for line in lines if line.startswith("expanding stopped being finite"))
    assert "step 33 (trajectory 0; last finite state, at step 32: [" in note


def test_rollout_figures_of_a_finite_and_of_a_diverged_rollout():
    body = system("RigidBody")
    reference = it.ground_truth(body, Y0_EXPANDING, h=0.5, n_steps=7)
    strang = it.splitting.Strang(body, h=0.1)
    y = np.asarray(strang.rollout(Y0_EXPANDING, 35, save_every=5))
    figures = it.rollout_figures(strang, y, reference, save_every=5, defect_points=4)
    report = it.diagnostics(y, body, reference=reference)
    assert figures.divergence is None and figures.report.divergence is None
    assert figures.error_final == np.max(np.linalg.norm(y[:, -1] - reference.states[:, -1], axis=-1))
    assert figures.error_max == report.max_trajectory_error
    assert figures.energy_error_max == report.max_energy_error > 0
    assert figures.energy_error_mean == report.mean_energy_error
    assert figures.casimir_drift_max == report.max_casimir_drift_relative
    np.testing.assert_array_equal(figures.energy_error_max_per_trajectory,
                                  [it.diagnostics(z, body).max_energy_error for z in y])
    # The defect: equally spaced outputs of trajectory 0, or a random draw from all of them.
    assert figures.poisson_defect_max == np.max(np.asarray(strang.poisson_defect(y[0, [0, 2, 4, 7]])))
    drawn = it.rollout_figures(strang, y, reference, save_every=5, defect_points=4, defect_seed=3)
    pick = y.reshape(-1, 3)[np.random.default_rng(3).choice(24, size=4, replace=False)]
    assert drawn.poisson_defect_max == np.max(np.asarray(strang.poisson_defect(pick)))
    assert it.rollout_figures(strang, y, save_every=5, defect_points=0).poisson_defect_max is None

    expanding = Expanding(body, h=0.1)
    y = np.asarray(expanding.rollout(Y0_EXPANDING, 35, save_every=5, nonfinite="return"))
    figures = it.rollout_figures(expanding, y, reference, save_every=5)
    assert figures.diverged_at_step == 33 and figures.divergence.trajectory == 0
    assert figures.error_final == figures.error_max == figures.energy_error_max == math.inf
    assert figures.energy_error_mean == figures.casimir_drift_max == math.inf
    # Trajectories 1 and 2 stayed finite over the 35 steps: each keeps its own figure.
    per_trajectory = figures.energy_error_max_per_trajectory
    assert per_trajectory[0] == math.inf
    np.testing.assert_array_equal(per_trajectory[1:], [it.diagnostics(z, body).max_energy_error for z in y[1:]])
    # What the 6 finite outputs alone would have said: finite, and never the map's figure.
    assert 0 < figures.report.before_divergence().max_energy_error < math.inf
    with pytest.raises(TypeError, match="step_map must be an integrators.AbstractStepMap"):
        it.rollout_figures("Strang", y, reference)
    with pytest.raises(ValueError, match="defect_points must be an integer >= 0"):
        it.rollout_figures(expanding, y, defect_points=-1)


@pytest.mark.filterwarnings("error")  # no numpy overflow warning on the way
def test_rollout_figures_of_a_trajectory_whose_energy_overflows_while_its_states_stay_finite():
    # Trajectory 1 heads out: its states stay finite, but from saved state 5 on its energy and
    # Casimir overflow. It alone is infinite per trajectory; the others keep the figures of all
    # their saved times (not of the series cut at step 5).
    body = system("RigidBody")
    strang = it.splitting.Strang(body, h=0.1)
    y0s = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4], [-0.2, 0.4, 0.9]])
    y = np.array(strang.rollout(y0s, 9))
    y[1, 5:, 0] = 1e160
    assert np.all(np.isfinite(y))
    figures = it.rollout_figures(strang, y, defect_points=0)
    assert figures.diverged_at_step == 5 and figures.divergence.trajectory == 1
    assert figures.energy_error_max == math.inf
    per_trajectory = figures.energy_error_max_per_trajectory
    assert per_trajectory[1] == math.inf
    np.testing.assert_array_equal(per_trajectory[[0, 2]], [it.diagnostics(y[i], body).max_energy_error for i in (0, 2)])
    assert np.all(np.isfinite(per_trajectory[[0, 2]]))


def test_step_timing_is_the_fastest_of_runs_long_enough(monkeypatch):
    # A fake clock that a rollout advances by 1 us per step and trajectory, and by 5 ms more on
    # every other run (load on a shared machine): the calibration and the minimum are then
    # exact, whatever the machine does (a test never passes or fails on real time).
    import integrators._timing as timing_module

    body = system("RigidBody")
    strang = it.splitting.Strang(body, h=0.1)
    clock = {"now": 0.0, "runs": 0}
    rollout = type(strang).rollout

    def timed_rollout(self, y0s, n_steps, **kwargs):
        clock["runs"] += 1
        clock["now"] += 1e-6 * n_steps * np.asarray(y0s).reshape(-1, 3).shape[0] + (5e-3 if clock["runs"] % 2 == 0 else 0.0)
        return rollout(self, y0s, n_steps, **kwargs)

    monkeypatch.setattr(type(strang), "rollout", timed_rollout)
    monkeypatch.setattr(timing_module.time, "perf_counter", lambda: clock["now"])
    timing = it.step_timing(strang, Y0S, min_seconds=0.01, repeats=3, outputs=4)
    assert len(timing.run_seconds) == 3 and timing.n_trajectories == 2 and timing.n_steps % 4 == 0
    assert min(timing.run_seconds) >= 0.01  # every timed run at least min_seconds long
    assert max(timing.run_seconds) == pytest.approx(min(timing.run_seconds) + 5e-3, rel=1e-9)  # loaded runs...
    assert timing.seconds_per_step == pytest.approx(1e-6, rel=1e-9)  # ...are not the ones that count
    assert timing.seconds_per_step == min(timing.run_seconds) / (timing.n_steps * 2)
    with pytest.raises(ValueError, match="min_seconds"):
        it.step_timing(strang, Y0S, min_seconds=0.0)
    with pytest.raises(ValueError, match="repeats must be an integer >= 1"):
        it.step_timing(strang, Y0S, repeats=0)
    with pytest.raises(TypeError, match="step_map must be an integrators.AbstractStepMap"):
        it.step_timing("Strang", Y0S)


def test_compare_arguments():
    body = system("RigidBody")
    strang = it.splitting.Strang(body, h=0.1)
    with pytest.raises(ValueError, match="must divide the output interval"):
        it.compare([it.splitting.Strang(body, h=0.3)], body, Y0S, t_final=10.0, n_outputs=20)
    with pytest.raises(TypeError, match="AbstractStepMap"):
        it.compare({"x": "Strang"}, body, Y0S, t_final=10.0)
    with pytest.raises(ValueError, match="not of the system compared"):
        it.compare([it.splitting.Strang(system("Kirchhoff"), h=0.1)], body, Y0S, t_final=10.0)
    with pytest.raises(ValueError, match="no step size h"):
        it.compare([learn.GLPNet(body)], body, Y0S, t_final=10.0)
    with pytest.raises(ValueError, match="t_final"):
        it.compare([strang], body, Y0S, t_final=-1.0)
    with pytest.raises(ValueError, match="y0s"):
        it.compare([strang], body, Y0S[:, :2], t_final=10.0)
    with pytest.raises(ValueError, match="at least one"):
        it.compare({}, body, Y0S, t_final=10.0)


@pytest.mark.parametrize("make, order", [
    (lambda body, h: it.splitting.Strang(body, h=h), 2),
    pytest.param(lambda body, h: it.RK4(body, h=h), 4, marks=pytest.mark.slow),  # RK4's order: test_runge_kutta.py
])
def test_convergence_observes_the_order(make, order, tmp_path):
    body = system("RigidBody")
    c = it.convergence(lambda h: make(body, h), body, Y0S, t_final=10.0, hs=[0.2, 0.1, 0.05, 0.025])
    # The log-log slope over h = 0.2 .. 0.025 (measured 2.002 and 3.994).
    assert abs(c.order - order) < 0.05
    # Each halving of h divides the error by about 2^order.
    assert np.all(np.abs(np.log2(c.errors[:-1] / c.errors[1:]) - order) < 0.2)
    it.plot_convergence(c, tmp_path / "convergence.png", label="method")
    assert (tmp_path / "convergence.png").stat().st_size > 0


def test_convergence_arguments():
    body = system("RigidBody")
    with pytest.raises(ValueError, match="must divide t_final"):
        it.convergence(lambda h: it.RK4(body, h=h), body, Y0S, t_final=1.0, hs=[0.3, 0.1])
    with pytest.raises(ValueError, match="at least 2"):
        it.convergence(lambda h: it.RK4(body, h=h), body, Y0S, t_final=1.0, hs=[0.1])
    with pytest.raises(ValueError, match="hs\\[1\\]"):
        it.convergence(lambda h: it.RK4(body, h=h), body, Y0S, t_final=1.0, hs=[0.1, -0.1])
    with pytest.raises(TypeError, match="must return an integrators.AbstractStepMap"):
        it.convergence(lambda h: "RK4", body, Y0S, t_final=1.0, hs=[0.1, 0.05])


def test_plot_styles_are_distinct_and_log_axes_span_a_decade():
    pytest.importorskip("matplotlib")
    from integrators._plots import figure, series_styles, span_decades

    styles = series_styles(40)  # W1 plots ~17 maps, a user comparison may plot more
    assert len({(s["color"], s["marker"], s["ls"]) for s in styles}) == 40
    ax = figure().subplots()
    ax.loglog([2e-6, 5e-6], [1.0, 2.0], "o")  # less than half a decade: minor labels would overlap
    span_decades(ax, "x")
    lo, hi = ax.get_xlim()
    assert np.log10(hi / lo) >= 1.2 - 1e-12 and lo < 2e-6 and hi > 5e-6
    assert any(lo <= 10.0**k <= hi for k in range(-8, 0))  # a labelled power of ten in view
