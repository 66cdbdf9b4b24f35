"""Reliability: bad input across the public API gets a clear error naming the argument (no raw
traceback from numpy/JAX/heyoka/h5py, no NaN, no silent answer); killed work leaves nothing
behind, and training resumed after kill -9 is bit-identical.

Classes of cases (issue 11): [load] loading what is not a valid file of the expected kind;
[save] saving into missing folders or onto folders; [kill] interrupted writes; [args]
arguments validated before work starts; [silent] silent wrong answers turned into errors;
[index] messages naming the user's argument and index; [table] the paper's table on a
malformed metrics file; [progress] progress bars on terminals only.
"""

from __future__ import annotations

import glob
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp

ROOT = Path(__file__).resolve().parents[1]
BODY = lp.systems.RigidBody()
Y0 = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4]])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """One file of each kind, and broken ones."""
    d = tmp_path_factory.mktemp("files")
    data = it.ground_truth(BODY, Y0, h=0.1, n_steps=4, seed=0)
    data.save(d / "data.h5")
    model, record = learn.fit(learn.GLPNet(BODY, key=0), data, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(3)),
                              validation_fraction=0.0, progress=False)
    model.save(d / "glpnet.h5")
    record.save(d / "record.h5")
    (d / "text.h5").write_text("not an HDF5 file\n")
    raw = (d / "data.h5").read_bytes()
    (d / "truncated.h5").write_bytes(raw[: len(raw) // 2])
    (d / "model_truncated.h5").write_bytes((d / "glpnet.h5").read_bytes()[:2000])
    with h5py.File(d / "foreign.h5", "w") as f:
        f["x"] = np.arange(3.0)
    (d / "folder.h5").mkdir()
    return d


# -- [load] ---------------------------------------------------------------------------------
LOADERS = {
    "Trajectories": (lambda p: it.Trajectories.load(p), "trajector"),
    "GLPNet": (lambda p: learn.GLPNet.load(p), "learn model"),
    "LPNet": (lambda p: learn.LPNet.load(p, BODY), "learn model"),
    "TrainingRecord": (lambda p: learn.TrainingRecord.load(p), "learn model"),
}
BAD_FILES = {
    "text.h5": r"not a readable HDF5 file",
    "truncated.h5": r"not a readable HDF5 file|damaged",
    "foreign.h5": r"not a liepoisson trajectory file|another kind of HDF5 file",
}


@pytest.mark.parametrize("loader", sorted(LOADERS))
@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_load_refuses_a_file_that_is_not_of_its_kind(files, loader, name):
    load, _ = LOADERS[loader]
    with pytest.raises(ValueError, match=rf"{name}.*({BAD_FILES[name]})|({BAD_FILES[name]}).*{name}"):
        load(files / name)


@pytest.mark.parametrize("loader", ["GLPNet", "LPNet", "TrainingRecord"])
def test_model_loaders_name_a_data_set_for_what_it_is(files, loader):
    with pytest.raises(ValueError, match=r"data\.h5.*holds a trajectory data set \(read it with integrators\.Trajectories\.load\)"):
        LOADERS[loader][0](files / "data.h5")


@pytest.mark.parametrize(
    "load, pattern",
    [
        (lambda d: it.Trajectories.load(d / "glpnet.h5"), r"glpnet\.h5.*not a liepoisson trajectory file"),
        (lambda d: learn.LPNet.load(d / "glpnet.h5"), r"glpnet\.h5.*holds a GLPNet, not a LPNet"),
        (lambda d: learn.GLPNet.load(d / "record.h5"), r"record\.h5.*holds a TrainingRecord, not a GLPNet"),
        (lambda d: learn.TrainingRecord.load(d / "glpnet.h5"), r"glpnet\.h5.*holds a GLPNet, not a TrainingRecord"),
        (lambda d: learn.GLPNet.load(d / "glpnet.h5", lp.systems.RigidBody(inertia=(1.0, 2.0, 4.0))),
         r"does not match the file .*glpnet\.h5.*parameters differ"),
        (lambda d: learn.GLPNet.load(d / "model_truncated.h5"), r"model_truncated\.h5.*(not a readable HDF5 file|damaged)"),
        (lambda d: it.Trajectories.load(d / "missing.h5"), r"no such file: .*missing\.h5"),
        (lambda d: learn.GLPNet.load(d / "missing.h5"), r"no such file: .*missing\.h5.*expected a learn model"),
        (lambda d: learn.GLPNet.load(d / "folder.h5"), r"folder\.h5.*is a folder"),
        (lambda d: it.Trajectories.load(d / "data.h5", system="RigidBody"), r"system must be an AbstractPoissonSystem or None; got str"),
    ],
)
def test_load_mistakes_are_named(files, load, pattern):
    with pytest.raises((ValueError, TypeError, FileNotFoundError, IsADirectoryError), match=pattern):
        load(files)


def test_resuming_from_a_checkpoint_of_another_system_or_model_is_refused(tmp_path):
    data = it.ground_truth(BODY, Y0, h=0.1, n_steps=4)
    path = tmp_path / "ckpt.h5"
    # no validation split: the checkpoint is all this fit is for (one loss program, not two)
    kwargs = {"optimiser": learn.Adam(20), "validation_fraction": 0.0, "progress": False}
    learn.fit(learn.LPNet(BODY, hidden=(4,)), data, checkpoint=learn.Checkpoint(path, every=10), **kwargs)
    other = lp.systems.RigidBody(inertia=(1.0, 2.0, 4.0))
    other_data = it.ground_truth(other, Y0, h=0.1, n_steps=4)
    resume = learn.Checkpoint(path, every=10, resume=True)
    with pytest.raises(ValueError, match=r"cannot resume: system RigidBody\(inertia=\[1\.0, 2\.0, 4\.0\]\) does not match checkpoint"):
        learn.fit(learn.LPNet(other, hidden=(4,)), other_data, checkpoint=resume, **kwargs)
    with pytest.raises(ValueError, match=r"hyperparameters"):
        learn.fit(learn.LPNet(BODY, hidden=(5,)), data, checkpoint=resume, **kwargs)


# -- [save] ---------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["data", "model", "record", "text"])
def test_saving_into_a_missing_folder_creates_it(tmp_path, files, kind):
    target = tmp_path / "a" / "b" / "out.h5"
    if kind == "data":
        it.Trajectories.load(files / "data.h5").save(target)
        assert it.Trajectories.load(target).states.shape == (2, 5, 3)
    elif kind == "model":
        learn.GLPNet.load(files / "glpnet.h5").save(target)
        assert learn.GLPNet.load(target).n_modules == 6
    elif kind == "record":
        learn.TrainingRecord.load(files / "record.h5").save(target)
        assert learn.TrainingRecord.load(target).stages
    else:
        from integrators._files import atomic_write_text

        atomic_write_text(target, "x")
        assert target.read_text() == "x"
    assert os.listdir(target.parent) == ["out.h5"]  # no temporary left beside it


def test_saving_onto_a_folder_is_refused(tmp_path, files):
    (tmp_path / "out.h5").mkdir()
    with pytest.raises(IsADirectoryError, match=r"out\.h5.*is a folder; give a file name"):
        it.Trajectories.load(files / "data.h5").save(tmp_path / "out.h5")
    assert os.listdir(tmp_path) == ["out.h5"]


# -- [kill] ---------------------------------------------------------------------------------
_SAVE_SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np
    import integrators as it, liepoisson as lp
    states = np.ones((200, 4001, 3))  # 19 MB: the write (seconds) takes long enough to be interrupted
    data = it.Trajectories(states, 0.1, lp.systems.RigidBody())
    print("ready", flush=True)
    for _ in range(100):
        data.save(sys.argv[1])
    """
)


def _start(script: str, *args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    proc = subprocess.Popen([sys.executable, "-c", script, *args], stdout=subprocess.PIPE, env=env, text=True)
    assert proc.stdout.readline().strip() == "ready"
    return proc


def _wait_for(pattern: str, timeout: float = 300.0) -> list[str]:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = glob.glob(pattern)
        if found:
            return found
        time.sleep(0.001)
    raise AssertionError(f"nothing matched {pattern} within {timeout} s")


# SIGTERM waits for h5py's write to return to Python: under -m slow. The file is 19 MB (it was
# 192 MB, ~40 s a write: a loaded machine took more than the 60 s allowed); the timeouts here
# (300 s) only keep a stuck child from hanging the run.
@pytest.mark.parametrize("sig", [signal.SIGKILL, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_a_killed_save_leaves_no_half_file_and_no_stale_temporary(tmp_path, sig):
    target = tmp_path / "big.h5"
    proc = _start(_SAVE_SCRIPT, str(target))
    _wait_for(str(tmp_path / ".big.h5.*.tmp"))
    proc.send_signal(sig)
    proc.wait(timeout=300)
    proc.stdout.close()
    if not target.exists():  # killed in its first write: nothing visible
        assert sig == signal.SIGKILL or not glob.glob(str(tmp_path / ".big.h5.*.tmp"))
    else:  # an earlier write completed: the file is whole
        assert it.Trajectories.load(target).states.shape == (200, 4001, 3)
    left = glob.glob(str(tmp_path / ".big.h5.*.tmp"))
    if sig == signal.SIGTERM:
        assert left == []  # SIGTERM raised SystemExit inside the write: it cleaned up
    # The next save of the same path removes what a SIGKILLed one had to leave behind.
    it.Trajectories(np.ones((1, 2, 3)), 0.1, BODY).save(target)
    assert sorted(os.listdir(tmp_path)) == ["big.h5"]
    assert it.Trajectories.load(target).states.shape == (1, 2, 3)


def test_a_sigterm_whose_exit_python_swallowed_still_ends_the_process_after_a_whole_write(tmp_path):
    """SIGTERM's SystemExit raised while a finalizer runs is printed as "Exception ignored" and
    lost (a timed-out docs build ran on so): the write completes, then the exit is raised again;
    meanwhile a second SIGTERM would kill outright (the default handler back)."""
    script = textwrap.dedent("""
        import os, signal, sys
        from integrators._files import atomic_path
        with atomic_path(sys.argv[1]) as tmp:
            with open(tmp, "w") as f:
                f.write("whole")
            try:
                os.kill(os.getpid(), signal.SIGTERM)  # the handler raises at the next bytecode
                signal.pthread_sigmask(signal.SIG_BLOCK, [])
            except SystemExit:
                pass  # swallowed, as in a finalizer
            print("default" if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL else "caught", flush=True)
        print("not reached", flush=True)
    """)
    target = tmp_path / "x.txt"
    done = subprocess.run([sys.executable, "-c", script, str(target)], check=False, capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 128 + signal.SIGTERM, done.stderr
    assert done.stdout.split() == ["default"]
    assert target.read_text() == "whole" and sorted(os.listdir(tmp_path)) == ["x.txt"]


def test_a_live_writers_temporary_is_kept(tmp_path):
    """Stale-temporary removal only touches files of dead processes (a concurrent writer's
    temporary carries its live pid)."""
    from integrators._files import remove_stale_temporaries

    live = tmp_path / f".x.h5.{os.getpid()}.abc.tmp"
    live.write_text("")
    dead = tmp_path / ".x.h5.999999999.abc.tmp"
    dead.write_text("")
    assert remove_stale_temporaries(tmp_path / "x.h5") == [str(dead)]
    assert live.exists() and not dead.exists()


_TRAIN_SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np
    import integrators as it, learn, liepoisson as lp
    import learn._solvers._adam as training
    training.CHUNK = 50
    body = lp.systems.RigidBody()
    data = it.ground_truth(body, np.array([[1.0, 0.5, 0.2], [0.3, 1.0, -0.4]]), h=0.1, n_steps=20, seed=0)
    print("ready", flush=True)
    learn.fit(learn.LPNet(body, hidden=(4,), key=2), data, optimiser=learn.Adam(int(sys.argv[2]), learning_rate=1e-2),
              checkpoint=learn.Checkpoint(sys.argv[1], every=50), progress=False)
    """
)
EPOCHS = 6000


@pytest.mark.slow
def test_training_killed_with_sigkill_resumes_bit_identically(tmp_path, monkeypatch):
    import learn._solvers._adam as training

    path = tmp_path / "ckpt.h5"
    proc = _start(_TRAIN_SCRIPT, str(path), str(EPOCHS))
    _wait_for(str(path))
    time.sleep(0.3)  # a few checkpoints in, well before the end
    proc.kill()
    proc.wait(timeout=300)
    proc.stdout.close()
    epoch = learn._files.read(path)[0]["epoch"]
    assert 0 < epoch < EPOCHS, epoch  # killed mid-training, with a checkpoint to resume from
    monkeypatch.setattr(training, "CHUNK", 50)
    data = it.ground_truth(BODY, Y0, h=0.1, n_steps=20, seed=0)
    kwargs = {"optimiser": learn.Adam(EPOCHS, learning_rate=1e-2), "progress": False}
    net = learn.LPNet(BODY, hidden=(4,), key=2)
    straight, straight_record = learn.fit(net, data, checkpoint=learn.Checkpoint(tmp_path / "s.h5", every=50), **kwargs)
    resumed, resumed_record = learn.fit(net, data, checkpoint=learn.Checkpoint(path, every=50, resume=True), **kwargs)
    for a, b in zip(learn._files.array_leaves(straight), learn._files.array_leaves(resumed), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(straight_record.history["train_loss"], resumed_record.history["train_loss"])
    assert sorted(os.listdir(tmp_path)) == ["ckpt.h5", "s.h5"]  # no stray temporaries


# -- [args] / [silent] / [index] ---------------------------------------------------------------
STRANG = it.splitting.Strang(BODY, 0.1)

ARG_CASES = [
    # (id, call, exception, the message must match)
    ("gt-h0", lambda: it.ground_truth(BODY, Y0, h=0.0, n_steps=3), ValueError, r"\bh must be"),
    ("gt-hneg", lambda: it.ground_truth(BODY, Y0, h=-1.0, n_steps=3), ValueError, r"\bh must be"),
    ("gt-hnan", lambda: it.ground_truth(BODY, Y0, h=np.nan, n_steps=3), ValueError, r"\bh must be"),
    ("gt-hstr", lambda: it.ground_truth(BODY, Y0, h="0.1", n_steps=3), TypeError, r"\bh must be"),
    ("gt-nsteps0", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=0), ValueError, r"n_steps must be an integer >= 1"),
    ("gt-nsteps-float", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=2.5), TypeError, r"n_steps must be an integer"),
    ("gt-tol0", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=3, tol=0.0), ValueError, r"tol must be"),
    ("gt-tol-big", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=3, tol=2.0), ValueError, r"tol must be a relative tolerance in \(0, 1\)"),
    ("gt-tol-str", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=3, tol="tight"), TypeError, r"tol must be"),
    ("gt-maxsteps-neg", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=3, max_steps=-1), ValueError, r"max_steps must be an integer >= 0"),
    ("gt-maxsteps-float", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=3, max_steps=0.5), TypeError, r"max_steps must be an integer"),
    ("gt-memory", lambda: it.ground_truth(BODY, np.ones((10**6, 3)), h=0.1, n_steps=10**7), ValueError,
     r"requested trajectories .*would need .* GiB .*, more than the .* GiB available to one request"),
    ("gt-y0-shape", lambda: it.ground_truth(BODY, np.ones((2, 4)), h=0.1, n_steps=3), ValueError, r"y0"),
    ("gt-y0-nan", lambda: it.ground_truth(BODY, np.array([1.0, np.nan, 0.0]), h=0.1, n_steps=3), ValueError, r"y0"),
    ("gt-system", lambda: it.ground_truth("RigidBody", Y0, h=0.1, n_steps=3), TypeError, r"system must be an AbstractPoissonSystem"),
    ("gt-progress", lambda: it.ground_truth(BODY, Y0, h=0.1, n_steps=3, progress="yes"), TypeError, r"progress must be True, False or None"),
    ("lyap-t", lambda: it.lyapunov_exponent(BODY, Y0[0], t_final="10"), TypeError, r"t_final must be"),
    ("lyap-tau", lambda: it.lyapunov_exponent(BODY, Y0[0], t_final=10.0, renormalization_time=-1.0), ValueError, r"renormalization_time must be"),
    ("lyap-tau-big", lambda: it.lyapunov_exponent(BODY, Y0[0], t_final=1.0, renormalization_time=2.0), ValueError, r"renormalization_time .* must not exceed t_final"),
    ("lyap-y0", lambda: it.lyapunov_exponent(BODY, Y0, t_final=1.0), ValueError, r"y0 must have shape \(3,\)"),
    ("lyap-system", lambda: it.lyapunov_exponent(None, Y0[0], t_final=1.0), TypeError, r"system must be"),
    ("flow-broadcast", lambda: lp.so3().coadjoint_flow(np.ones((2, 3)), np.ones(3), np.ones((4, 3))), ValueError,
     r"batch shapes of alpha \(2,\), mu \(4,\), t \(3,\) do not broadcast"),
    ("testflow-broadcast", lambda: BODY.test_flow(np.ones((2, 3)), 0.1, np.ones((5, 3))), ValueError,
     r"batch shapes of alpha \(2,\), y \(5,\), t \(\) do not broadcast"),
    ("flow-alpha-dim", lambda: lp.so3().coadjoint_flow(np.ones(4), 0.1, np.ones(3)), ValueError, r"alpha"),
    ("flow-mu-nan", lambda: lp.so3().coadjoint_flow(np.ones(3), 0.1, [1.0, np.nan, 0.0]), ValueError, r"mu"),
    ("flow-t-inf", lambda: lp.so3().coadjoint_flow(np.ones(3), np.inf, np.ones(3)), ValueError, r"\bt\b"),
    ("flow-overflow", lambda: lp.sl2().coadjoint_flow([900.0, 0.0, 0.0], 1.0, [1.0, 1.0, 1.0]), FloatingPointError,
     r"coadjoint_flow overflowed .* \|t\| \|alpha\| = 900"),
    ("algebra-str", lambda: lp.LieAlgebra("C"), TypeError, r"structure_constants must be a real array"),
    ("algebra-shape", lambda: lp.LieAlgebra(np.zeros((3, 3))), ValueError, r"structure_constants must have shape \(n, n, n\)"),
    ("algebra-antisym", lambda: lp.LieAlgebra(np.ones((2, 2, 2))), ValueError, r"structure_constants must be antisymmetric"),
    ("algebra-sign", lambda: lp.LieAlgebra(np.zeros((2, 2, 2)), sign=2), ValueError, r"sign must be -1"),
    ("strang-h0", lambda: it.splitting.Strang(BODY, 0.0), ValueError, r"\bh must be"),
    ("strang-ordering", lambda: it.splitting.Strang(BODY, 0.1, ordering=(0, 0, 1)), ValueError, r"ordering must be a permutation of range\(3\)"),
    ("strang-terms", lambda: it.splitting.Strang(BODY, 0.1, terms=[1, 2]), TypeError, r"terms\[0\] must be an exact piece"),
    ("rk4-h", lambda: it.RK4(BODY, -0.1), ValueError, r"\bh must be"),
    ("rollout-n", lambda: STRANG.rollout(Y0, -1), ValueError, r"n_steps must be an integer >= 0"),
    ("rollout-save", lambda: STRANG.rollout(Y0, 10, save_every=0), ValueError, r"save_every must be an integer >= 1"),
    ("rollout-divide", lambda: STRANG.rollout(Y0, 10, save_every=3), ValueError, r"save_every must divide n_steps"),
    ("rollout-y0", lambda: STRANG.rollout(np.ones((2, 4)), 10), ValueError, r"y0"),
    ("rollout-y0-3d", lambda: STRANG.rollout(np.ones((2, 2, 3)), 10), ValueError, r"y0 must have shape \(3,\) or \(n_traj, 3\)"),
    ("rollout-nonfinite", lambda: STRANG.rollout(Y0, 10, nonfinite="warn"), ValueError, r"nonfinite must be one of \('raise', 'return'\)"),
    ("rollout-diverged", lambda: it.RK4(BODY, 20.0).rollout(Y0, 60), it.RolloutDivergedError, r"trajectory \d became non-finite at step \d+"),
    ("with-h", lambda: STRANG.with_h(0.0), ValueError, r"\bh must be"),
    ("defect-shape", lambda: STRANG.poisson_defect(np.ones(4)), ValueError, r"\by\b"),
    ("diag-shape", lambda: it.diagnostics(np.ones((2, 5, 4)), BODY), ValueError, r"trajectory"),
    ("diag-start-nan", lambda: it.diagnostics(np.array([[1.0, 0.0, np.inf], [1.0, 0.0, 0.0]]), BODY), ValueError,
     r"initial state has component 2 = inf"),
    ("compare-t", lambda: it.compare([STRANG], BODY, Y0, t_final=-1.0), ValueError, r"t_final must be"),
    ("compare-maps", lambda: it.compare([1], BODY, Y0, t_final=1.0), TypeError, r"maps"),
    ("traj-states", lambda: it.Trajectories(np.ones((2, 5, 4)), 0.1, BODY), ValueError, r"states"),
    ("traj-h", lambda: it.Trajectories(np.ones((1, 2, 3)), 0.0, BODY), ValueError, r"\bh must be"),
    ("traj-system", lambda: it.Trajectories(np.ones((1, 2, 3)), 0.1, "RigidBody"), TypeError, r"system must be an AbstractPoissonSystem"),
    ("traj-nan", lambda: it.Trajectories(np.full((1, 2, 3), np.nan), 0.1, BODY), ValueError, r"states"),
    ("lpnet-system", lambda: learn.LPNet("RigidBody"), TypeError, r"system must be"),
    ("glpnet-modules", lambda: learn.GLPNet(BODY, n_modules=0), ValueError, r"n_modules must be an integer >= 1"),
    ("glpnet-activation", lambda: learn.GLPNet(BODY, activation="relu6"), ValueError, r"activation"),
    ("glpnet-method", lambda: learn.GLPNet(BODY, method="Strang"), TypeError, r"method must be a splitting method"),
    ("fit-data", lambda: learn.fit(learn.GLPNet(BODY), [1, 2, 3], progress=False), ValueError, r"data given as a tuple must be \(y0, y1\)"),
    ("fit-data-type", lambda: learn.fit(learn.GLPNet(BODY), "data.h5", progress=False), TypeError, r"data must be an integrators\.Trajectories"),
    ("fit-h-missing", lambda: learn.fit(learn.GLPNet(BODY), (Y0, Y0), progress=False), ValueError, r"h \(the time step between y0 and y1\) is required"),
    ("fit-progress", lambda: learn.fit(learn.GLPNet(BODY), (Y0, Y0), h=0.1, progress="yes"), TypeError, r"progress must be True, False or None"),
    ("fit-valfrac", lambda: learn.fit(learn.GLPNet(BODY), (Y0, Y0), h=0.1, validation_fraction=1.5, progress=False), ValueError, r"validation_fraction"),
    # [silent]: pairs that no Casimir-preserving map connects, whatever the loss
    ("fit-casimir-pair", lambda: learn.fit(learn.LPNet(BODY), (Y0, 2.0 * Y0), h=0.1, loss="state", progress=False), ValueError,
     r"data pair 0: Casimir 0 differs between y0 and y1 .* no Poisson map connects them"),
    ("fit-casimir-traj", lambda: learn.fit(learn.GLPNet(BODY), _scaled_trajectories(), progress=False), ValueError,
     r"data trajectory 1, step 2 -> 3: Casimir 0 differs"),
    ("model-unfitted", lambda: learn.GLPNet(BODY).rollout(Y0, 3), ValueError, r"GLPNet has no step size h yet"),
    ("from-name", lambda: lp.systems.from_name("Pendulum"), ValueError, r"unknown system 'Pendulum'"),
    ("user-xp", lambda: lp.systems.LiePoissonSystem(lp.so3(), lambda m, xp: np.sqrt(m[0] ** 2 + 1)), TypeError,
     r"hamiltonian: .*numpy\.sqrt.*xp\.sqrt"),
]


