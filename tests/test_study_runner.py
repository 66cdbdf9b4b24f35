"""What a newcomer adds is one class each: a row of a study (`paper._study.AbstractStudyModel`),
a loss (`learn.AbstractPairsLoss`), a solver wrapper (`learn.AbstractWrappedStage`) and a family
of learned Hamiltonians (`learn.Family`), all four defined here and run end to end through W2's
study runner on a tiny case; and the one `Profile` type every experiment's budgets share."""

import dataclasses
import json
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import learn
from paper._experiment import Profile, fmt, profiles
from paper._study import AbstractHamiltonianModel, AbstractStepMapModel, Fitted, Identified


class UnitStartFamily(learn.Family):
    """The quadratic family on the basis axes, started from the unit form $|y|^2/2$ instead of
    the least-squares estimate of the observations."""

    def start(self, system, data, size):
        return self.terms_of(system, np.eye(system.dim), np.zeros(system.dim), size)


class RelativeStateLoss(learn.AbstractPairsLoss):
    r"""The state loss of one step relative to the size of its target: $(\Phi(y_0) - y_1)/|y_1|$."""

    def pair_residuals(self, model, y0, targets):
        return (jax.vmap(model.step)(y0) - targets) / jnp.linalg.norm(targets, axis=-1, keepdims=True)


