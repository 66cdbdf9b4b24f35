"""W8, fluids from data (`paper/w8_fluids.py`): its pieces (the limit's fixed Laplacian, the
truths' spectra, the Casimir drift, the profiles), and the whole study at the smoke profile
(slow)."""

import dataclasses
import json
import math
import re
import types

import equinox as eqx
import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import learn
from liepoisson.systems import Zeitlin
from paper import w8_fluids as w8
from paper.__main__ import main
from paper._registry import EXPERIMENTS


def test_w8_is_registered_with_a_profile_of_each_name():
    assert EXPERIMENTS["W8"] is w8.EXPERIMENT
    assert set(w8.PROFILES) == {"smoke", "quick", "full"}
    # the grid at N = 32, one condition of each noise at N = 64 (a learned fit there outlasts a
    # session) and N = 128 on the time budget (a fast check)
    full = w8.PROFILES["full"]
    conditions = list(w8.EXPERIMENT.conditions(full))
    keys = [c.key for c in conditions]
    assert len(keys) == len(set(keys)) == 8 + 2 + 1
    assert {c.N for c in conditions} == {32, 64, 128}
    assert {c.noise for c in conditions if c.N == 64} == {1e-3, 1e-2}
    assert [c.N for c in conditions if c.fast] == [128]
    for P in w8.PROFILES.values():
        assert set(P.truths) <= set(w8.TRUTHS)
        assert {name for _, name, _ in P.spot_checks + P.fast_checks} <= set(w8.TRUTHS)
        assert set(P.fast_settings) <= set(P.as_dict())  # names the profile has (Profile.replace)


def test_a_fast_check_takes_its_settings_and_two_midpoints_an_interval_at_n_128():
    P = w8.PROFILES["full"]
    fast = w8.Condition(128, w8.TRUTHS["Euler"], 1e-3, P, fast=True)
    assert fast.key == "N128-Euler-0.001-fast" and w8.Condition(128, w8.TRUTHS["Euler"], 1e-3, P).key != fast.key
    assert fast.P.standard_errors is False and fast.P.n_train == 2 and fast.P.composition is None
    assert P.standard_errors is True and P.n_train == 4  # the profile itself unchanged
    # the longest interval (1.5 mean intervals) is two steps at N = 128
    assert fast.P.interval < P.interval
    assert math.ceil(1.5 * fast.P.interval * fast.tau / fast.max_step - 1e-12) == 2
    assert all(m.iterations == w8.FAST["lm_iterations"] for m in w8.EXPERIMENT.models(P, fast)
               if isinstance(m, (w8.LearnedStreamModel, w8.LimitModel)))
    # a fast check that is also a grid condition would be judged with it: refused, named
    clash = P.replace(fast_checks=((32, "Euler", 1e-3),))
    with pytest.raises(ValueError, match=r"fast checks \[\(32, 'Euler', 0.001\)\]"):
        list(w8.EXPERIMENT.conditions(clash))


def _row(N, model, error, *, z=None, seconds=1.0, memory=None):
    return w8.W8Row(N=N, truth="Euler", noise=1e-3, model=model, error_1=error, error_5=2 * error,
                    energy_error=0.0, enstrophy_error=0.0, z=z, casimir_drift=1e-15, fit_seconds=seconds,
                    parameters=None, note=None, peak_memory_gb=memory)


def test_the_verdict_judges_a_fast_check_on_its_budget_and_the_others_on_standard_errors():
    rows = [_row(32, w8.LEARNED, 0.0012, z=3.5), _row(32, w8.LIMIT, 0.001, z=1.0),
            _row(128, w8.LEARNED, 0.02, seconds=700.0, memory=3.9), _row(128, w8.LIMIT, 0.01, seconds=90.0)]
    grid, fast = w8.verdict(rows, frozenset({(128, "Euler", 1e-3)}))
    assert "1.2x at most: within 1.5x" in grid and "3.5 standard errors at most (NOT within 3)" in grid
    assert "2x at most: NOT within 1.5x" in fast and "700 s (NOT under 600 s)" in fast
    assert "3.9 GB (under 8 GB)" in fast and "standard errors at most" not in fast
    rows[2] = _row(128, w8.LEARNED, 0.01, seconds=500.0, memory=9.0)
    fast = w8.verdict(rows, frozenset({(128, "Euler", 1e-3)}))[1]
    assert "500 s (under 600 s)" in fast and "9 GB (NOT under 8 GB)" in fast


