"""learn.fit_stream_operator: the spectrum of a fluid's stream operator identified from
observed vorticity fields (Euler and quasi-geostrophic flow on the sphere, N = 8)."""

import functools
import json

import equinox as eqx
import h5py
import jax.numpy as jnp
import numpy as np
import pytest

import learn
from integrators import IsospectralMidpoint, Observations, add_field_noise
from liepoisson.systems import RigidBody, Zeitlin

N = 8
F = 10.0
L = np.arange(1, N)
TOL = 1e-13  # the stage tolerance of truth and model: the data are the model's map to this


@functools.cache
def _times():
    rng = np.random.default_rng(0)
    return [np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.12, 8))]) for _ in range(3)]


def _starts():
    system = Zeitlin(N)
    return [2 * system.random_state(j, decay=0.5, lmax=N - 1) for j in range(3)]


@functools.cache
def euler_data():
    """Zeitlin's model by `integrators.IsospectralMidpoint` (the tridiagonal Poisson solve: no
    code shared with the model's spectral one), one step per interval."""
    system = Zeitlin(N)
    method = IsospectralMidpoint(system, 0.1, tol=TOL)
    states = []
    for y, t in zip(_starts(), _times()):
        ys = [y]
        for dt in np.diff(t):
            ys.append(np.asarray(method.with_h(float(dt)).rollout(ys[-1], 1))[-1])
        states.append(np.stack(ys))
    return Observations(system, _times(), states)


@functools.cache
def quasi_geostrophic_data():
    system = Zeitlin(N)
    truth = learn.StreamOperator(system, learn.QuasiGeostrophicSpectrum(F), tol=TOL, iterations=16)
    roll = eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))
    states = [np.asarray(roll(truth, jnp.asarray(y), jnp.asarray(np.diff(t)))) for y, t in zip(_starts(), _times())]
    return Observations(system, _times(), states)


def _model(values):
    # 11 stage iterations converge on these intervals: every fit keeps them, and so shares one compilation
    return learn.StreamOperator(Zeitlin(N), learn.DegreeSpectrum(values), tol=TOL, iterations=11)


@pytest.mark.slow  # ~100 s on 2 loaded cores, mostly compiling the fit at N = 8: over the default run's budget
def test_euler_spectrum_from_exact_data():
    data = euler_data()
    assert min(np.linalg.norm(y[-1] - y[0]) / np.linalg.norm(y[0]) for y in data.states) > 0.2  # they move
    start = -(L * (L + 1.0)) * (1 + 0.2 * np.sin(L))
    start[0] = -2.0  # the gauge: degree 1 held at the truth's (the flow cannot tell; learn.DegreeSpectrum)
    fit = learn.fit_stream_operator(_model(start), data, iterations=40, rtol=1e-14, chi2_tol=0.0,
                                    standard_errors=False)  # exact data: chi^2 has no noise to stop at
    true = -(L * (L + 1.0))
    # exact data of the model's own map (to the stage tolerance 1e-13 of |W|): the misfit at the
    # truth is ~1e-13 of the field, and eigenvalues whose fields move by O(1) of their norm are
    # found to that over their sensitivity; 1e-8 leaves 1e5 for the high degrees' conditioning
    assert np.max(np.abs(fit.values - true) / np.abs(true)) <= 1e-8, fit.values
    assert fit.losses[-1] <= 1e-20 * np.mean(np.concatenate(data.states) ** 2)


@pytest.mark.slow  # the compilations are shared with the two tests above (slow too); the fit itself ~10 s
def test_quasi_geostrophic_spectrum_from_exact_data():
    start = -(L * (L + 1.0))
    start[0] = -2.0 - F  # the gauge at the truth's degree 1
    fit = learn.fit_stream_operator(_model(start), quasi_geostrophic_data(), iterations=40, rtol=1e-14,
                                    chi2_tol=0.0, standard_errors=False)
    true = -(L * (L + 1.0)) - F
    assert np.max(np.abs(fit.values - true) / np.abs(true)) <= 1e-8, fit.values  # as the Euler case