@dataclasses.dataclass(frozen=True)
class Twice(learn.AbstractWrappedStage):
    """`stage` run twice, the second run from the first's result."""

    stage: learn.AbstractStage

    @property
    def budget(self):
        return 2 * self.stage.budget

    def with_budget(self, budget):
        return Twice(self.stage.with_budget(max(1, budget // 2)))

    def run(self, problem, context):
        first = self.stage.run(problem, context)
        second = self.stage.run(problem.with_start(first.y), context.shifted(first.record.iterations))
        shift = first.history["epoch"][-1] if first.history["epoch"].size else 0
        history = {key: np.concatenate([first.history[key], second.history[key] + (shift if key == "epoch" else 0)])
                   for key in ("epoch", "train_loss", "val_loss")}
        record = dataclasses.replace(second.record, iterations=first.record.iterations + second.record.iterations,
                                     details={**second.record.details, "runs": 2})
        return learn.Result(second.y, record, history, second.linearisation)


FAMILY = UnitStartFamily("quadratic, from the unit form", "identity", linear_term=False, bias=False)


@dataclasses.dataclass(frozen=True)
class RefinedGLPNet(AbstractStepMapModel, AbstractHamiltonianModel):
    """A row of W2: a G-LPNet of `FAMILY` (`learn.fit_splitting`), then refined on consecutive
    observations by `RelativeStateLoss` with `Twice(LevenbergMarquardt)`."""

    label: str = "G-LPNet, unit start, refined"

    def fit(self, system, data, *, progress=False):
        net, records = learn.fit_splitting(system, data, families=[FAMILY], iterations=3, progress=False)
        y0, y1, dt = data.pairs()
        net, record = learn.fit(net, (y0, y1), h=float(dt[0]), loss=RelativeStateLoss(), validation_fraction=0.0,
                                optimiser=Twice(learn.LevenbergMarquardt(2)), progress=False)
        return Fitted(net, (*records, record))

    def identify(self, fitted, system, states, diagonal):
        choice = fitted.records[0].choice
        return Identified(family=choice.chosen, bic={s.family: s.bic for s in choice.scores})


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_a_new_row_loss_wrapper_and_family_run_through_the_study_runner(tmp_path, monkeypatch):
    from paper import w2_observations as w2

    # exact observations: the refinement on pairs needs pairs a Poisson map joins (equal Casimirs)
    tiny = w2.PROFILES["smoke"].replace(noises=(0.0,), n_trajectories=4, n_observations=6, test_steps=20)
    monkeypatch.setitem(w2.PROFILES, "smoke", tiny)
    monkeypatch.setattr(w2, "models", lambda protocol, profile: [RefinedGLPNet()])  # the study's row list
    fits = []  # what the row's fit returned, kept to look into its records
    fit = RefinedGLPNet.fit
    monkeypatch.setattr(RefinedGLPNet, "fit", lambda self, *args, **kw: fits.append(fit(self, *args, **kw)) or fits[-1])
    metrics = w2.EXPERIMENT.execute(profile="smoke", progress=False, out_dir=tmp_path)
    (row,) = metrics["rows"]
    assert row["model"] == "G-LPNet, unit start, refined" and row["family"] == FAMILY.name
    # the family was offered (fit_splitting fitted it and scored it) and chosen, alone
    assert list(row["bic"]) == [FAMILY.name]
    # the row in the study's table, with the figure the model produced and its family
    table = (tmp_path / "table.md").read_text()
    line = next(li for li in table.splitlines() if "| G-LPNet, unit start, refined |" in li)
    assert f"| {fmt(row['state_error'])} |" in line and f"| {FAMILY.name} |" in line
    # saved as it was measured, under the runner's name for it: a rerun reads it, fits nothing
    saved = tmp_path / "rows" / "smoke-rigid_body-regular-0-G-LPNet,_unit_start,_refined.json"
    assert json.loads(saved.read_text())["state_error"] == row["state_error"]
    monkeypatch.setattr(w2, "models", lambda protocol, profile: [_Unfittable()])
    assert w2.EXPERIMENT.execute(profile="smoke", progress=False, out_dir=tmp_path)["rows"] == []  # not admitted
    monkeypatch.setattr(w2, "models", lambda protocol, profile: [RefinedGLPNet()])
    again = w2.EXPERIMENT.execute(profile="smoke", progress=False, out_dir=tmp_path)
    assert again["rows"] == metrics["rows"] and again["resumed_rows"] == 1

    # the loss and the wrapper, seen in the record of the refinement: the loss by its name, the
    # wrapper's two runs of 2 Levenberg-Marquardt steps each (a step that does not lower the loss
    # still counts); the row's training loss is the refinement's
    (fitted,) = fits
    refinement = fitted.records[-1]
    assert refinement.loss == "RelativeStateLoss"
    (stage,) = refinement.stages
    assert stage.details["runs"] == 2 and stage.iterations == 4
    assert fitted.records[0].choice.chosen == FAMILY.name
    assert refinement.train_loss == row["train_loss"]


class _Unfittable(RefinedGLPNet):
    """A row the study does not admit: it refuses the data (the runner skips it, as W2 skips
    the MLP on uneven sampling)."""

    def accepts(self, data):
        return False


def test_one_profile_type_for_every_experiment():
    from paper._registry import EXPERIMENTS
    from paper.w4_bodies import PROFILES as W4

    P = Profile(epochs=3, seeds=(1, 2))
    assert P.epochs == 3 and P.replace(epochs=4).epochs == 4 and P.epochs == 3
    assert pickle.loads(pickle.dumps(P)) == P  # to worker processes (`--scheduler processes`)
    with pytest.raises(dataclasses.FrozenInstanceError):
        P.epochs = 4
    with pytest.raises(ValueError, match="epoch"):
        P.replace(epoch=4)  # a misspelt setting
    with pytest.raises(AttributeError, match="no setting 'epoch'"):
        _ = P.epoch
    with pytest.raises(ValueError, match="'full' profile lacks \\['seeds'\\]"):
        profiles(smoke=Profile(epochs=1, seeds=1), full=Profile(epochs=2))
    made = profiles(Profile(seeds=1), smoke=Profile(epochs=1), full=Profile(epochs=2, seeds=3))
    assert (made["smoke"].seeds, made["full"].seeds) == (1, 3)
    # every experiment's and study's budgets are Profiles with the same settings in each profile
    for exp_id, exp in EXPERIMENTS.items():
        module = __import__(type(exp).__module__, fromlist=["PROFILES"])
        budgets = module.PROFILES
        assert set(budgets) == {"smoke", "quick", "full"}, exp_id
        assert all(type(P) is Profile for P in budgets.values()), exp_id
        assert len({frozenset(P.as_dict()) for P in budgets.values()}) == 1, exp_id
    assert W4["full"].then.part == "LLPNN protocol"  # a study's second part: a Profile too


@dataclasses.dataclass(frozen=True)
class _TinyRow:
    condition: int
    value: float


def _tiny_study(evaluated: list, grid=(1, 2), scale=2.0):
    """A study of one model on the conditions `grid` whose row is `condition * scale`, saved
    per condition; each evaluation appended to `evaluated`."""
    from paper._runner import AbstractStudy

    class Tiny(AbstractStudy):
        id = "T"
        title = "tiny"
        profiles = profiles(smoke=Profile(conditions=grid, scale=scale))
        row_type = _TinyRow

        def conditions(self, P):
            return P.conditions

        def models(self, P, condition):
            return ["one"]

        def evaluate(self, condition, model, progress):
            evaluated.append(condition)
            return _TinyRow(condition, condition * self.profiles["smoke"].scale)

        def row_name(self, profile, condition, model):
            return f"{profile}-{condition}.json"

        def description(self, metrics):
            return ""

    return Tiny()


def test_a_rerun_with_other_settings_is_refused_not_mixed_with_the_saved_rows(tmp_path, capsys):
    from paper.__main__ import main

    evaluated = []
    study = _tiny_study(evaluated)
    assert study.execute("smoke", progress=False, out_dir=tmp_path)["rows"][1]["value"] == 4.0
    assert study.execute("smoke", progress=False, out_dir=tmp_path)["resumed_rows"] == 2 and evaluated == [1, 2]
    # the same profile with another setting: the saved rows (of scale 2) are not read back as its
    study.profiles = profiles(smoke=Profile(conditions=(1, 2), scale=3.0))
    with pytest.raises(ValueError, match=r"holds the smoke profile's rows of other settings \(scale: 2.0 then, "
                                         r"3.0 now\): run into another folder \(--out\), or delete"):
        study.execute("smoke", progress=False, out_dir=tmp_path)
    assert evaluated == [1, 2]
    # the command line says so in one line before running anything (W8's folder, its settings changed)
    (tmp_path / "W8").mkdir()
    (tmp_path / "W8" / "smoke-settings.json").write_text(json.dumps({"sizes": [9]}))
    assert main(["run", "W8", "--profile", "smoke", "--no-progress", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds the smoke profile's rows of other settings" in err and "sizes: [9] then" in err
    (tmp_path / "W8" / "smoke-settings.json").write_text("{not json")
    assert main(["run", "W8", "--profile", "smoke", "--no-progress", "--out", str(tmp_path)]) == 2
    assert "not a settings file of this library" in capsys.readouterr().err


def _holder(row):
    """Another process that claims `row`, prints 'claimed', and saves it (condition 2, value
    99) and releases it once a line is written to its stdin."""
    import subprocess
    import sys

    return subprocess.Popen(
        [sys.executable, "-c", ("import json, sys; from pathlib import Path; from paper._claims import claim, "
                                "release; p = Path(sys.argv[1]); assert claim(p); print('claimed', flush=True); "
                                "sys.stdin.readline(); p.write_text(json.dumps({'condition': 2, 'value': 99.0})); "
                                "release(p)"), str(row)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def test_processes_running_one_study_into_one_folder_share_its_rows(tmp_path, monkeypatch, capsys):
    """A row another process has claimed is not computed again: it is read once that process
    saves it; a claim whose process died is no claim (the kernel drops its lock)."""
    import subprocess
    import sys
    import threading
    import time

    from paper import _runner
    from paper._claims import holder
    evaluated = []
    monkeypatch.setattr(_runner, "POLL_SECONDS", 0.02)
    row2 = tmp_path / "rows" / "smoke-2.json"
    with _holder(row2) as other:  # another process: claims row 2, saves it (value 99) when told to
        try:
            assert other.stdout.readline().strip() == "claimed"
            assert holder(row2).endswith(f" {other.pid}")

            def finish_when_the_others_are_done():
                deadline = time.monotonic() + 60
                while evaluated != [1, 3] and time.monotonic() < deadline:
                    time.sleep(0.01)
                other.stdin.write("\n")
                other.stdin.flush()

            threading.Thread(target=finish_when_the_others_are_done, daemon=True).start()
            metrics = _tiny_study(evaluated, (1, 2, 3)).execute("smoke", progress=True, out_dir=tmp_path)
        finally:
            other.kill()
    assert evaluated == [1, 3]  # row 2 was the other process's
    assert [r["value"] for r in metrics["rows"]] == [2.0, 99.0, 6.0]  # in the study's order, read when saved
    assert "smoke-2.json: computed by another process" in capsys.readouterr().out
    assert not list((tmp_path / "rows").glob("*.claim"))  # every claim released, its file deleted

    # a process that dies holding a claim, while this one waits for the row, leaves its file but not
    # its lock: the row is computed here
    row2.unlink()
    with subprocess.Popen([sys.executable, "-c", ("import sys, time; from pathlib import Path; "
                                                  "from paper._claims import claim; assert claim(Path(sys.argv[1])); "
                                                  "print('claimed', flush=True); time.sleep(600)"), str(row2)],
                          stdout=subprocess.PIPE, text=True) as dead:
        try:
            assert dead.stdout.readline().strip() == "claimed"
            del evaluated[:]

            def die_while_waited_for():
                deadline = time.monotonic() + 60
                while not (row2.with_name("smoke-3.json").exists() or time.monotonic() > deadline):
                    time.sleep(0.01)  # row 3 saved: this process is past row 2, waiting for it
                time.sleep(0.1)
                dead.kill()

            row2.with_name("smoke-3.json").unlink()
            threading.Thread(target=die_while_waited_for, daemon=True).start()
            again = _tiny_study(evaluated, (1, 2, 3)).execute("smoke", progress=False, out_dir=tmp_path)
        finally:
            dead.kill()
    assert not row2.with_name(row2.name + ".claim").exists() and holder(row2) is None
    assert evaluated == [3, 2] and [r["value"] for r in again["rows"]] == [2.0, 4.0, 6.0]
    assert again["resumed_rows"] == 1  # row 1, saved by the first run
    assert not list((tmp_path / "rows").glob("*.claim"))


def test_a_row_of_another_format_is_refitted_by_one_process_only(tmp_path, monkeypatch, capsys):
    """A saved row of an older format is refitted, but not while another process holds its
    claim: that process's row is read when saved (before, the file's existence skipped the claim
    and both refitted it)."""

    from paper import _runner

    monkeypatch.setattr(_runner, "POLL_SECONDS", 0.02)
    rows = tmp_path / "rows"
    rows.mkdir()
    for k in (1, 2):
        (rows / f"smoke-{k}.json").write_text(json.dumps({"old": k}))  # another version's rows
    row2 = rows / "smoke-2.json"
    with _holder(row2) as other:  # holds row 2's claim, saves its row (value 99) when told to
        try:
            assert other.stdout.readline().strip() == "claimed"
            evaluated = []
            study = _tiny_study(evaluated)
            first = study.condition_rows("smoke", 1, ["one"], tmp_path, progress=False)
            second = study.condition_rows("smoke", 2, ["one"], tmp_path, progress=False)
            assert evaluated == [1] and first[0].value == 2.0  # row 1 refitted here, row 2 left to the holder
            assert isinstance(second[0], _runner._Elsewhere)
            other.stdin.write("\n")
            other.stdin.flush()
            assert study._awaited(second[0], progress=False).value == 99.0 and evaluated == [1]
        finally:
            other.kill()
    err = capsys.readouterr().err
    assert err.count("refitting") == 1 and "smoke-1.json" in err  # the one refit says so, not each look
