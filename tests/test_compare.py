"""integrators.compare: learned and classical step maps measured side by side against heyoka."""

import numpy as np
import pytest
from helpers import system

import integrators as it
import learn

EPS = np.finfo(np.float64).eps
Y0S = np.array([[1 / np.sqrt(2), -1 / np.sqrt(2), 1.0], [0.5, 1.0, -0.2]])


def test_compare_measures_every_map_against_the_same_reference(tmp_path):
    body = system("RigidBody")
    maps = {
        "Strang h": it.splitting.Strang(body, h=0.1),
        "Strang h/2": it.splitting.Strang(body, h=0.05),
        "RK4": it.RK4(body, h=0.1),
        "G-LPNet": learn.GLPNet(body, n_modules=3, h=0.1),
    }
    c = it.compare(maps, body, Y0S, t_final=10.0, n_outputs=20)
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
    c.plot_work_precision(tmp_path / "wp.png")
    c.plot_energy(tmp_path / "energy.png")
    assert (tmp_path / "wp.png").stat().st_size > 0 and (tmp_path / "energy.png").stat().st_size > 0


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
    (lambda body, h: it.RK4(body, h=h), 4),
])
def test_convergence_observes_the_order(make, order, tmp_path):
    body = system("RigidBody")
    c = it.convergence(lambda h: make(body, h), body, Y0S, t_final=10.0, hs=[0.2, 0.1, 0.05, 0.025])
    # The log-log slope over h = 0.2 .. 0.025 (measured 2.002 and 3.994).
    assert abs(c.order - order) < 0.05
    # Each halving of h divides the error by about 2^order.
    assert np.all(np.abs(np.log2(c.errors[:-1] / c.errors[1:]) - order) < 0.2)
    c.plot(tmp_path / "convergence.png", label="method")
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