@pytest.mark.slow  # ~100 s on 2 loaded cores, mostly compiling the fit at N = 8: over the default run's budget
def test_quasi_geostrophic_spectrum_from_noisy_data_within_three_standard_errors(capsys):
    data = quasi_geostrophic_data()
    noisy = add_field_noise(data, 1e-3, seed=3)
    start = -(L * (L + 1.0))
    start[0] = -2.0 - F
    fit = learn.fit_stream_operator(_model(start), noisy, iterations=40, progress=True)
    assert fit.stopped.startswith("converged"), fit.stopped  # at the noise floor, not out of iterations
    # a negligible step made with an older J_theta is judged once more with a fresh one, then the
    # fit stops: at most one such relinearisation (judging by the state after the step, whose
    # J_theta is the step's, relinearised after every step until one was refused)
    assert capsys.readouterr().out.count("afresh (a negligible step") <= 1
    true = -(L * (L + 1.0)) - F
    se = fit.standard_errors
    assert se[0] == 0.0 and np.all(np.isfinite(se[1:])) and np.all(se[1:] > 0)
    z = np.abs(fit.values - true)[1:] / se[1:]
    assert np.all(z <= 3), z
    # the errors are of the size the standard errors say: not all far inside them either
    assert np.max(z) >= 0.1, z
    # the residuals' noise estimate matches the noise put in (1530 degrees of freedom: 2%)
    assert fit.noise == pytest.approx(noisy.metadata["noise_std"], rel=0.1)
    # chi2_tol's stop (chi^2 lowered by less than 0.01) leaves the estimate within a small part of
    # its error bar of the minimum itself (continued with only rtol = 1e-14 to stop): a step that
    # lowers chi^2 by eps moves it by about sqrt(eps) = 0.1 standard errors; 0.5 leaves room for
    # the few iterations before the stop each contributing
    tight = learn.fit_stream_operator(fit.model, noisy, iterations=40, rtol=1e-14, chi2_tol=0.0,
                                      starts=fit.starts, standard_errors=False)
    moved = np.abs(tight.values - fit.values)[1:] / se[1:]
    assert np.max(moved) <= 0.5, moved
    # the learned rollout keeps every Casimir tr(iW)^k: unitary conjugations, whatever was fitted
    model = fit.model
    rng = np.random.default_rng(1)
    intervals = jnp.asarray(rng.uniform(0.05, 0.12, 30))
    ys = np.asarray(eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))(model, jnp.asarray(fit.starts[0]),
                                                                              intervals))
    W0, W1 = (np.asarray(model.system.algebra.matrix(y)) for y in (ys[0], ys[-1]))
    e0, e1 = np.linalg.eigvalsh(1j * W0), np.linalg.eigvalsh(1j * W1)
    for k in range(1, N + 1):
        # 30 unitary conjugations, each a rounding of a few eps of |W| (a random walk), the
        # k-th power multiplying it by k: 1e-13 of sum |e|^k
        assert abs(np.sum(e1**k) - np.sum(e0**k)) <= 1e-13 * np.sum(np.abs(e0) ** k), k


@pytest.mark.slow
def test_the_true_family_is_identified():
    """The limit: the quasi-geostrophic family fitted to its own data finds F."""
    model = learn.StreamOperator(Zeitlin(N), learn.QuasiGeostrophicSpectrum(0.0), tol=TOL, iterations=11)
    fit = learn.fit_stream_operator(model, quasi_geostrophic_data(), iterations=40, rtol=1e-14, chi2_tol=0.0,
                                    standard_errors=False)
    assert abs(float(fit.values[0]) - F) <= 1e-8 * F  # as the exact cases above