def _scaled_trajectories() -> it.Trajectories:
    """A data set whose trajectory 1 jumps off its Casimir level between steps 2 and 3."""
    states = np.asarray(it.ground_truth(BODY, Y0, h=0.1, n_steps=4).states).copy()
    states[1, 3:] *= 1.5
    return it.Trajectories(states, 0.1, BODY)


@pytest.mark.parametrize("call, exc, pattern", [c[1:] for c in ARG_CASES], ids=[c[0] for c in ARG_CASES])
def test_bad_arguments_raise_clear_errors(call, exc, pattern):
    with pytest.raises(exc, match=pattern) as info:
        call()
    # a clear error is raised by the library, not from inside numpy, JAX, heyoka or h5py
    raised_in = str(info.traceback[-1].path)
    assert not any(f"/{lib}/" in raised_in for lib in ("jax", "numpy", "heyoka", "h5py", "scipy")), raised_in


# -- [table] -------------------------------------------------------------------------------
@pytest.mark.parametrize("content", ["{not json", "[1, 2]", json.dumps({"profile": "quick", "rows": "garbled"})])
def test_paper_table_warns_on_a_malformed_metrics_file_and_goes_on(tmp_path, content, capsys):
    from paper.__main__ import load_results, summary_table

    (tmp_path / "W1").mkdir()
    (tmp_path / "W1" / "metrics.json").write_text(content)
    table = summary_table(load_results(tmp_path))
    assert table.startswith("| experiment | metric |")
    assert "warning: skipping" in capsys.readouterr().err