def _fit_like(values, se, bias, rotation=None, rotation_se=None, rotation_bias=None):
    """What `_unbiased_words` reads of a `learn.StreamOperatorFit`."""
    return types.SimpleNamespace(values=np.asarray(values, float), standard_errors=np.asarray(se, float),
                                 step_bias=np.asarray(bias, float), rotation=rotation,
                                 rotation_standard_error=rotation_se, rotation_step_bias=rotation_bias)


def test_the_error_less_the_steps_bias_is_in_standard_errors_and_names_its_worst_parameter():
    true = np.array([-2.0, -6.0, -12.0, -20.0])  # degrees 1..3 and the gauge's 4 (held: left out)
    se = np.array([0.1, 0.2, 0.1, 0.0])
    # errors 0.25, -0.5, 0.2 (2.5, 2.5, 2 SE); biases 0.05, -0.1, -0.1: less them 2.0, 2.0, 3.0 SE
    fit = _fit_like(true + [0.25, -0.5, 0.2, 0.0], se, [0.05, -0.1, -0.1, 0.0])
    assert w8._unbiased_words(fit, true, None) == "; less the step's bias, |error|/SE 3 at most (degree 3)"
    # the rotation after the degrees: 1.004 with bias 0.001, SE 0.001, the truth 1: 3 SE
    fit = _fit_like(true, se, np.zeros(4), rotation=1.004, rotation_se=0.001, rotation_bias=0.001)
    assert w8._unbiased_words(fit, true, 1.0) == "; less the step's bias, |error|/SE 3 at most (the rotation)"
    assert w8._unbiased_words(_fit_like(true, se, np.full(4, np.nan)), true, None) == ""  # no bias known


def _spectrum_row(N, spectrum, z=None):
    return dataclasses.replace(_row(N, w8.LEARNED, 0.001, z=z), spectrum=spectrum)