@pytest.mark.slow  # two fits at N = 6, each compiled
def test_the_fit_keeps_the_order_and_order_4_removes_the_steps_bias():
    """On the exact flow (heyoka at machine precision), one step per interval: the QG family's
    F, 0 in truth, is biased by the step's error, O(h^2) at order 2; at order 4 (the same
    intervals, five midpoints a step) the bias is 100 times smaller. Fails if the fit
    drops the model's order."""
    from integrators import ground_truth

    n = 6
    system = Zeitlin(n)
    rng = np.random.default_rng(5)
    times, states = [], []
    for j in range(2):
        t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.08, 0.12, 8))])
        y = system.random_state(10 + j, decay=0.5, lmax=n - 1)
        ys = [y]
        for dt in np.diff(t):
            ys.append(ground_truth(system, ys[-1], float(dt), 1, progress=False).states[0, -1])
        times.append(t)
        states.append(np.stack(ys))
    data = Observations(system, times, states)
    biases = {}
    for order, composition in ((2, None), (4, "Suzuki")):
        model = learn.StreamOperator(system, learn.QuasiGeostrophicSpectrum(0.3), composition=composition, tol=TOL,
                                     iterations=12)
        fit = learn.fit_stream_operator(model, data, iterations=30, rtol=1e-14, chi2_tol=0.0, standard_errors=False)
        assert fit.model.composition == model.composition and fit.model.order == order
        biases[order] = abs(float(fit.values[0]))
    # measured: 8.0e-3 at order 2, 7.0e-6 at order 4
    assert biases[2] > 1e-4, biases  # the midpoint's bias is there to be removed
    assert biases[4] <= biases[2] / 100, biases


def test_bad_input():
    data = euler_data()
    with pytest.raises(TypeError, match="model must be a learn.StreamOperator"):
        learn.fit_stream_operator(learn.IsospectralPolynomial(Zeitlin(N)), data)
    with pytest.raises(TypeError, match="data must be integrators.Observations"):
        learn.fit_stream_operator(_model(-(L * (L + 1.0))), (data.states, data.times))
    with pytest.raises(ValueError, match=r"data holds fields of N = 8 \(dimension 64\); the model is for N = 6"):
        learn.fit_stream_operator(learn.StreamOperator(Zeitlin(6)), data)
    rigid = Observations(RigidBody(), [np.arange(3.0)], [np.ones((3, 3))])
    with pytest.raises(ValueError, match="data must be observations of liepoisson.systems.Zeitlin"):
        learn.fit_stream_operator(_model(-(L * (L + 1.0))), rigid)
    with pytest.raises(ValueError, match="max_step must be"):
        learn.fit_stream_operator(_model(-(L * (L + 1.0))), data, max_step=-1.0)
    with pytest.raises(ValueError, match="rtol must be a number in"):
        learn.fit_stream_operator(_model(-(L * (L + 1.0))), data, rtol=2.0)
    for bad in (-0.1, float("nan"), float("inf"), "0.01", True):
        with pytest.raises(ValueError, match="chi2_tol must be a finite number >= 0"):
            learn.fit_stream_operator(_model(-(L * (L + 1.0))), data, chi2_tol=bad)
    for name in ("cg_rtol", "se_rtol"):
        with pytest.raises(ValueError, match=f"{name} must be below 1"):
            learn.fit_stream_operator(_model(-(L * (L + 1.0))), data, **{name: 10.0})
        with pytest.raises(ValueError, match=name):
            learn.fit_stream_operator(_model(-(L * (L + 1.0))), data, **{name: 0.0})
    with pytest.raises(TypeError, match="checkpoint must be a learn.Checkpoint"):
        learn.fit_stream_operator(_model(-(L * (L + 1.0))), data, checkpoint="fit.h5")