# -- [progress] ----------------------------------------------------------------------------
def test_progress_bars_only_on_a_terminal(monkeypatch):
    from liepoisson._progress import show_progress

    class Stream:
        def __init__(self, tty):
            self.tty = tty

        def isatty(self):
            return self.tty

    monkeypatch.setattr(sys, "stderr", Stream(False))
    assert show_progress(None) is False and show_progress(True) is True
    monkeypatch.setattr(sys, "stderr", Stream(True))
    assert show_progress(None) is True and show_progress(False) is False


def test_a_state_at_a_singular_point_is_refused_not_a_nan():
    import integrators as it

    s = lp.systems.ChargedParticle()
    at_origin = [[1.0, 0.5, 0.3, 0.0], [1.0, 0.5, 0.0, 0.0]]
    for method in (s.hamiltonian, s.hamiltonian_gradient, s.vector_field):
        with pytest.raises(ValueError, match=r"y\[1\] = \[1\.0, 0\.5, 0\.0, 0\.0\] is a singular point of ChargedParticle"):
            method(at_origin)
    with pytest.raises(ValueError, match=r"y0 = .* singular point .* origin"):
        it.ground_truth(s, [1.0, 0.5, 0.0, 0.0], 0.1, 3)
    assert np.isfinite(s.hamiltonian(at_origin[0]))  # next to it: defined
    assert np.all(np.isfinite(s.vector_field([1.0, 0.5, 1e-100, 0.0])))
    with pytest.raises(ValueError, match="singular point"):  # r^2 underflows: the origin in float64
        s.vector_field([1.0, 0.5, 1e-300, 0.0])
