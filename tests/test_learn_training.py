"""learn training: Adam fits (LPNet, MLPBaseline), BFGS fits (GLPNet), best-validation weights,
quasi-Newton stages, HDF5 save/load of models and records, and checkpoint resume."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
from helpers import ToyProblem

import learn
import liepoisson as lp

H = 0.1


def _rigid_body_pairs(y0, n_steps, inertia=(1.0, 2.0, 3.0)):
    """Reference trajectory (numpy Euler equations, DOP853 at tight tolerance): no shared code."""
    inertia = np.asarray(inertia)
    t = np.arange(n_steps + 1) * H
    sol = scipy.integrate.solve_ivp(
        lambda _, y: np.cross(y, y / inertia), (0, t[-1]), y0, method="DOP853",
        rtol=1e-13, atol=1e-14, t_eval=t,
    )
    Y = sol.y.T
    return Y[:-1], Y[1:]


@pytest.fixture(scope="module")
def rb():
    return lp.systems.RigidBody()


@pytest.fixture(scope="module")
def pairs():
    return _rigid_body_pairs(np.array([1 / np.sqrt(2), -1 / np.sqrt(2), 1.0]), 120)


@pytest.fixture(scope="module")
def many_pairs():
    rng = np.random.default_rng(0)
    y0s, y1s = zip(*(_rigid_body_pairs(y, 10) for y in rng.uniform(-2, 2, size=(8, 3))))
    return np.concatenate(y0s), np.concatenate(y1s)


def _leaves(model):
    """The weights (array leaves) of a model."""
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_array))]


def _assert_same_weights(a, b):
    la, lb = _leaves(a), _leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        assert x.dtype == y.dtype and np.array_equal(x, y)


# The Adam stages of this file come in few settings (network, epochs, learning rate, batches): a
# compiled chunk of epochs is a program of these, and the same program is not compiled twice
# (JAX's compilation cache, shared by the test workers).
ADAM_200 = learn.Adam(200, learning_rate=1e-2, log_every=1)  # LPNet(8, 8), MLPBaseline(8, 8)
ADAM_20 = learn.Adam(20, log_every=1)  # LPNet(4,); the default learning rate, as `epochs=20` has


@pytest.fixture(scope="module")
def fitted(rb, pairs):
    net = learn.LPNet(rb, hidden=(8, 8), key=0)
    return learn.fit(net, pairs, h=H, optimiser=ADAM_200, progress=False)


def test_lpnet_fit_decreases_loss_and_keeps_best(rb, fitted):
    model, record = fitted
    hist = record.history
    assert len(hist["epoch"]) == 200
    assert hist["train_loss"][-1] < 0.1 * hist["train_loss"][0]
    assert model.h == record.h == H and record.wall_time_s > 0
    assert record.model == "LPNet" and record.loss == "state" and record.n_train + record.n_val == 120
    assert [s.optimiser for s in record.stages] == ["Adam"] and record.stages[0].iterations == 200
    # the kept weights are the best-validation ones (not the last)
    assert record.val_loss <= np.min(hist["val_loss"]) * (1 + 1e-12)
    assert np.isfinite(record.train_loss)
    # and the fitted map still conserves the Casimir
    y = np.asarray(model.rollout(np.array([0.43, 1.33, -0.21]), 1000))
    C = np.sum(y**2, -1)
    assert np.max(np.abs(C - C[0])) < 1e-12


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_lpnet_alpha_loss_and_minibatches(rb, pairs):
    net = learn.LPNet(rb, hidden=(8,), key=1)
    adam = learn.Adam(50, learning_rate=1e-2, final_learning_rate=1e-3, batch_size=32, log_every=1)
    _, record = learn.fit(net, pairs, h=H, optimiser=adam, loss="alpha", normalise=True, progress=False)
    assert record.history["train_loss"][-1] < record.history["train_loss"][0]
    assert np.isfinite(record.val_loss)
    assert record.loss == "alpha" and record.normalise


def test_save_load_round_trip_is_bit_identical(tmp_path, rb, fitted):
    model, record = fitted
    path = tmp_path / "net.h5"
    model.save(path)
    loaded = learn.LPNet.load(path, rb)
    _assert_same_weights(model, loaded)
    assert loaded.h == model.h and loaded.hyperparameters() == model.hyperparameters()
    record.save(tmp_path / "record.h5")
    loaded_record = learn.TrainingRecord.load(tmp_path / "record.h5")
    assert loaded_record.val_loss == record.val_loss
    np.testing.assert_array_equal(loaded_record.history["val_loss"], record.history["val_loss"])
    y0 = np.array([0.43, 1.33, -0.21])
    # 1000 steps: the length of the fixture test's rollout, one compiled program for both
    np.testing.assert_array_equal(np.asarray(loaded.rollout(y0, 1000)), np.asarray(model.rollout(y0, 1000)))
    with pytest.raises(ValueError, match="GLPNet"):
        learn.GLPNet.load(path, rb)
    with pytest.raises(ValueError, match="system"):
        learn.LPNet.load(path, lp.systems.RigidBody(inertia=(1.0, 2.0, 4.0)))
    with pytest.raises(ValueError, match="TrainingRecord"):
        learn.TrainingRecord.load(path)


# seeded mini-batches (E4's sweep: their shuffles resume too) and full batch, both with -m slow; an Adam
# fit resumed from its checkpoint runs by default in test_distributed.py (an interrupted sweep point)
@pytest.mark.parametrize("batch_size", [pytest.param(None, marks=pytest.mark.slow), pytest.param(32, marks=pytest.mark.slow)])
def test_checkpoint_resume_continues(tmp_path, rb, pairs, monkeypatch, batch_size):
    import learn._files as ckpt
    import learn._solvers._adam as training

    monkeypatch.setattr(training, "CHUNK", 50)
    adam = learn.Adam(150, learning_rate=1e-2, batch_size=batch_size)
    kwargs = {"h": H, "optimiser": adam, "progress": False}
    net = learn.LPNet(rb, hidden=(4,), key=2)
    straight, straight_record = learn.fit(net, pairs, checkpoint=learn.Checkpoint(tmp_path / "a.h5", every=50), **kwargs)

    path = tmp_path / "b.h5"
    write = ckpt.write
    calls = []

    def interrupted(*args, **kw):
        write(*args, **kw)
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(ckpt, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        learn.fit(net, pairs, checkpoint=learn.Checkpoint(path, every=50), **kwargs)
    monkeypatch.setattr(ckpt, "write", write)
    assert calls == [1]
    assert learn.LPNet.load(path, rb).h == H  # a valid file after the interruption
    resume = learn.Checkpoint(path, every=50, resume=True)
    resumed, resumed_record = learn.fit(net, pairs, checkpoint=resume, **kwargs)
    _assert_same_weights(straight, resumed)
    assert resumed_record.history.keys() == straight_record.history.keys()
    for key in straight_record.history:
        assert np.array_equal(straight_record.history[key], resumed_record.history[key], equal_nan=True)
    assert resumed_record.val_loss == straight_record.val_loss
    with pytest.raises(ValueError, match="learning_rate"):
        learn.fit(net, pairs, checkpoint=resume, **{**kwargs, "optimiser": learn.Adam(150, learning_rate=5e-3)})
    # Adam's checkpoint does not depend on the refinement that follows it
    _, refined = learn.fit(net, pairs, checkpoint=resume, **{**kwargs, "optimiser": (adam, learn.KeepIfBetter(learn.ScipyLBFGSB(5)))})
    assert refined.stages[-1].details["val_loss_before"] == resumed_record.val_loss


def test_fit_accepts_trajectories(rb, pairs):
    integrators = pytest.importorskip("integrators")
    states = np.concatenate([pairs[0], pairs[1][-1:]])
    data = integrators.Trajectories(states, H, rb)
    kwargs = {"optimiser": ADAM_20, "progress": False}
    net = learn.LPNet(rb, hidden=(4,), key=3)
    a, record = learn.fit(net, data, **kwargs)
    b, _ = learn.fit(net, pairs, h=H, **kwargs)  # same seeded split of the same pairs
    assert a.h == record.h == H
    # fit returns a new model and leaves its argument alone
    assert net.h is None
    _assert_same_weights(net, learn.LPNet(rb, hidden=(4,), key=3))
    _assert_same_weights(a, b)
    with pytest.raises(ValueError, match="h="):
        learn.fit(net, data, h=0.2, **kwargs)
    # `epochs=N` is short for `optimiser=learn.Adam(N)`
    c, _ = learn.fit(net, data, epochs=20, progress=False)
    d, _ = learn.fit(net, data, optimiser=learn.Adam(20), progress=False)
    _assert_same_weights(c, d)


def test_fit_bad_inputs_name_the_argument(rb, pairs):
    net = learn.LPNet(rb, hidden=(4,))
    adam = learn.Adam(2)
    with pytest.raises(ValueError, match="epochs"):
        learn.fit(net, pairs, h=H, epochs=0)
    with pytest.raises(ValueError, match="Adam.epochs"):
        learn.Adam(0)
    with pytest.raises(ValueError, match="h"):
        learn.fit(net, pairs, optimiser=adam)
    with pytest.raises(ValueError, match="h"):
        learn.fit(net, pairs, h=0.0, optimiser=adam)
    with pytest.raises(ValueError, match="validation_fraction"):
        learn.fit(net, pairs, h=H, validation_fraction=1.5, optimiser=adam)
    with pytest.raises(ValueError, match="loss"):
        learn.fit(net, pairs, h=H, loss="energy", optimiser=adam)
    with pytest.raises(ValueError, match="y0"):
        learn.fit(net, (pairs[0][:, :2], pairs[1]), h=H, optimiser=adam)
    with pytest.raises(ValueError, match="y1"):
        learn.fit(net, (pairs[0], np.full_like(pairs[1], np.inf)), h=H, optimiser=adam)
    # resuming needs a Checkpoint for exactly one Adam stage
    with pytest.raises(TypeError, match="checkpoint"):
        learn.fit(net, pairs, h=H, optimiser=adam, checkpoint="ckpt.h5")
    with pytest.raises(ValueError, match="checkpoint"):
        learn.fit(net, pairs, h=H, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(2)), checkpoint=learn.Checkpoint("c.h5", resume=True))
    with pytest.raises(TypeError, match="Checkpoint.path"):
        learn.Checkpoint(3)
    with pytest.raises(TypeError, match="optimiser"):
        learn.fit(net, pairs, h=H, optimiser="adam")
    with pytest.raises(ValueError, match="epochs.*optimiser"):
        learn.fit(net, pairs, h=H, epochs=2, optimiser=adam)
    with pytest.raises(TypeError, match="model"):
        learn.fit("LPNet", pairs, h=H, optimiser=adam)
    with pytest.raises(ValueError, match="alpha"):
        learn.fit(learn.MLPBaseline(rb, hidden=(4,)), pairs, h=H, loss="alpha", optimiser=adam)
    with pytest.raises(ValueError, match="normalise"):
        learn.fit(learn.GLPNet(rb), pairs, h=H, normalise=True, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(2)))
    with pytest.raises(ValueError, match="learn.WarmStart: a LPNet has no warm start"):
        learn.fit(net, pairs, h=H, optimiser=learn.WarmStart(learn.ScipyLBFGSB(2)))
    with pytest.raises(ValueError, match="h=0.2"):  # the model's step against the data's
        learn.fit(learn.LPNet(rb, hidden=(4,), h=0.2), pairs, h=H, optimiser=adam)


# 12 s each; BFGS G-LPNet fits run by default in tests/test_any_algebra.py and test_learn_warm_start.py.
@pytest.mark.slow
@pytest.mark.parametrize("solver", [learn.ScipyBFGS, learn.OptaxLBFGS])
def test_glpnet_fit_decreases_loss(tmp_path, rb, many_pairs, solver):
    g = learn.GLPNet(rb, n_modules=6, key=0)
    # the paper's G-LPNet training: quasi-Newton with the identity warm start on all pairs
    stage = learn.KeepIfBetter(learn.Restarts(learn.WarmStart(solver(100)), 2))
    f, record = learn.fit(g, many_pairs, h=H, optimiser=stage, validation_fraction=0.0, progress=False)
    hist = record.history["train_loss"]
    assert hist[-1] < 0.1 * hist[0]
    assert record.n_val == 0 and np.isnan(record.val_loss)
    assert record.train_loss <= min(record.stages[-1].details["start_train_losses"]) + 0.0
    y = np.random.default_rng(5).uniform(-1, 1, (5, 3))
    assert np.max(np.asarray(f.poisson_defect(y))) < 1e-12
    f.save(tmp_path / "g.h5")
    loaded = learn.GLPNet.load(tmp_path / "g.h5", rb)
    _assert_same_weights(f, loaded)


def test_baseline_fit_and_casimir_drift(tmp_path, rb, pairs):
    base = learn.MLPBaseline(rb, hidden=(8, 8), key=0)
    f, record = learn.fit(base, pairs, h=H, optimiser=ADAM_200, progress=False)
    assert record.history["train_loss"][-1] < 0.1 * record.history["train_loss"][0]
    y = np.asarray(f.rollout(pairs[0][0], 500))
    C = np.sum(y**2, -1)
    assert np.max(np.abs(C - C[0])) > 1e-8  # no structure: the Casimir drifts
    f.save(tmp_path / "b.h5")
    loaded = learn.MLPBaseline.load(tmp_path / "b.h5", rb)
    np.testing.assert_array_equal(np.asarray(jax.vmap(loaded.step)(y[:3])), np.asarray(jax.vmap(f.step)(y[:3])))


# the LPNet by default; the baseline's refinement (the same stage on another network) with -m slow
@pytest.mark.parametrize("cls", [learn.LPNet, pytest.param(learn.MLPBaseline, marks=pytest.mark.slow)])
def test_quasi_newton_refinement_lowers_the_loss(rb, pairs, cls):
    net = cls(rb, hidden=(8, 8), key=0)
    stages = (ADAM_200, learn.KeepIfBetter(learn.ScipyLBFGSB(150)))
    _, record = learn.fit(net, pairs, h=H, optimiser=stages, progress=False)
    adam, refine = record.stages
    assert (adam.optimiser, refine.optimiser) == ("Adam", "ScipyLBFGSB")
    assert refine.kept and refine.iterations > 0
    # the refinement starts from Adam's weights
    assert refine.details["val_loss_before"] == adam.val_loss
    # 150 L-BFGS-B iterations go well below what 200 Adam epochs reach (measured: by 1e5 for
    # the LPNet, by 20 for the baseline)
    assert record.val_loss < 0.1 * refine.details["val_loss_before"]
    assert record.train_loss < 0.1 * refine.details["train_loss_before"]
    hist = record.history
    n = refine.iterations
    assert len(hist["epoch"]) == 200 + n
    np.testing.assert_array_equal(hist["epoch"][:200], np.arange(200))
    assert np.all(np.diff(hist["epoch"]) > 0)  # the iterations are numbered on from Adam's epochs
    assert np.all(np.isnan(hist["val_loss"][200:]))  # not measured by the quasi-Newton stage
    assert hist["train_loss"][-1] == pytest.approx(record.train_loss, rel=1e-6)


@pytest.mark.slow  # the numbering after Adam's epochs by default in test_quasi_newton_refinement_lowers_the_loss
def test_refinement_iterations_numbered_after_adam_epochs(rb, pairs):
    stages = (ADAM_20, learn.KeepIfBetter(learn.ScipyLBFGSB(5)))
    _, record = learn.fit(learn.LPNet(rb, hidden=(4,), key=0), pairs, h=H, optimiser=stages, progress=False)
    n = record.stages[-1].iterations
    # Adam's entry e is the loss after e updates; iteration k of the refinement comes after all
    # 20 epochs and k iterations: 20 + k
    np.testing.assert_array_equal(record.history["epoch"][20:], 20 + np.arange(1, n + 1))


class _Line(eqx.Module):
    w: jax.Array


class _LineLoss(learn.AbstractLeastSquares):
    """Residuals w x - t of a line through the origin on data (x, t)."""

    def residuals(self, y, args):
        x, t = args
        return y.w * x - t

    def count(self, y, args):
        return int(args[0].size)

    def __call__(self, y, args):
        return jnp.mean(self.residuals(y, args) ** 2)


def test_refinement_is_dropped_when_validation_gets_worse():
    """Training targets y = 2x, validation targets y = 0: minimising the training loss from
    w = 0 raises the validation loss, so the quasi-Newton stage must keep the starting
    weights."""
    x = jnp.linspace(-1, 1, 20)
    start = _Line(jnp.asarray(0.0))
    problem = ToyProblem(_LineLoss(), start, (x, 2 * x), (x, 0 * x))
    result = learn.KeepIfBetter(learn.ScipyLBFGSB(20)).run(problem, learn.Context())
    kept, rec = result.y, result.record
    assert not rec.kept
    assert float(kept.w) == 0.0
    # the minimiser alone does lower the training loss; the validation loss decided against it
    alone = learn.ScipyLBFGSB(20).run(problem, learn.Context()).record
    assert alone.train_loss < rec.details["train_loss_before"] and alone.val_loss > rec.details["val_loss_before"]
    assert rec.train_loss == rec.details["train_loss_before"] and rec.val_loss == rec.details["val_loss_before"]
    # without validation data the training loss decides, and w reaches 2
    result = learn.KeepIfBetter(learn.ScipyBFGS(20)).run(dataclasses.replace(problem, validation=None), learn.Context())
    assert result.record.kept and float(result.y.w) == pytest.approx(2.0, rel=1e-10)
    # Levenberg-Marquardt solves the same least-squares problem (one step for a linear one)
    result = learn.KeepIfBetter(learn.LevenbergMarquardt(5)).run(dataclasses.replace(problem, validation=None),
                                                                 learn.Context())
    assert result.record.kept and float(result.y.w) == pytest.approx(2.0, rel=1e-12)


def test_refinement_bad_arguments():
    with pytest.raises(ValueError, match="ScipyLBFGSB.iterations"):
        learn.ScipyLBFGSB(-1)
    with pytest.raises(TypeError, match="OptaxLBFGS.iterations"):
        learn.OptaxLBFGS(1.5)
    with pytest.raises(ValueError, match="ScipyBFGS.rtol"):
        learn.ScipyBFGS(5, rtol=1.0)
    with pytest.raises(ValueError, match="Restarts.starts"):
        learn.Restarts(learn.ScipyBFGS(5), 0)


def test_refine_only_continues_from_the_current_weights(rb, pairs, fitted):
    model, record = fitted
    _, again_record = learn.fit(model, pairs, h=H, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(50)), progress=False)
    (stage,) = again_record.stages
    # the starting point is the fitted network: its losses are fitted's
    assert stage.details["val_loss_before"] == pytest.approx(record.val_loss, rel=1e-12)
    assert stage.optimiser == "ScipyLBFGSB" and len(again_record.history["epoch"]) == stage.iterations
    assert again_record.val_loss < record.val_loss
    with pytest.raises(TypeError, match="optimiser"):  # nothing to train
        learn.fit(model, pairs, h=H, optimiser=())


def test_training_record_round_trip(tmp_path, rb, pairs):
    stages = (ADAM_20, learn.KeepIfBetter(learn.ScipyLBFGSB(5)))
    _, record = learn.fit(learn.LPNet(rb, hidden=(4,), key=0), pairs, h=H, optimiser=stages, progress=False)
    record.save(tmp_path / "record.h5")
    loaded = learn.TrainingRecord.load(tmp_path / "record.h5")
    for field in dataclasses.fields(learn.TrainingRecord):
        if field.name != "history":
            assert getattr(loaded, field.name) == getattr(record, field.name), field.name
    assert loaded.history.keys() == record.history.keys()
    for key, value in record.history.items():
        assert loaded.history[key].dtype == value.dtype
        assert np.array_equal(loaded.history[key], value, equal_nan=True), key


# SciPy's L-BFGS-B (every iteration reported) by default; optax's L-BFGS (its chunks) with -m slow
@pytest.mark.parametrize("solver", [learn.ScipyLBFGSB, pytest.param(learn.OptaxLBFGS, marks=pytest.mark.slow)])
def test_callback_follows_every_stage_as_it_runs(rb, pairs, solver):
    """`callback` sees each optimiser's progress while it runs (what a live plot or a
    time-to-figure measurement needs): Adam's chunks, every quasi-Newton iteration (SciPy) or
    chunk (optax), every Levenberg-Marquardt step; the iteration counts rise within a stage,
    and the losses reported inside a second-order stage are its history's."""
    seen: list[learn.Progress] = []
    stages = (ADAM_20, learn.KeepIfBetter(solver(12)))
    _, record = learn.fit(learn.LPNet(rb, hidden=(4,), key=0), pairs, h=H, optimiser=stages, progress=False,
                          callback=seen.append)
    assert {p.stage for p in seen} == {0, 1}
    assert all(isinstance(p, learn.Progress) for p in seen)
    qn = [p for p in seen if p.stage == 1]
    assert all(p.optimiser == solver.__name__ and p.total == 12 for p in qn)
    inside = [p for p in qn if np.isnan(p.val_loss)]  # during the run; the last one is the start's result
    assert len(inside) >= (record.stages[1].iterations if solver is learn.ScipyLBFGSB else 1)
    assert all(np.diff([p.iteration for p in inside]) > 0)
    history = record.history["train_loss"][20:]
    for p in inside:
        assert p.train_loss == history[p.iteration - 1]
    assert qn[-1].iteration == 12 and np.isfinite(qn[-1].val_loss)

    pairs_small = (pairs[0][:20], pairs[1][:20])
    glp = learn.GLPNet(rb, n_modules=2, key=0)
    seen.clear()
    _, record = learn.fit(glp, pairs_small, h=H, optimiser=learn.LevenbergMarquardt(5, rtol=0.0), progress=False,
                          callback=seen.append)
    steps = [p for p in seen if np.isnan(p.val_loss)]
    assert [p.iteration for p in steps] == list(range(1, record.stages[0].iterations + 1))
    np.testing.assert_array_equal([p.train_loss for p in steps], record.history["train_loss"])


