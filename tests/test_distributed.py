"""Scale-out on Dask: chunked ground truth (in memory and written chunk by chunk to HDF5,
resumable) and training sweeps on a real `LocalCluster` of 2 worker processes."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import cloudpickle
import distributed
import h5py
import jax
import numpy as np
import pytest

import integrators
import learn
import liepoisson as lp
from integrators import _ground_truth


@pytest.fixture(scope="module")
def client():
    # the scheduler's web server on a free port: with dashboard_address=None Dask still binds
    # its default 8787, and the CLI's own cluster (below) would then warn that it is taken
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster, distributed.Client(cluster) as c:
        yield c


BODY = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))


def _y0(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, 3))


@pytest.mark.slow  # the default run's time (7 s); resumption and sweeps on the cluster by default
def test_chunked_ground_truth_on_a_cluster_is_bitwise_the_single_process_result(client):
    y0 = _y0(11)
    here = integrators.ground_truth(BODY, y0, 0.1, 40)
    there = integrators.ground_truth(BODY, y0, 0.1, 40, client=client, chunk_size=3)  # 4 chunks, last of 2
    np.testing.assert_array_equal(there.states, here.states)
    assert there.metadata == {**here.metadata, "created": there.created}


_THREADS_SCRIPT = """
import distributed, numpy as np, integrators, liepoisson as lp
body = lp.systems.RigidBody()
y0 = np.random.default_rng(9).uniform(-1, 1, size=(16, 3))
here = integrators.ground_truth(body, y0, 0.1, 200)
with distributed.LocalCluster(n_workers=1, threads_per_worker=4, processes=False,
                              dashboard_address=None) as cluster, distributed.Client(cluster) as threads:
    there = integrators.ground_truth(body, y0, 0.1, 200, client=threads, chunk_size=1)