def test_a_row_keeps_its_spectrum_through_json_and_the_figure_draws_it(tmp_path):
    from paper._experiment import row_from_json, row_to_json

    kept = {"values": [-2.1, -6.0, -12.0], "true": [-2.0, -6.2, -12.0], "standard_errors": [0.1, 0.1, 0.0],
            "step_bias": [0.01, float("nan"), 0.0]}
    row = _spectrum_row(4, kept, z=2.0)
    saved = row_to_json(row)
    assert saved["spectrum"]["step_bias"][1] is None  # NaN is saved as null
    back = row_from_json(w8.W8Row, json.loads(json.dumps(saved)))
    assert back.spectrum["values"] == kept["values"] and back.spectrum["step_bias"][1] is None
    old = {k: v for k, v in saved.items() if k != "spectrum"}  # a row saved before spectra were kept
    assert "spectrum" not in row_to_json(_row(4, w8.LIMIT, 0.001))  # only the rows that have one
    assert row_from_json(w8.W8Row, old).spectrum is None
    fast = _spectrum_row(8, {"values": [-2.1, -6.0, -12.0], "true": [-2.0, -6.2, -12.0]})
    assert w8.spectrum_figure([back, fast, _row(4, w8.LIMIT, 0.001)], tmp_path) == ["spectrum.png"]
    assert (tmp_path / "spectrum.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert w8.spectrum_figure([_row(4, w8.LIMIT, 0.001)], tmp_path / "none") == []  # no spectrum: no figure
    assert not (tmp_path / "none").exists()


def test_steps_are_shorter_on_a_sphere_turning_faster_than_the_eddies():
    # fit_step times the shortest time scale: tau, or 1/(2 Omega) (the planetary vorticity's
    # largest value 2 Omega); Euler's and QG's steps are fit_step eddy turnovers
    P = w8.PROFILES["full"]
    euler = w8.Condition(8, w8.TRUTHS["Euler"], 1e-3, P)
    assert euler.max_step == P.fit_step * euler.tau
    assert w8.Condition(8, w8.TRUTHS["QG F = 100"], 1e-3, P).max_step == euler.max_step
    for rotation, scale in ((1.0, 0.5), (4.0, 0.125), (-4.0, 0.125), (0.1, euler.tau), (0.0, euler.tau)):
        turning = w8.Condition(8, w8.Truth("turning", rotation=rotation), 1e-3, P)
        assert turning.max_step == pytest.approx(P.fit_step * min(scale, euler.tau), rel=1e-15)
    # above N = 32 the step shortens with the finest degree N - 1 (Courant's number l h)
    for N, shorter in ((32, 1.0), (64, 31 / 63), (128, 31 / 127)):
        condition = w8.Condition(N, w8.TRUTHS["Euler"], 1e-3, P)
        assert condition.max_step == pytest.approx(P.fit_step * condition.tau * shorter, rel=1e-15)


@pytest.mark.slow  # rollouts at N = 64, compiled
def test_the_step_at_n_64_errs_no_more_than_the_step_at_n_32():
    # The step error of W8's Euler truth over one interval of 0.15 tau (W8's longest), at each
    # size's Condition.max_step, against 16 substeps (order 6: their own error far below it);
    # at N = 32's step N = 64 errs ten times more (BENCHMARKS.md, "The step's order", --courant).
    P = w8.PROFILES["full"]
    errors = {}
    for N in (32, 64):
        condition = w8.Condition(N, w8.TRUTHS["Euler"], 1e-3, P)
        tau = condition.tau
        y0 = jnp.asarray(condition._fields(w8.TRAIN_SEED, 1)[0])
        model = learn.StreamOperator(condition.system, composition=P.composition, tol=1e-13, iterations=16)
        interval = jnp.full(1, 0.15 * tau)
        n = math.ceil(0.15 * tau / condition.max_step - 1e-12)
        y = np.asarray(model.rollout_intervals(y0, interval, n))[-1]
        reference = np.asarray(model.rollout_intervals(y0, interval, 16))[-1]
        errors[N] = np.linalg.norm(y - reference) / np.linalg.norm(reference)
    assert np.isfinite(errors[64]) and errors[64] <= errors[32]


def test_the_limits_laplacian_is_the_quasi_geostrophic_family_at_zero_and_learns_nothing():
    N = 6
    fixed = w8.LaplacianSpectrum()
    np.testing.assert_array_equal(np.asarray(fixed.eigenvalues(N))[1:],
                                  np.asarray(learn.QuasiGeostrophicSpectrum(0.0).eigenvalues(N))[1:])
    model = learn.StreamOperator(Zeitlin(N), fixed, rotation=0.5)
    params = eqx.filter(model, eqx.is_inexact_array)
    assert [float(x) for x in jax.tree_util.tree_leaves(params)] == [0.5]  # the rotation is its one parameter
    assert w8.TRUTHS["QG F = 10"].degree_values(4).tolist() == [-12.0, -16.0, -22.0]


def test_casimir_drift_is_round_off_for_a_unitary_conjugation_and_sees_the_absolute_vorticity():
    N = 6
    system = Zeitlin(N)
    W = np.asarray(system.algebra.matrix(system.random_state(0)))
    rng = np.random.default_rng(0)
    U, _ = np.linalg.qr(rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N)))
    f = learn.planetary_vorticity(N)
    q1 = U @ (W + f) @ U.conj().T  # the absolute vorticity conjugated: W1 = q1 - f
    ys = np.stack([system.algebra.coordinates(jnp.asarray(m)) for m in (W, q1 - f)])[None]
    assert w8.casimir_drift(system, ys, rotation=1.0) <= 1e-14
    assert w8.casimir_drift(system, ys) > 1e-3  # the relative vorticity's are not kept
    assert w8.casimir_drift(system, np.full_like(ys, np.nan)) == np.inf