def test_scipy_quasi_newton_runs_numpy_blas_on_one_thread(rb, pairs, monkeypatch):
    # A multi-threaded BLAS pool spins after L-BFGS-B's host updates on the cores that the next
    # JAX gradient needs (BENCHMARKS.md, "BLAS threads in the SciPy loop"): inside SciPy's loop
    # (its own thread, handing iterations to the shared loop) the pool has one thread, and the
    # caller's setting is back afterwards.
    import scipy.optimize
    import threadpoolctl

    def blas_threads():
        return {p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"}

    inside, minimize = [], scipy.optimize.minimize

    def watched(*args, callback, **kwargs):
        def seen(intermediate_result):
            inside.append(blas_threads())
            return callback(intermediate_result)

        return minimize(*args, callback=seen, **kwargs)

    monkeypatch.setattr(scipy.optimize, "minimize", watched)
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        if blas_threads() != {2}:
            pytest.skip("NumPy's BLAS cannot be set to 2 threads here (not visible to threadpoolctl, or serial)")
        learn.fit(learn.LPNet(rb, hidden=(4,), key=0), pairs, h=H, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(5)),
                  progress=False)
        assert blas_threads() == {2}
    assert len(inside) == 5 and all(t == {1} for t in inside)


class _WeightedStateLoss(learn.AbstractPairsLoss):
    """A loss of the user's: the state residuals weighted per component. One class, no edit of
    `learn.fit` or of any solver."""

    weights: jax.Array

    def pair_residuals(self, model, y0, targets):
        return (jax.vmap(model.step)(y0) - targets) * self.weights

    @property
    def name(self):
        return "weighted state"