@pytest.mark.slow  # ~70 s on 2 loaded cores, compiling three programs at N = 4
def test_profiled_matrix_is_the_dense_schur_complement_to_second_order_in_the_solves():
    r"""`_profiled`'s $A - \sum_j B_j^\top G_j^{-1}B_j$ against the same matrix from the dense
    Jacobian (N = 4: 16 components a start, 3 parameters), its solves loose (relative residual
    1e-2): the product formed to second order in their error meets the dense one to ~1e-4 of
    the profiled part (measured 3.6e-8 of |A|), where the first-order $A - B^\top X$ is off by
    $B^\top E$, ~1e-2 of it."""
    import jax

    from learn._training._stream_fit import (
        _all_residuals,
        _flat,
        _linearisation,
        _padded,
        _profiled,
    )

    model, data = _small_fit_problem(noise=1e-2, shift=-3.0)
    padded = _padded(data)
    S = jnp.asarray(np.stack([y[0] for y in data.states]))
    lin = _linearisation(model, S, padded, 1, None)
    counts = jnp.sum(padded.mask, axis=1)
    profiled, steps, _ = _profiled(model, S, padded, lin.J_theta, lin.A, counts, 1, 1e-2, 200)

    x, rebuild = _flat(model)
    jac = jax.jacfwd(lambda z, s: _all_residuals(rebuild(z), s, padded, 1).reshape(-1), argnums=(0, 1))
    J_theta, J_s = (np.asarray(j) for j in jac(x, S))
    J_s = J_s.reshape(J_s.shape[0], -1)
    A = J_theta.T @ J_theta
    dense = A - J_theta.T @ J_s @ np.linalg.solve(J_s.T @ J_s, J_s.T @ J_theta)
    assert np.all(np.asarray(steps) >= 1)
    # the dense reference itself is good to ~cond(G) eps of |A| (cond(G) ~ 2 here); the loose
    # solves' second-order error, ~(1e-2)^2 of the profiled part (0.7 |A|): 1e-6 of |A| bounds
    # it with room, 1e3 below the first-order error
    scale = np.max(np.abs(A))
    assert np.max(np.abs(np.asarray(profiled) - dense)) <= 1e-6 * scale
    # and the profiling matters here: the starts take a visible part of the information
    assert np.max(np.abs(A - dense)) >= 1e-3 * scale
    # preconditioned on every degree (1 to N - 1; degree 0, the trace, is kept by the flow and
    # so is G's identity there): the preconditioner is G's inverse and the first step solves
    # (lineax's second sees it: steps 2), to the same product
    exact, exact_steps, _ = _profiled(model, S, padded, lin.J_theta, lin.A, counts, 1, 1e-2, 200, 3)
    assert np.all(np.asarray(exact_steps) <= 2) and np.all(np.asarray(steps) > 2)
    assert np.max(np.abs(np.asarray(exact) - dense)) <= 1e-6 * scale
    # on degree 1 alone (a block of G, not its inverse): no more steps than none, the same product
    low, low_steps, _ = _profiled(model, S, padded, lin.J_theta, lin.A, counts, 1, 1e-2, 200, 1)
    assert np.all(np.asarray(low_steps) <= np.asarray(steps))
    assert np.max(np.abs(np.asarray(low) - dense)) <= 1e-6 * scale


def _small_fit_problem(noise: float = 1e-3, shift: float = 0.0):
    """Noisy quasi-geostrophic fields (F = 3) at N = 4 (3 degrees, 2 trajectories of 6
    snapshots, `noise` of the field) and a model with a spectrum per degree started at the
    Laplacian's plus `shift`, gauge at degree 3: every part of a fit in seconds."""
    n4 = 4
    system = Zeitlin(n4)
    rng = np.random.default_rng(5)
    times = [np.concatenate([[0.0], np.cumsum(rng.uniform(0.1, 0.3, 5))]) for _ in range(2)]
    truth = learn.StreamOperator(system, learn.QuasiGeostrophicSpectrum(3.0), tol=TOL, iterations=16)
    roll = eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))
    states = [np.asarray(roll(truth, jnp.asarray(system.random_state(j, lmax=3, decay=0.5)), jnp.asarray(np.diff(t))))
              for j, t in enumerate(times)]
    data = add_field_noise(Observations(system, times, states), noise, seed=2)
    l = np.arange(1, n4)
    model = learn.StreamOperator(system, learn.DegreeSpectrum(-(l * (l + 1.0)) + shift, reference_degree=n4 - 1),
                                 tol=TOL, iterations=16)
    return model, data