@pytest.mark.slow  # compiles four fits' standard errors at N = 8: ~6 min on 2 loaded cores
def test_w8_smoke_runs_resumes_and_says_its_verdict(tmp_path):
    args = ["run", "W8", "--profile", "smoke", "--no-progress", "--out", str(tmp_path)]
    assert main(args) == 0
    metrics = json.loads((tmp_path / "W8" / "metrics.json").read_text())
    rows = metrics["rows"]
    truths = w8.PROFILES["smoke"].truths
    learned = [r for r in rows if r["model"] == w8.LEARNED]
    assert [r["truth"] for r in learned] == list(truths)
    assert len(metrics["verdict"]) == len(truths)
    for r in learned + [r for r in rows if r["model"] == w8.LIMIT]:
        assert r["casimir_drift"] <= 1e-13  # unitary conjugations of q, whatever was fitted
        assert r["error_1"] <= 0.05 and r["z"] is not None  # from a start with 1% noise
    for r in learned:  # the truth's Wald test, every parameter at once: N - 2 degrees (and the rotation)
        dof = int(re.search(r"Wald d\^2 [0-9.]+ on (\d+) parameters, p = ", r["parameters"]).group(1))
        assert dof == 6 + (r["truth"] == "rotating")
        # the spectrum kept per degree gives the row's largest |error|/SE (the rotation's aside)
        sp = {k: np.asarray(v, dtype=float) for k, v in r["spectrum"].items()}
        assert all(len(v) == 7 for v in sp.values())  # degrees 1..N-1
        z = np.max(np.abs(sp["values"] - sp["true"])[:-1] / sp["standard_errors"][:-1])
        if r["truth"] == "rotating":
            assert z <= r["z"] * (1 + 1e-12)
        else:
            assert z == pytest.approx(r["z"], rel=1e-12)  # the same floats, the same operations
        assert "less the step's bias, |error|/SE" in r["parameters"]
    assert metrics["figures"] == ["spectrum.png"] and (tmp_path / "W8" / "spectrum.png").exists()
    assert all("spectrum" not in r for r in rows if r["model"] != w8.LEARNED)
    assert len(list((tmp_path / "W8" / "snapshots").rglob("*.h5"))) == len(truths) * w8.PROFILES["smoke"].n_train
    # the stream operators' fits (learned and limit; smoke's prefix is every snapshot: one stage),
    # each resumable from its checkpoint
    assert len(list((tmp_path / "W8" / "checkpoints").rglob("*.h5"))) == len(truths) * 2
    table = (tmp_path / "W8" / "table.md").read_text()
    assert table.startswith("# W8") and "limit (the true family)" in table
    assert main(args) == 0  # every row resumed: nothing refitted
    again = json.loads((tmp_path / "W8" / "metrics.json").read_text())
    assert again["resumed_rows"] == len(rows) and again["rows"] == rows
    # a row lost (a process killed after its fit, before the row was saved): its fit is read back
    # from the checkpoint, not redone, and its figures are the same to the bit
    lost = next((tmp_path / "W8" / "rows").glob("smoke-*-learned_stream_operator.json"))
    before = json.loads(lost.read_text())
    lost.unlink()
    assert main(args) == 0
    after = json.loads(lost.read_text())
    assert after["fit_seconds"] > before["fit_seconds"]  # the fit's time over both processes
    # the process's figures (its time, its peak memory) are not the fit's: every other is the same
    own = ("fit_seconds", "peak_memory_gb")
    assert {k: v for k, v in after.items() if k not in own} == {k: v for k, v in before.items() if k not in own}
    assert after["peak_memory_gb"] > 0 and before["peak_memory_gb"] > 0