# by default through Levenberg-Marquardt (residuals); BFGS (the loss's gradient) and Adam (the same
# gradient, minibatched) with -m slow
@pytest.mark.parametrize("optimiser", [pytest.param(learn.Adam(200, learning_rate=1e-2), marks=pytest.mark.slow),
                                       pytest.param(learn.KeepIfBetter(learn.ScipyBFGS(60)), marks=pytest.mark.slow),
                                       learn.LevenbergMarquardt(20)],
                         ids=["Adam", "BFGS", "Levenberg-Marquardt"])
def test_a_new_loss_is_one_class_and_trains_through_every_solver(rb, pairs, optimiser):
    weights = jnp.array([1.0, 10.0, 100.0])
    loss = _WeightedStateLoss(weights)
    net = learn.GLPNet(rb, n_modules=3, key=0, h=H)
    y0, y1 = (jnp.asarray(a) for a in pairs)

    def by_hand(model):  # the weighted mean square, written out independently
        return float(jnp.mean(((jax.vmap(model.step)(y0) - y1) * weights) ** 2))

    fitted, record = learn.fit(net, pairs, h=H, loss=loss, optimiser=optimiser, validation_fraction=0.0,
                               progress=False)
    assert record.loss == "weighted state"
    # the loss minimised is the weighted one: the record's figure is it, not the plain state loss
    # (they differ by ~10^3 here); the same sums in another compiled program, a few eps apart
    assert record.train_loss == pytest.approx(by_hand(fitted), rel=1e-10)
    assert record.train_loss != pytest.approx(float(learn.state_mse(fitted, y0, y1)), rel=0.5)
    assert record.train_loss < 0.5 * by_hand(net)