@pytest.mark.slow  # ~3 fits at N = 4, each compiling its programs
def test_a_fit_resumed_from_any_of_its_checkpoints_ends_bit_for_bit_as_the_uninterrupted_one(tmp_path, monkeypatch):
    from learn._training import _stream_checkpoint

    model, data = _small_fit_problem()
    path = tmp_path / "fit.h5"
    copies = []
    write = _stream_checkpoint.write

    def write_and_copy(target, state, key, settings):  # every file the fit writes, kept aside
        write(target, state, key, settings)
        copies.append((state.phase, state.done, state.columns, state.seconds, path.read_bytes()))

    monkeypatch.setattr(_stream_checkpoint, "write", write_and_copy)
    whole = learn.fit_stream_operator(model, data, max_step=0.1, checkpoint=learn.Checkpoint(path, every=1))
    monkeypatch.setattr(_stream_checkpoint, "write", write)
    phases = [(phase, done, columns) for phase, done, columns, _, _ in copies]
    p = whole.values.size - 1  # the gauge's degree is not fitted
    assert whole.iterations >= 2 and whole.stopped == "converged"
    # one file per accepted iteration but the one that converged (it ends them), one when they
    # end, one per standard error's column
    assert phases == ([("iterations", k, 0) for k in range(1, whole.iterations)]
                      + [("standard errors", whole.iterations, 0)]
                      + [("standard errors", whole.iterations, k) for k in range(1, p + 1)])
    # the standard errors' files keep no J_theta (recomputed on resume), the iterations' do
    for phase, _, _, _, blob in copies:
        (tmp_path / "copy.h5").write_bytes(blob)
        with h5py.File(tmp_path / "copy.h5") as f:
            assert ("state_J_theta" in f) == (phase == "iterations"), phase
    # after iteration 1 and the last but one, when they end, after the first column, at the end
    for k in (0, whole.iterations - 2, whole.iterations - 1, whole.iterations, len(copies) - 1):
        path.write_bytes(copies[k][4])
        resumed = learn.fit_stream_operator(model, data, max_step=0.1, checkpoint=learn.Checkpoint(path, resume=True))
        for name in ("values", "standard_errors", "starts", "covariance"):
            np.testing.assert_array_equal(getattr(resumed, name), getattr(whole, name), err_msg=f"{name}, file {k}")
        assert (resumed.losses, resumed.iterations, resumed.stopped) == (whole.losses, whole.iterations, whole.stopped)
        assert resumed.seconds > copies[k][3] > 0  # the time before the checkpoint counts
    # a fit the iteration cap stops: its last iteration is written, then again as they end
    copies.clear()
    monkeypatch.setattr(_stream_checkpoint, "write", write_and_copy)
    capped = learn.fit_stream_operator(model, data, max_step=0.1, iterations=2, standard_errors=False,
                                       checkpoint=learn.Checkpoint(path, every=1))
    monkeypatch.setattr(_stream_checkpoint, "write", write)
    assert capped.stopped == "iterations"
    assert [c[:3] for c in copies] == [("iterations", 1, 0), ("iterations", 2, 0), ("standard errors", 2, 0)]
    path.write_bytes(copies[0][4])
    resumed = learn.fit_stream_operator(model, data, max_step=0.1, iterations=2, standard_errors=False,
                                        checkpoint=learn.Checkpoint(path, resume=True))
    np.testing.assert_array_equal(resumed.values, capped.values)
    assert resumed.losses == capped.losses