@pytest.mark.slow  # two fits at N = 8, compiled
def test_a_fast_check_fits_without_standard_errors_and_keeps_the_casimirs(tmp_path):
    P = w8.PROFILES["smoke"].replace(fast_settings={**w8.FAST, "n_test": 1})
    condition = w8.Condition(8, w8.TRUTHS["QG F = 10"], 1e-3, P, fast=True)
    condition.folder = tmp_path / "snapshots"
    learned = w8.measure(condition, w8.LearnedStreamModel(w8.FAST["lm_iterations"]), progress=False)
    limit = w8.measure(condition, w8.LimitModel(w8.FAST["lm_iterations"]), progress=False)
    assert len(list(condition.folder.glob("*.h5"))) == w8.FAST["n_train"]
    for row in (learned, limit):
        assert row.z is None and row.parameters.startswith("no standard errors")
        assert row.casimir_drift <= 1e-13  # unitary conjugations, whatever was fitted
        assert row.peak_memory_gb is not None and 0 < row.peak_memory_gb < 64
    # six snapshots over 0.1 tau, a midpoint an interval: both forecast to a few times the noise
    # (1e-3 of the field; measured 3.4e-3 and 1.7e-3 at tau)
    assert learned.error_1 < 1e-2 and limit.error_1 < 1e-2
    F = float(re.search(r"F = ([0-9.e+-]+)", limit.parameters).group(1))
    assert abs(F - 10.0) < 0.5  # the limit's F from 0 (measured 9.81 after its 10 iterations)
    largest = float(re.search(r"largest relative error ([0-9.e+-]+) at degree \d", learned.parameters).group(1))
    assert largest < 0.1  # measured 0.033
    sp = {k: np.asarray(v) for k, v in learned.spectrum.items()}  # no standard errors: values and truth
    assert set(sp) == {"values", "true"} and limit.spectrum is None
    assert float(f"{np.max(np.abs(sp['values'] - sp['true'])[:-1] / np.abs(sp['true'][:-1])):.2g}") == largest


@pytest.mark.slow  # two fits with standard errors at N = 8, compiled
def test_a_step_whose_bias_is_over_the_profiles_limit_is_halved_until_it_is_not(tmp_path):
    P = w8.PROFILES["smoke"].replace(max_step_bias=0.05)
    condition = w8.Condition(8, w8.TRUTHS["rotating"], 1e-2, P)
    condition.folder, condition.checkpoints = tmp_path / "snapshots", tmp_path / "checkpoints"
    model = learn.StreamOperator(condition.system, learn.DegreeSpectrum(w8.TRUTHS["rotating"].degree_values(8),
                                                                        reference_degree=7),
                                 rotation=1.0, composition=P.composition, tol=w8.MODEL_TOL, iterations=6)
    fit, predict, _ = w8._fit(model, condition, condition.data, P.lm_iterations, False, "learned")
    longest = float(np.max(np.diff(condition.clock)))
    first = math.ceil(longest / condition.max_step - 1e-12)
    # at the profile's step the bias was 0.17 SE (measured); one midpoint a step, order 2: half
    # the step takes it to a quarter, 0.04, under the limit: one halving, its own checkpoint
    assert fit.substeps == 2 * first
    assert w8.worst_step_bias(fit) <= 0.05
    assert sorted(p.name for p in condition.checkpoints.iterdir()) == ["learned-half1.h5", "learned.h5"]
    # the refit's standard errors started from the first fit's solves (se_start, in its settings)
    from learn._training import _stream_checkpoint

    with h5py.File(condition.checkpoints / "learned-half1.h5") as f:
        settings = json.loads(f.attrs["settings"])
    solves = _stream_checkpoint.read_solves(condition.checkpoints / "learned.h5")
    assert settings["se_start"] == _stream_checkpoint.fingerprint(*solves)
    ys = predict(np.asarray(condition.data.states[0][:1]), 0.1, 2)  # forecasts in the halved steps
    assert np.all(np.isfinite(ys))
    # the profile without the limit: the first fit only, read back from its checkpoint
    plain = w8.Condition(8, w8.TRUTHS["rotating"], 1e-2, P.replace(max_step_bias=None))
    plain.folder, plain.checkpoints = condition.folder, condition.checkpoints
    unhalved = w8._fit(model, plain, plain.data, P.lm_iterations, False, "learned")[0]
    assert unhalved.substeps == first and w8.worst_step_bias(unhalved) > 0.05