np.testing.assert_array_equal(there.states, here.states)
print("bitwise equal")
"""


@pytest.mark.slow
def test_threads_of_one_worker_do_not_share_an_integrator():
    # heyoka's integrator holds its state: two threads integrating chunks at once must each have
    # their own (a shared one raised "the first element of the time grid must match ...").
    # In its own process: an in-process cluster beside this module's cluster broke the next
    # test's fixture in a full run.
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1]), "JAX_PLATFORMS": "cpu"}
    done = subprocess.run([sys.executable, "-c", _THREADS_SCRIPT], check=False, capture_output=True, text=True, env=env,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().endswith("bitwise equal")


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_a_user_system_is_sent_to_the_workers_once_and_integrated_bitwise_alike(client):
    algebra = lp.so3()
    system = lp.systems.LiePoissonSystem(
        algebra, lambda y, xp: 0.5 * (y[0] ** 2 + 0.5 * y[1] ** 2 + y[2] ** 2 / 3) + 0.1 * xp.cos(y[0]), name="mine"
    )
    y0 = _y0(7, seed=1)
    here = integrators.ground_truth(system, y0, 0.05, 30)
    there = integrators.ground_truth(system, y0, 0.05, 30, client=client, chunk_size=2)
    np.testing.assert_array_equal(there.states, here.states)


def test_save_ground_truth_writes_the_file_that_save_would_with_or_without_a_client(client, tmp_path):
    y0 = _y0(9, seed=2)
    reference = integrators.ground_truth(BODY, y0, 0.1, 25, seed=7)
    for name, c in (("local.h5", None), ("cluster.h5", client)):
        path = integrators.save_ground_truth(tmp_path / name, BODY, y0, 0.1, 25, client=c, chunk_size=4, seed=7)
        assert path == os.fspath(tmp_path / name)
        loaded = integrators.Trajectories.load(path)
        np.testing.assert_array_equal(loaded.states, reference.states)
        np.testing.assert_array_equal(loaded.times, reference.times)
        assert {k: v for k, v in loaded.metadata.items() if k != "created"} == {
            k: v for k, v in reference.metadata.items() if k != "created"
        }
    assert sorted(os.listdir(tmp_path)) == ["cluster.h5", "local.h5"]  # no partial file left
    part = integrators.Trajectories.load(tmp_path / "local.h5", select=slice(2, 5))
    np.testing.assert_array_equal(part.states, reference.states[2:5])
    np.testing.assert_array_equal(integrators.Trajectories.load(tmp_path / "local.h5", select=[0, 8]).states,
                                  reference.states[[0, 8]])


_KILLED_RUN = textwrap.dedent(
    """
    import os, signal, sys
    import numpy as np
    import integrators, liepoisson as lp
    from integrators import _ground_truth

    calls = 0
    original = _ground_truth.integrate_chunk

    def integrate_then_die(*args):
        global calls
        calls += 1
        if calls == 4:  # three chunks written, killed outright while computing the fourth
            os.kill(os.getpid(), signal.SIGKILL)
        return original(*args)

    _ground_truth.integrate_chunk = integrate_then_die
    y0 = np.random.default_rng(3).normal(size=(10, 3))
    integrators.save_ground_truth(sys.argv[1], lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)), y0, 0.1, 30,
                                  chunk_size=2)
    """
)


@pytest.fixture(scope="module")
def killed_run(tmp_path_factory):
    """A `save_ground_truth` run of 5 chunks killed (SIGKILL) after writing 3: its partial file."""
    folder = tmp_path_factory.mktemp("killed")
    target = folder / "truth.h5"
    proc = subprocess.run([sys.executable, "-c", _KILLED_RUN, str(target)], check=False, capture_output=True,
                          text=True)
    assert proc.returncode == -9, proc.stderr
    assert not target.exists()
    partial = folder / ".truth.h5.partial.h5"
    assert partial.exists()
    return partial.read_bytes()


@pytest.mark.parametrize("on_cluster", [False, True])
def test_a_killed_run_resumes_computing_only_the_missing_chunks(killed_run, on_cluster, request, tmp_path,
                                                                monkeypatch, caplog):
    c = request.getfixturevalue("client") if on_cluster else None
    (tmp_path / ".truth.h5.partial.h5").write_bytes(killed_run)
    y0 = np.random.default_rng(3).normal(size=(10, 3))
    computed = []
    if not on_cluster:  # count the chunks computed here
        original = _ground_truth.integrate_chunk
        monkeypatch.setattr(_ground_truth, "integrate_chunk",
                            lambda system, start, *a: computed.append(start) or original(system, start, *a))
    with caplog.at_level(logging.INFO, logger="liepoisson"):
        integrators.save_ground_truth(tmp_path / "truth.h5", BODY, y0, 0.1, 30, chunk_size=2, client=c)
    assert "3 of 5 chunks already" in caplog.text
    if not on_cluster:
        assert computed == [6, 8]
    resumed = integrators.Trajectories.load(tmp_path / "truth.h5")
    np.testing.assert_array_equal(resumed.states, integrators.ground_truth(BODY, y0, 0.1, 30).states)
    assert os.listdir(tmp_path) == ["truth.h5"]


def test_a_partial_file_of_another_request_is_started_over(killed_run, tmp_path, caplog):
    (tmp_path / ".truth.h5.partial.h5").write_bytes(killed_run)
    y0 = np.random.default_rng(4).normal(size=(10, 3))  # other initial conditions
    with caplog.at_level(logging.INFO, logger="liepoisson"):
        integrators.save_ground_truth(tmp_path / "truth.h5", BODY, y0, 0.1, 30, chunk_size=2)
    assert "0 of 5 chunks already" in caplog.text
    np.testing.assert_array_equal(integrators.Trajectories.load(tmp_path / "truth.h5").states,
                                  integrators.ground_truth(BODY, y0, 0.1, 30).states)


def test_a_damaged_partial_file_is_started_over(tmp_path):
    (tmp_path / ".truth.h5.partial.h5").write_bytes(b"not HDF5 at all")
    y0 = _y0(3)
    integrators.save_ground_truth(tmp_path / "truth.h5", BODY, y0, 0.1, 5)
    np.testing.assert_array_equal(integrators.Trajectories.load(tmp_path / "truth.h5").states,
                                  integrators.ground_truth(BODY, y0, 0.1, 5).states)


def test_a_missing_dask_extra_is_named(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(ImportError, match=r"liepoisson\[dask\]"):
        integrators.ground_truth(BODY, _y0(2), 0.1, 3, client=object())


def test_bad_client_chunk_size_path_and_select_are_refused(tmp_path):
    with pytest.raises(TypeError, match="client must be a dask.distributed.Client"):
        integrators.ground_truth(BODY, _y0(2), 0.1, 3, client="tcp://localhost:8786")
    with pytest.raises(ValueError, match="chunk_size"):
        integrators.ground_truth(BODY, _y0(2), 0.1, 3, chunk_size=0)
    with pytest.raises(IsADirectoryError, match="it is a folder"):
        integrators.save_ground_truth(tmp_path, BODY, _y0(2), 0.1, 3)
    integrators.ground_truth(BODY, _y0(4), 0.1, 3).save(tmp_path / "t.h5")
    with pytest.raises(IndexError, match="out of range for a file of 4"):
        integrators.Trajectories.load(tmp_path / "t.h5", select=4)
    with pytest.raises(IndexError, match="increasing indices"):
        integrators.Trajectories.load(tmp_path / "t.h5", select=[2, 1])
    with pytest.raises(TypeError, match="select must be"):
        integrators.Trajectories.load(tmp_path / "t.h5", select="all")


# -- sweeps ---------------------------------------------------------------------------------

cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers cannot import tests/

SWEEP_DATA = integrators.ground_truth(BODY, _y0(6, seed=5), 0.1, 12)
SWEEP_GRID = {"n_modules": [2, 3], "seed": [0, 1]}
# without the identity warm start (tested in test_learn_warm_start.py): it is a second compiled
# program per network size, and a sweep hands any optimiser to learn.fit alike
SWEEP_OPTIMISER = learn.KeepIfBetter(learn.ScipyBFGS(25))


def _make_glpnet(point):
    return learn.GLPNet(BODY, n_modules=point["n_modules"], key=point["seed"])


def _energy_of_first_step(model, point):
    y = model.step(SWEEP_DATA.states[0, 0])
    return {"energy_after_one_step": float(BODY.hamiltonian(y))}


@pytest.fixture(scope="module")
def sequential_fits():
    return [learn.fit(_make_glpnet(p), SWEEP_DATA, optimiser=SWEEP_OPTIMISER, seed=p["seed"], progress=False)
            for p in learn.grid_points(SWEEP_GRID)]


# On the cluster and in process, both under -m slow; a rerun sweep and an interrupted sweep point run
# by default below.
@pytest.mark.parametrize("on_cluster", [pytest.param(False, marks=pytest.mark.slow), pytest.param(True, marks=pytest.mark.slow)])
def test_a_sweep_returns_the_numbers_of_sequential_fits_and_saves_every_point(
    sequential_fits, on_cluster, request, tmp_path
):
    c = request.getfixturevalue("client") if on_cluster else None
    result = learn.sweep(_make_glpnet, SWEEP_GRID, SWEEP_DATA, out=tmp_path / "sweep", client=c,
                         optimiser=SWEEP_OPTIMISER, evaluate=_energy_of_first_step)
    assert [r.point for r in result] == learn.grid_points(SWEEP_GRID)
    assert [r.seed for r in result] == [0, 1, 0, 1]
    for r, (model, record) in zip(result, sequential_fits):
        assert r.metrics["val_loss"] == record.val_loss
        assert r.metrics["train_loss"] == record.train_loss
        loaded = r.model()
        for a, b in zip(jax.tree_util.tree_leaves(loaded), jax.tree_util.tree_leaves(model)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert r.metrics["energy_after_one_step"] == float(BODY.hamiltonian(model.step(SWEEP_DATA.states[0, 0])))
        assert r.record().val_loss == record.val_loss
    reread = learn.Sweep.load(tmp_path / "sweep")
    assert [r.metrics for r in reread] == [r.metrics for r in result]
    assert "n_modules" in reread.table() and reread.best("val_loss").metrics["val_loss"] == min(
        rec.val_loss for _, rec in sequential_fits)


def test_a_rerun_sweep_trains_only_the_points_not_done(tmp_path, monkeypatch):
    from learn._training import _sweep

    trained = []
    original = _sweep._train
    monkeypatch.setattr(_sweep, "_train", lambda *a: trained.append(a[4]) or original(*a))  # a[4]: the point
    out = tmp_path / "sweep"
    grid = {"n_modules": [2], "seed": [0, 1, 2, 3]}
    learn.sweep(_make_glpnet, [{"n_modules": 2, "seed": 0}, {"n_modules": 2, "seed": 2}], SWEEP_DATA, out=out,
                optimiser=SWEEP_OPTIMISER)
    trained.clear()
    result = learn.sweep(_make_glpnet, grid, SWEEP_DATA, out=out, optimiser=SWEEP_OPTIMISER)
    assert trained == [{"n_modules": 2, "seed": 1}, {"n_modules": 2, "seed": 3}]
    assert len(result) == 4 and [r.seed for r in result] == [0, 1, 2, 3]
    # A rerun on a smaller grid returns that grid, and the folder still lists every point.
    trained.clear()
    small = learn.sweep(_make_glpnet, {"n_modules": [2], "seed": [3]}, SWEEP_DATA, out=out, optimiser=SWEEP_OPTIMISER)
    assert trained == [] and [r.seed for r in small] == [3]
    assert sorted(r.seed for r in learn.Sweep.load(out)) == [0, 1, 2, 3]


def _make_lpnet(point):
    return learn.LPNet(BODY, hidden=(4,), key=point["seed"])


def test_an_interrupted_sweep_point_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    import learn._files as ckpt
    import learn._solvers._adam as training

    monkeypatch.setattr(training, "CHUNK", 10)
    adam = learn.Adam(30, learning_rate=1e-2)
    grid = [{"seed": 0}]
    straight = learn.sweep(_make_lpnet, grid, SWEEP_DATA, out=tmp_path / "a", optimiser=adam)[0]
    write, calls = ckpt.write, []

    def interrupted(*args, **kw):  # the process dies right after the first checkpoint (epoch 10)
        write(*args, **kw)
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(ckpt, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        learn.sweep(_make_lpnet, grid, SWEEP_DATA, out=tmp_path / "b", optimiser=adam, checkpoint_every=10)
    monkeypatch.setattr(ckpt, "write", write)
    (folder,) = (tmp_path / "b" / "points").iterdir()
    assert calls == [1] and (folder / "adam-checkpoint.h5").exists() and not (folder / "result.json").exists()
    resumed = learn.sweep(_make_lpnet, grid, SWEEP_DATA, out=tmp_path / "b", optimiser=adam, checkpoint_every=10)[0]
    assert not (folder / "adam-checkpoint.h5").exists()  # removed once the point is saved
    assert resumed.metrics["val_loss"] == straight.metrics["val_loss"]
    for a, b in zip(jax.tree_util.tree_leaves(resumed.model()), jax.tree_util.tree_leaves(straight.model())):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(ValueError, match="checkpoint_every"):
        learn.sweep(_make_lpnet, grid, SWEEP_DATA, out=tmp_path / "c", optimiser=adam,
                    checkpoint=learn.Checkpoint(tmp_path / "x.h5"))
    with pytest.raises((TypeError, ValueError), match="checkpoint_every"):
        learn.sweep(_make_lpnet, grid, SWEEP_DATA, out=tmp_path / "c", optimiser=adam, checkpoint_every=0)


def test_bad_sweep_arguments_are_refused(tmp_path):
    with pytest.raises(TypeError, match="grid must be"):
        learn.sweep(_make_glpnet, "seed", SWEEP_DATA, out=tmp_path)
    with pytest.raises(TypeError, match=r"grid\['seed'\] must be a non-empty list"):
        learn.sweep(_make_glpnet, {"seed": []}, SWEEP_DATA, out=tmp_path)
    with pytest.raises(TypeError, match="unknown keyword argument"):
        learn.sweep(_make_glpnet, {"seed": [0]}, SWEEP_DATA, out=tmp_path, optimizer=SWEEP_OPTIMISER)
    with pytest.raises(ValueError, match="repeated points"):
        learn.sweep(_make_glpnet, [{"seed": 0}, {"seed": 0}], SWEEP_DATA, out=tmp_path)
    with pytest.raises(TypeError, match="must return a learned map"):
        learn.sweep(lambda p: None, {"seed": [0]}, SWEEP_DATA, out=tmp_path)
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="is a file"):
        learn.sweep(_make_glpnet, {"seed": [0]}, SWEEP_DATA, out=tmp_path / "file")


# -- python -m paper --scheduler ----------------------------------------------------------


@pytest.mark.slow  # two E1 smoke runs and a cluster: 80 s
def test_paper_trainings_on_a_local_cluster_give_the_numbers_of_one_process(tmp_path, capsys):
    from paper.__main__ import main

    assert main(["run", "E1", "--profile", "smoke", "--no-progress", "--out", str(tmp_path / "one")]) == 0
    assert main(["run", "E1", "--profile", "smoke", "--no-progress", "--out", str(tmp_path / "dask"),
                 "--scheduler"]) == 0
    assert "trainings on the Dask scheduler" in capsys.readouterr().out
    one, dask = (json.loads((tmp_path / d / "E1" / "metrics.json").read_text()) for d in ("one", "dask"))
    assert len(one["train_loss_seeds"]) == 2  # two seeds: two tasks
    for key in ("train_loss_seeds", "train_loss_seeds_adam_only"):  # the trainings: bitwise
        assert dask[key] == one[key], key
    # The rollout of a trained net over 300 steps in a worker process differs from this
    # process's in the last digits (seen: 7e-15 relative), as if XLA's threaded reductions
    # split differently; allow 1000 eps.
    np.testing.assert_allclose(dask["energy_rel_err_max_seeds"], one["energy_rel_err_max_seeds"], rtol=1000 * 2.2e-16)


@pytest.mark.slow  # two E1 smoke runs: ~20 s
def test_paper_trainings_in_threads_give_the_numbers_of_one_after_the_other(tmp_path, capsys):
    """The default `--scheduler threads`: E1's seeds, baseline and G-LPNet trained two at a time
    in threads give every figure of the run one after the other, bit for bit (same process, same
    compiled programs: nothing may depend on what runs beside a training)."""
    from paper.__main__ import main

    argv = ["run", "E1", "--profile", "smoke", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "one"), "--scheduler", "none"]) == 0
    assert "trainings on the" not in capsys.readouterr().out
    assert main([*argv, "--out", str(tmp_path / "threads")]) == 0  # the default
    assert "of this process" in capsys.readouterr().out
    one, threads = (json.loads((tmp_path / d / "E1" / "metrics.json").read_text()) for d in ("one", "threads"))

    def figures(metrics, prefix=""):  # every number but the timings
        for key, value in metrics.items():
            if isinstance(value, dict):
                yield from figures(value, f"{prefix}{key}.")
            elif "time" not in key and isinstance(value, (int, float, list)):
                yield f"{prefix}{key}", value

    assert dict(figures(threads)) == dict(figures(one))
    assert len(dict(figures(one))) > 20  # the seeds', the baseline's and the G-LPNet's figures


@pytest.mark.slow  # two E4 smoke runs, one in a spawned process: 12 s
def test_paper_trainings_in_worker_processes_give_the_numbers_of_one_process(tmp_path, capsys, monkeypatch):
    """`--scheduler processes`: the LPNet and the baseline of E4 trained in a spawned worker
    process (sent by cloudpickle) give the figures of one process."""
    from paper.__main__ import main

    # one worker process (a pool of one per core): each spawned process imports JAX and the
    # paper anew (~3 s); the trainings travel and come back the same way with one or many
    monkeypatch.setattr("paper._cluster.cores", lambda: 1)
    argv = ["run", "E4", "--profile", "smoke", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "one"), "--scheduler", "none"]) == 0
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "pool"), "--scheduler", "processes"]) == 0
    assert "trainings on the 1 worker process on this machine" in capsys.readouterr().out
    one, pool = (json.loads((tmp_path / d / "E4" / "metrics.json").read_text()) for d in ("one", "pool"))
    for key in ("train_loss", "val_loss"):  # the trainings: bitwise
        assert pool[key] == one[key], key
        assert pool["baseline"][key] == one["baseline"][key], key
    # rollouts in another process may differ in the last digits (see the Dask test): 1000 eps
    np.testing.assert_allclose(pool["energy_rel_err_max"], one["energy_rel_err_max"], rtol=1000 * 2.2e-16)


def test_paper_scheduler_without_the_extra_or_unreachable_is_a_clear_error(tmp_path, monkeypatch, capsys):
    from paper.__main__ import main

    argv = ["run", "E6", "--profile", "smoke", "--no-progress", "--out", str(tmp_path)]
    monkeypatch.setattr("paper._cluster.CONNECT_TIMEOUT", 1.0)
    assert main([*argv, "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "cannot reach a Dask scheduler" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "distributed", None)
    monkeypatch.setenv("LIEPOISSON_SCHEDULER", "local")
    assert main(argv) == 2
    assert "liepoisson[dask]" in capsys.readouterr().err


@pytest.mark.slow  # a cluster, 2000 trajectories and a sweep of 8 short fits: ~1 min
def test_the_readme_dask_example_runs_as_a_script(tmp_path):
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    (block,) = re.findall(r"```py\n(.*?)```", readme, re.DOTALL)
    for full, small in (("size=(100_000, 3)", "size=(2000, 3)"), ("epochs=3000", "epochs=50")):
        assert full in block, f"the README's Dask example no longer has {full!r}"
        block = block.replace(full, small)
    (tmp_path / "example.py").write_text(block)
    proc = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.count("\n| ") >= 8  # a row per grid point
    assert integrators.Trajectories.load(tmp_path / "truth.h5").n_traj == 2000
    assert len(learn.Sweep.load(tmp_path / "sweep")) == 8


def test_save_ground_truth_with_configurations_writes_what_ground_truth_gives_and_resumes_only_its_own(tmp_path):
    from scipy.spatial.transform import Rotation

    y0 = _y0(5, seed=3)
    g0 = Rotation.random(5, random_state=4).as_quat()
    reference = integrators.ground_truth(BODY, y0, 0.1, 20, g0=g0)
    path = integrators.save_ground_truth(tmp_path / "truth.h5", BODY, y0, 0.1, 20, chunk_size=2, g0=g0)
    loaded = integrators.Trajectories.load(path)
    np.testing.assert_array_equal(loaded.states, reference.states)
    np.testing.assert_array_equal(loaded.configurations, reference.configurations)
    np.testing.assert_array_equal(integrators.Trajectories.load(path, select=[1, 4]).configurations,
                                  reference.configurations[[1, 4]])
    # a partial file of the same momenta from other configurations is started over, not resumed
    other = _ground_truth._job(BODY, y0, 0.1, 20, None, 0, None, False, 2, Rotation.random(5, random_state=5).as_quat())
    partial = _ground_truth._partial_path(os.fspath(tmp_path / "again.h5"))
    _ground_truth._open_partial(partial, other)
    with h5py.File(partial, "r+") as f:  # chunk 0 "done" with wrong values
        f["configurations"][0:2] = 0.5
        f["chunk_done"][0] = True
    again = integrators.Trajectories.load(
        integrators.save_ground_truth(tmp_path / "again.h5", BODY, y0, 0.1, 20, chunk_size=2, g0=g0))
    np.testing.assert_array_equal(again.configurations, reference.configurations)
    # ... and one of the same request is resumed: its chunk 0 is kept as written
    same = _ground_truth._job(BODY, y0, 0.1, 20, None, 0, None, False, 2, g0)
    _ground_truth._open_partial(partial, same)
    with h5py.File(partial, "r+") as f:
        f["configurations"][0:2] = 0.5
        f["chunk_done"][0] = True
    resumed = integrators.Trajectories.load(
        integrators.save_ground_truth(tmp_path / "again.h5", BODY, y0, 0.1, 20, chunk_size=2, g0=g0))
    np.testing.assert_array_equal(resumed.configurations[2:], reference.configurations[2:])


def test_threads_are_as_many_as_the_cores_this_process_may_use(monkeypatch):
    """A process pinned to some cores (taskset, a container's CPU set) trains on as many threads
    as it has cores, not the machine's count; without affinity (macOS) the machine's."""
    from paper import _cluster

    monkeypatch.setattr(_cluster.os, "sched_getaffinity", lambda pid: {1}, raising=False)
    monkeypatch.setattr(_cluster.os, "cpu_count", lambda: 8)
    assert _cluster.cores() == 1
    with _cluster.scheduler("threads") as description:
        assert description == "1 thread of this process"
    monkeypatch.delattr(_cluster.os, "sched_getaffinity")
    assert _cluster.cores() == 8