@pytest.mark.slow  # a fit at N = 4 compiled
def test_a_checkpoint_of_another_fit_or_file_is_refused_by_name(tmp_path):
    model, data = _small_fit_problem()
    path = tmp_path / "fit.h5"
    learn.fit_stream_operator(model, data, max_step=0.1, standard_errors=False, checkpoint=learn.Checkpoint(path))
    resume = learn.Checkpoint(path, resume=True)
    with pytest.raises(ValueError, match=r"other settings \(cg_rtol=1e-08 then, 1e-06 now\)"):
        learn.fit_stream_operator(model, data, max_step=0.1, standard_errors=False, cg_rtol=1e-6, checkpoint=resume)
    other = add_field_noise(data, 1e-3, seed=3)
    with pytest.raises(ValueError, match=r"written by a fit of other data, start \(data, model, start compared\)"):
        learn.fit_stream_operator(model, other, max_step=0.1, standard_errors=False, checkpoint=resume)
    # the same start: data alone, and where data made again differ from (the machine's BLAS kernel)
    with pytest.raises(ValueError, match=r"written by a fit of other data \(.*OPENBLAS_CORETYPE sets it"):
        learn.fit_stream_operator(model, other, max_step=0.1, standard_errors=False, checkpoint=resume,
                                  starts=np.stack([y[0] for y in data.states]))
    with pytest.raises(ValueError, match=r"written by a fit of other start \(") as start_only:
        learn.fit_stream_operator(model, data, max_step=0.1, standard_errors=False, checkpoint=resume,
                                  starts=np.stack([y[1] for y in data.states]))
    assert "OPENBLAS" not in str(start_only.value)  # the hint is about data alone
    with h5py.File(path, "r+") as f:  # as if written on a machine whose OpenBLAS ran another kernel
        f.attrs["openblas"] = json.dumps(["Elsewhere"])
    with pytest.raises(ValueError, match=r"OpenBLAS ran its Elsewhere kernel, this process runs .*"
                                         r"OPENBLAS_CORETYPE=Elsewhere"):
        learn.fit_stream_operator(model, other, max_step=0.1, standard_errors=False, checkpoint=resume,
                                  starts=np.stack([y[0] for y in data.states]))
    with pytest.raises(ValueError, match=r"other settings \(substeps=\d+ then, \d+ now \(from max_step\)\)"):
        learn.fit_stream_operator(model, data, max_step=0.05, standard_errors=False, checkpoint=resume)
    # other settings of the standard errors alone: the iterations kept, the standard errors afresh
    full = learn.fit_stream_operator(model, data, max_step=0.1, checkpoint=learn.Checkpoint(path, every=1))
    again = learn.fit_stream_operator(model, data, max_step=0.1, se_coarse_degree=0,
                                      checkpoint=learn.Checkpoint(path, resume=True))
    fresh = learn.fit_stream_operator(model, data, max_step=0.1, se_coarse_degree=0)
    assert again.losses == full.losses and again.iterations == full.iterations
    np.testing.assert_array_equal(again.values, full.values)
    np.testing.assert_array_equal(again.standard_errors, fresh.standard_errors)
    with pytest.raises(ValueError, match="se_coarse_degree must be an integer >= 0"):
        learn.fit_stream_operator(model, data, se_coarse_degree=-1)
    with h5py.File(path, "a") as f:  # cut short
        del f["x"]
    with pytest.raises(ValueError, match="lacks x"):
        learn.fit_stream_operator(model, data, max_step=0.1, standard_errors=False, checkpoint=resume)
    # an iteration's file keeps the linearisation its next step is made with: without it (a
    # standard errors' file relabelled), refused
    learn.fit_stream_operator(model, data, max_step=0.1, iterations=1, standard_errors=False,
                              checkpoint=learn.Checkpoint(path, every=1))
    with h5py.File(path, "a") as f:
        assert f.attrs["phase"] == "standard errors" and "state_J_theta" not in f
        f.attrs["phase"] = "iterations"
    with pytest.raises(ValueError, match="lacks state_cost, state_g_theta, state_c, state_J_theta, state_A"):
        learn.fit_stream_operator(model, data, max_step=0.1, iterations=1, standard_errors=False, checkpoint=resume)
    with h5py.File(path, "w") as f:  # a foreign HDF5 file
        f["x"] = np.zeros(3)
    with pytest.raises(ValueError, match="is not a checkpoint of learn.fit_stream_operator"):
        learn.fit_stream_operator(model, data, max_step=0.1, standard_errors=False, checkpoint=resume)
    path.write_text("not HDF5")
    with pytest.raises(ValueError, match="not a readable HDF5 file"):
        learn.fit_stream_operator(model, data, max_step=0.1, standard_errors=False, checkpoint=resume)


