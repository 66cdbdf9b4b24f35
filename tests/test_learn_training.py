"""learn training: Adam fits (LPNet, MLPBaseline), BFGS fits (GLPNet), best-validation weights,
HDF5 save/load and checkpoint resume."""

import jax
import numpy as np
import pytest
import scipy.integrate

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
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(model)]


@pytest.fixture(scope="module")
def fitted(rb, pairs):
    net = learn.LPNet(rb, hidden=(8, 8), key=0)
    return net.fit(pairs, h=H, epochs=300, learning_rate=2e-2, progress=False, log_every=1)


def test_lpnet_fit_decreases_loss_and_keeps_best(fitted):
    hist = fitted.history
    assert len(hist["epoch"]) == 300
    assert hist["train_loss"][-1] < 0.1 * hist["train_loss"][0]
    assert fitted.h == H and fitted.wall_time_s > 0
    # the kept weights are the best-validation ones (not the last)
    assert fitted.val_loss <= np.min(hist["val_loss"]) * (1 + 1e-12)
    assert np.isfinite(fitted.train_loss)
    # and the fitted map still conserves the Casimir
    y = np.asarray(fitted.rollout(np.array([0.43, 1.33, -0.21]), 1000))
    C = np.sum(y**2, -1)
    assert np.max(np.abs(C - C[0])) < 1e-12


def test_lpnet_alpha_loss_and_minibatches(rb, pairs):
    net = learn.LPNet(rb, hidden=(8,), key=1)
    f = net.fit(pairs, h=H, epochs=50, loss="alpha", batch_size=32, learning_rate=1e-2,
                final_learning_rate=1e-3, progress=False, log_every=1, normalise=True)
    assert f.history["train_loss"][-1] < f.history["train_loss"][0]
    assert np.isfinite(f.val_loss)


def test_save_load_round_trip_is_bit_identical(tmp_path, rb, fitted):
    path = tmp_path / "net.h5"
    fitted.save(path)
    loaded = learn.LPNet.load(path, rb)
    for a, b in zip(_leaves(fitted), _leaves(loaded)):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert loaded.h == fitted.h and loaded.hyperparameters() == fitted.hyperparameters()
    assert loaded.val_loss == fitted.val_loss
    np.testing.assert_array_equal(loaded.history["val_loss"], fitted.history["val_loss"])
    y0 = np.array([0.43, 1.33, -0.21])
    np.testing.assert_array_equal(np.asarray(loaded.rollout(y0, 50)), np.asarray(fitted.rollout(y0, 50)))
    with pytest.raises(ValueError, match="GLPNet"):
        learn.GLPNet.load(path, rb)
    with pytest.raises(ValueError, match="system"):
        learn.LPNet.load(path, lp.systems.RigidBody(inertia=(1.0, 2.0, 4.0)))