@pytest.mark.slow  # three fits at N = 4 with standard errors, ~70 s
def test_standard_errors_started_from_an_earlier_fits_solves_are_the_cold_ones_in_fewer_steps(tmp_path):
    """A fit refined in half the step, its standard errors' solves started from those of the
    fit at the full step (`se_start`): the same covariance as solves from 0, to the solves'
    tolerance, in fewer conjugate gradient steps; a file without finished solves, or of
    another shape, or not a path, is refused by name."""

    model, data = _small_fit_problem(noise=1e-2, shift=-3.0)
    coarse, cold_path, warm_path = tmp_path / "coarse.h5", tmp_path / "cold.h5", tmp_path / "warm.h5"
    first = learn.fit_stream_operator(model, data, max_step=0.2, checkpoint=learn.Checkpoint(coarse))
    cold = learn.fit_stream_operator(first.model, data, max_step=0.1, starts=first.starts,
                                     checkpoint=learn.Checkpoint(cold_path))
    warm = learn.fit_stream_operator(first.model, data, max_step=0.1, starts=first.starts, se_start=coarse,
                                     checkpoint=learn.Checkpoint(warm_path))
    # the iterations do not see se_start: the same bits
    np.testing.assert_array_equal(warm.values, cold.values)
    # the covariance is second order in the solves' error: relative residuals of se_rtol = 1e-3
    # leave ~1e-6 of it, 1e-4 bounds both fits' with room (and a warm start from the longer
    # step's solves, ~1e-2 off here, without a solve would miss by ~1e-4 of it: see below)
    np.testing.assert_allclose(warm.covariance, cold.covariance, rtol=1e-4)
    with h5py.File(cold_path) as f, h5py.File(warm_path) as g:
        cold_steps, warm_steps = np.asarray(f["steps"]), np.asarray(g["steps"])
    assert np.all(warm_steps >= 1) and np.sum(warm_steps) < np.sum(cold_steps)
    # refused: a fit without finished standard errors, another problem's solves, not a path
    unfinished = tmp_path / "unfinished.h5"
    learn.fit_stream_operator(model, data, max_step=0.2, standard_errors=False, checkpoint=learn.Checkpoint(unfinished))
    with pytest.raises(ValueError, match="holds no finished standard errors"):
        learn.fit_stream_operator(model, data, max_step=0.1, se_start=unfinished)
    with pytest.raises(ValueError, match=r"se_start's solves have shape"):
        learn.fit_stream_operator(model, Observations(data.system, data.times[:1], data.states[:1]), se_start=coarse)
    with pytest.raises(TypeError, match="se_start must be a learn.Checkpoint or the path of one"):
        learn.fit_stream_operator(model, data, se_start=3)


@pytest.mark.slow  # compiles a fit with standard errors at N = 4: over the default run's budget
def test_the_steps_estimated_bias_is_the_bias_a_coarse_step_puts_in_the_parameters():
    # the data: a rotating fluid rolled out in 32 midpoints an interval (its step error 1/1024 of
    # one midpoint's, order 2); the model: one midpoint an interval, fitted to them from the
    # truth, its deviation the step's bias (the reference degree held at the truth's: no gauge on
    # a rotating sphere). The estimate is first order in the bias and Richardson's in the step
    # (the midpoint's next term is O(h^4)): a tenth of it is room for both.
    n = 4
    system = Zeitlin(n)
    l = np.arange(1, n)
    true = -(l * (l + 1.0)) - 3.0
    truth = learn.StreamOperator(system, learn.DegreeSpectrum(true), rotation=0.8, tol=TOL, iterations=16)
    roll = eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d, 32))
    rng = np.random.default_rng(1)
    times = [np.concatenate([[0.0], np.cumsum(rng.uniform(0.2, 0.4, 8))]) for _ in range(2)]
    states = [np.asarray(roll(truth, jnp.asarray(2 * system.random_state(j, decay=0.5)), jnp.asarray(np.diff(t))))
              for j, t in enumerate(times)]
    model = learn.StreamOperator(system, learn.DegreeSpectrum(true), rotation=0.8, tol=TOL, iterations=16)
    fit = learn.fit_stream_operator(model, Observations(system, times, states), iterations=30, rtol=1e-14,
                                    chi2_tol=0.0)
    bias = np.append(fit.values - true, fit.rotation - 0.8)
    estimate = np.append(fit.step_bias, fit.rotation_step_bias)
    assert bias[0] == estimate[0] == 0.0  # the held reference
    assert np.min(np.abs(bias[1:]) / np.abs(np.append(true[1:], 0.8))) > 1e-4  # a bias to see
    np.testing.assert_allclose(estimate[1:], bias[1:], rtol=0.1)
    # without standard errors there is no estimate
    bare = learn.fit_stream_operator(model, Observations(system, times, states), iterations=2, standard_errors=False)
    assert np.all(np.isnan(bare.step_bias)) and np.isnan(bare.rotation_step_bias)


def _fit_with(model, covariance):
    """A StreamOperatorFit holding `model` and `covariance` (what wald_test reads), the rest
    placeholders."""
    nan = np.full(np.shape(model.spectrum.values()), np.nan)
    rotation = None if model.rotation is None else float(model.rotation)
    return learn.StreamOperatorFit(
        model=model, spectrum=model.spectrum, values=model.spectrum.values(), standard_errors=nan,
        rotation=rotation, rotation_standard_error=None if rotation is None else np.nan, starts=np.zeros((1, 16)),
        covariance=covariance, noise=1.0, losses=[], iterations=0, stopped="", substeps=1, seconds=0.0,
        step_bias=nan, rotation_step_bias=None if rotation is None else np.nan)