def test_checkpoint_resume_continues(tmp_path, rb, pairs, monkeypatch):
    import learn._checkpoint as ckpt
    import learn._training as training

    monkeypatch.setattr(training, "CHUNK", 50)
    kwargs = {"h": H, "epochs": 150, "learning_rate": 1e-2, "progress": False, "checkpoint_every": 50}
    net = learn.LPNet(rb, hidden=(4,), key=2)
    straight = net.fit(pairs, checkpoint=tmp_path / "a.h5", **kwargs)

    path = tmp_path / "b.h5"
    write = ckpt.write
    calls = []

    def interrupted(*args, **kw):
        write(*args, **kw)
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(ckpt, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        net.fit(pairs, checkpoint=path, **kwargs)
    monkeypatch.setattr(ckpt, "write", write)
    assert learn.LPNet.load(path, rb).h == H  # a valid file after the interruption
    resumed = net.fit(pairs, checkpoint=path, resume=True, **kwargs)
    for a, b in zip(_leaves(straight), _leaves(resumed)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(straight.history["train_loss"], resumed.history["train_loss"])
    with pytest.raises(ValueError, match="learning_rate"):
        net.fit(pairs, checkpoint=path, resume=True, **{**kwargs, "learning_rate": 5e-3})
    # Adam's checkpoint does not depend on the refinement that follows it
    refined = net.fit(pairs, checkpoint=path, resume=True, refine_iterations=5, **kwargs)
    assert refined.record.info["val_loss_before_refine"] == resumed.val_loss


def test_fit_accepts_trajectories(rb, pairs):
    integrators = pytest.importorskip("integrators")
    states = np.concatenate([pairs[0], pairs[1][-1:]])
    data = integrators.Trajectories(states, H, rb)
    kwargs = {"epochs": 20, "learning_rate": 1e-2, "progress": False}
    net = learn.LPNet(rb, hidden=(4,), key=3)
    a = net.fit(data, **kwargs)
    b = net.fit(pairs, h=H, **kwargs)  # same seeded split of the same pairs
    assert a.h == H
    for x, y in zip(_leaves(a), _leaves(b)):
        np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError, match="h="):
        net.fit(data, h=0.2, **kwargs)


def test_fit_bad_inputs_name_the_argument(rb, pairs):
    net = learn.LPNet(rb, hidden=(4,))
    with pytest.raises(ValueError, match="epochs"):
        net.fit(pairs, h=H, epochs=0)
    with pytest.raises(ValueError, match="h"):
        net.fit(pairs)
    with pytest.raises(ValueError, match="h"):
        net.fit(pairs, h=0.0)
    with pytest.raises(ValueError, match="validation_fraction"):
        net.fit(pairs, h=H, validation_fraction=1.5)
    with pytest.raises(ValueError, match="loss"):
        net.fit(pairs, h=H, loss="energy")
    with pytest.raises(ValueError, match="y0"):
        net.fit((pairs[0][:, :2], pairs[1]), h=H)
    with pytest.raises(ValueError, match="y1"):
        net.fit((pairs[0], np.full_like(pairs[1], np.inf)), h=H)
    with pytest.raises(ValueError, match="resume"):
        net.fit(pairs, h=H, resume=True)
    with pytest.raises(ValueError, match="method"):
        learn.GLPNet(rb).fit(pairs, h=H, method="adam")


@pytest.mark.parametrize("method", ["bfgs", pytest.param("lbfgs", marks=pytest.mark.slow)])
def test_glpnet_fit_decreases_loss(tmp_path, rb, many_pairs, method):
    g = learn.GLPNet(rb, n_modules=6, key=0)
    f = g.fit(many_pairs, h=H, method=method, max_iter=100, restarts=2, progress=False)
    hist = f.history["train_loss"]
    assert hist[-1] < 0.1 * hist[0]
    assert f.train_loss <= min(f.record.info["restart_train_losses"]) + 0.0
    y = np.random.default_rng(5).uniform(-1, 1, (5, 3))
    assert np.max(np.asarray(f.poisson_defect(y))) < 1e-12
    f.save(tmp_path / "g.h5")
    loaded = learn.GLPNet.load(tmp_path / "g.h5", rb)
    for a, b in zip(_leaves(f), _leaves(loaded)):
        np.testing.assert_array_equal(a, b)


def test_baseline_fit_and_casimir_drift(tmp_path, rb, pairs):
    base = learn.MLPBaseline(rb, hidden=(8, 8), key=0)
    f = base.fit(pairs, h=H, epochs=200, learning_rate=1e-2, progress=False)
    assert f.history["train_loss"][-1] < 0.1 * f.history["train_loss"][0]
    y = np.asarray(f.rollout(pairs[0][0], 500))
    C = np.sum(y**2, -1)
    assert np.max(np.abs(C - C[0])) > 1e-8  # no structure: the Casimir drifts
    f.save(tmp_path / "b.h5")
    loaded = learn.MLPBaseline.load(tmp_path / "b.h5", rb)
    np.testing.assert_array_equal(np.asarray(loaded.step(y[:3])), np.asarray(f.step(y[:3])))


@pytest.mark.parametrize("cls", [learn.LPNet, learn.MLPBaseline])
def test_quasi_newton_refinement_lowers_the_loss(rb, pairs, cls):
    net = cls(rb, hidden=(8, 8), key=0)
    f = net.fit(pairs, h=H, epochs=200, learning_rate=1e-2, progress=False, log_every=1, refine_iterations=150)
    info = f.record.info
    assert info["refine_kept"] and info["refine_iterations_run"] > 0
    # 150 L-BFGS-B iterations go well below what 200 Adam epochs reach (measured: by 1e5 for
    # the LPNet, by 20 for the baseline)
    assert f.val_loss < 0.1 * info["val_loss_before_refine"]
    assert f.train_loss < 0.1 * info["train_loss_before_refine"]
    hist = f.history
    n = info["refine_iterations_run"]
    assert len(hist["epoch"]) == 200 + n
    np.testing.assert_array_equal(hist["epoch"][200:], 200 + np.arange(1, n + 1))
    assert hist["train_loss"][-1] == pytest.approx(f.train_loss, rel=1e-6)


def test_refinement_is_dropped_when_validation_gets_worse():
    """Training targets y = 2x, validation targets y = 0: minimising the training loss from
    w = 0 raises the validation loss, so `refine` must keep the starting weights."""
    import equinox as eqx
    import jax.numpy as jnp

    from learn._training import refine

    class Line(eqx.Module):
        w: jax.Array

    def loss(m, x, t):
        return jnp.mean((m.w * x - t) ** 2)

    x = np.linspace(-1, 1, 20)
    start = Line(jnp.asarray(0.0))
    kept, info = refine(start, (x, 2 * x), (x, 0 * x), loss, iterations=20, method="lbfgsb", progress=False, desc="")
    assert not info["kept"] and info["criterion_after"] > info["criterion_before"]
    assert float(kept.w) == 0.0
    # without validation data the training loss decides, and w reaches 2
    kept, info = refine(start, (x, 2 * x), (x[:0], x[:0]), loss, iterations=20, method="bfgs", progress=False, desc="")
    assert info["kept"] and float(kept.w) == pytest.approx(2.0, rel=1e-10)


def test_refinement_bad_arguments(rb, pairs):
    net = learn.LPNet(rb, hidden=(4,))
    with pytest.raises(ValueError, match="refine_iterations"):
        net.fit(pairs, h=H, epochs=2, refine_iterations=-1)
    with pytest.raises(TypeError, match="refine_iterations"):
        net.fit(pairs, h=H, epochs=2, refine_iterations=1.5)
    with pytest.raises(ValueError, match="method"):
        net.fit(pairs, h=H, epochs=2, refine_method="newton")


def test_refine_only_continues_from_the_current_weights(rb, pairs, fitted):
    again = fitted.fit(pairs, h=H, epochs=0, refine_iterations=50, progress=False)
    info = again.record.info
    # the starting point is the fitted network: its losses are fitted's
    assert info["val_loss_before_refine"] == pytest.approx(fitted.val_loss, rel=1e-12)
    assert info["epochs_run"] == 0 and len(again.history["epoch"]) == info["refine_iterations_run"]
    assert again.val_loss < fitted.val_loss
    with pytest.raises(ValueError, match="nothing to train"):
        fitted.fit(pairs, h=H, epochs=0)