def test_wald_test_is_the_covariance_distance_of_the_inverse_eigenvalues_in_any_gauge():
    from scipy.linalg import cho_factor, cho_solve
    from scipy.stats import chi2

    system = Zeitlin(4)
    fitted = np.array([-2.1, -5.8, -12.0])  # held at degree 3 (the gauge's reference)
    rng = np.random.default_rng(0)
    M = rng.normal(size=(2, 2))
    C = 1e-4 * (M @ M.T + np.eye(2))
    fit = _fit_with(learn.StreamOperator(system, learn.DegreeSpectrum(fitted, reference_degree=3)), C)
    truth = np.array([-2.0, -6.0, -12.0])
    # by hand: the fitted inverse eigenvalues of degrees 1, 2 less the truth's (same gauge)
    delta = 1.0 / fitted[:2] - 1.0 / truth[:2]
    expected = float(delta @ cho_solve(cho_factor(C), delta))
    test = fit.wald_test(truth)
    assert test.dof == 2
    # a 2x2 solve: a few ulps of the statistic (cond(C) ~ 10)
    assert test.statistic == pytest.approx(expected, rel=64 * np.finfo(float).eps)
    assert test.p_value == pytest.approx(chi2.sf(expected, 2), rel=1e-12)
    # the same hypothesis in another gauge (a constant added to every 1/lambda): the same flow
    moved = learn.in_gauge(truth, 0, -1.5)
    assert fit.wald_test(moved).statistic == pytest.approx(expected, rel=1e-10)
    assert fit.wald_test(fitted).statistic == 0.0
    with pytest.raises(ValueError, match=r"values must have shape \(3,\); got shape \(2,\)"):
        fit.wald_test(truth[:2])
    with pytest.raises(ValueError, match="rotation must be given exactly when the fit has one"):
        fit.wald_test(truth, rotation=1.0)
    with pytest.raises(ValueError, match="fit with standard_errors=True"):
        _fit_with(fit.model, np.full((2, 2), np.nan)).wald_test(truth)


def test_wald_test_on_a_rotating_sphere_holds_the_gauge_and_tests_the_rotation():
    system = Zeitlin(4)
    fitted = np.array([-2.1, -5.8, -12.0])
    C = np.diag([1e-4, 4e-4, 1e-6])  # the inverse eigenvalues of degrees 1, 2, then the rotation
    fit = _fit_with(learn.StreamOperator(system, learn.DegreeSpectrum(fitted, reference_degree=3), rotation=1.002), C)
    truth = np.array([-2.0, -6.0, -12.0])
    delta = np.array([1 / -2.1 - 1 / -2.0, 1 / -5.8 - 1 / -6.0, 0.002])
    test = fit.wald_test(truth, rotation=1.0)
    assert test.dof == 3
    assert test.statistic == pytest.approx(float(np.sum(delta**2 / np.diag(C))), rel=1e-12)
    # no gauge freedom: a hypothesis in another gauge is another flow, refused
    with pytest.raises(ValueError, match=r"values\[2\] must be the held eigenvalue -12.0 \(the gauge\)"):
        fit.wald_test(learn.in_gauge(truth, 0, -1.5), rotation=1.0)
    with pytest.raises(ValueError, match="rotation must be given exactly when the fit has one"):
        fit.wald_test(truth)
    with pytest.raises(ValueError, match="rotation must be a finite real number"):
        fit.wald_test(truth, rotation=np.inf)


def test_wald_test_of_the_quasi_geostrophic_family_is_z_squared():
    system = Zeitlin(4)
    fit = _fit_with(learn.StreamOperator(system, learn.QuasiGeostrophicSpectrum(0.3)), np.array([[0.01]]))
    test = fit.wald_test([0.0])  # Euler's equations: F = 0, 3 standard errors away
    assert test.dof == 1 and test.statistic == pytest.approx(9.0, rel=1e-12)
    assert test.p_value == pytest.approx(0.0026997960632601866, rel=1e-9)  # P(|Z| >= 3), a normal table's value
    with pytest.raises(ValueError, match=r"values must be \(F,\), one real number; got shape \(2,\)"):
        fit.wald_test([0.0, 1.0])
