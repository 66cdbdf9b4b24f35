"""`learn.LevenbergMarquardt` (least squares on the residuals of a loss), the block Jacobian of
the observation loss it uses, and `integrators.splitting.IndexedFlows` (a G-LPNet's modules
composed in a scan): minima known in closed form, Jacobians against `jax.jacfwd`, scanned
steps against unrolled ones."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
from helpers import ToyProblem, slow_except

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import composition_flops
from integrators.splitting import METHODS, IndexedFlows, LieTrotter, Strang, TripleJump

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))


class _Curve(eqx.Module):
    """y = a exp(b x) + c: a nonlinear least-squares problem with a known minimum."""

    theta: jax.Array


class _CurveLoss(learn.AbstractLeastSquares):
    def residuals(self, y, args):
        x, target = args
        a, b, c = y.theta
        return a * jnp.exp(b * x) + c - target

    def count(self, y, args):
        return int(args[0].size)

    def __call__(self, y, args):
        return jnp.mean(self.residuals(y, args) ** 2)


def _fit_curve(theta0, y, stage):
    x = jnp.linspace(0.0, 1.0, 40)
    result = stage.run(ToyProblem(_CurveLoss(), _Curve(jnp.asarray(theta0)), (x, y)), learn.Context())
    return result.y, result.record, result.history


def test_levenberg_marquardt_finds_the_exact_minimum_of_a_nonlinear_fit():
    x = jnp.linspace(0.0, 1.0, 40)
    truth = np.array([2.0, -1.5, 0.3])
    y = truth[0] * jnp.exp(truth[1] * x) + truth[2]
    fitted, rec, hist = _fit_curve([1.0, 0.0, 0.0], y, learn.LevenbergMarquardt(100, rtol=0.0))
    # exact data: the minimum is the truth with zero residual. The parameters are determined to
    # the conditioning of J (~1e3 here) times eps of the residuals' scale: 1e4 eps is generous.
    np.testing.assert_allclose(np.asarray(fitted.theta), truth, rtol=0, atol=1e4 * EPS)
    assert rec.kept and rec.optimiser == "LevenbergMarquardt" and rec.train_loss < 1e-25
    assert rec.iterations == len(hist["train_loss"]) < 100  # stops when no damping lowers the loss further


def test_levenberg_marquardt_minimum_of_noisy_data_is_the_normal_equations_solution():
    # an independent reference: scipy's trust-region least squares at its tightest tolerances
    x = np.linspace(0.0, 1.0, 40)
    y = 2.0 * np.exp(-1.5 * x) + 0.3 + 1e-2 * np.random.default_rng(0).normal(size=x.size)
    ref = scipy.optimize.least_squares(lambda t: t[0] * np.exp(t[1] * x) + t[2] - y, [1.0, 0.0, 0.0],
                                       xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    fitted, _, _ = _fit_curve([1.0, 0.0, 0.0], jnp.asarray(y), learn.LevenbergMarquardt(200, rtol=0.0))
    # Both stop where the sum of squares S ~ 4e-3 no longer changes in floating point: a
    # parameter error d changes S by ~ lambda_min(J^T J) d^2, so the minimiser is determined
    # only to sqrt(eps S / lambda_min) ~ 3e-9 (lambda_min = 0.08 for this exponential fit);
    # measured 1.1e-9 apart.
    np.testing.assert_allclose(np.asarray(fitted.theta), ref, rtol=0, atol=1e-8)


def test_levenberg_marquardt_keeps_the_start_when_it_cannot_improve():
    x = jnp.linspace(0.0, 1.0, 40)
    truth = jnp.asarray([2.0, -1.5, 0.3])
    y = truth[0] * jnp.exp(truth[1] * x) + truth[2]
    fitted, rec, _ = _fit_curve(truth, y, learn.KeepIfBetter(learn.LevenbergMarquardt(10)))
    assert not rec.kept and rec.train_loss == 0.0
    np.testing.assert_array_equal(np.asarray(fitted.theta), np.asarray(truth))


def test_a_target_out_of_reach_stops_levenberg_marquardt_and_one_in_reach_changes_nothing():
    from learn._solvers._levenberg_marquardt import TARGET_AFTER

    x = np.linspace(0.0, 1.0, 40)
    y = jnp.asarray(2.0 * np.exp(-1.5 * x) + 0.3 + 1e-2 * np.random.default_rng(0).normal(size=x.size))
    free, free_record, free_history = _fit_curve([1.0, 0.0, 0.0], y, learn.LevenbergMarquardt(200, rtol=0.0))
    floor = free_record.train_loss  # the noise's floor, ~1e-4
    assert free_record.iterations > TARGET_AFTER  # without a target it runs past the judged steps
    # a tenth of the floor: no fit reaches it; judged after TARGET_AFTER steps, at the floor's flat rate
    _, record, history = _fit_curve([1.0, 0.0, 0.0], y, learn.LevenbergMarquardt(200, rtol=0.0, target=0.1 * floor))
    assert record.iterations == TARGET_AFTER and history["train_loss"][-1] > 0.1 * floor
    # a target the fit reaches: the same steps, bit for bit
    reached, _, reached_history = _fit_curve([1.0, 0.0, 0.0], y,
                                             learn.LevenbergMarquardt(200, rtol=0.0, target=2.0 * floor))
    np.testing.assert_array_equal(np.asarray(reached.theta), np.asarray(free.theta))
    np.testing.assert_array_equal(reached_history["train_loss"], free_history["train_loss"])


def test_a_target_beyond_a_converging_fits_limit_is_out_of_reach_and_one_within_it_is_not():
    from learn._solvers._levenberg_marquardt import TARGET_AFTER, _out_of_reach

    # a linearly converging loss: L_k = L* (1 + 0.01 rho^k), its decreases shrinking by rho
    # per step; at its last rate for the 190 steps left it would fall ~6% below L*
    limit, rho = 1e-4, 0.8
    values = [limit * (1 + 0.01 * rho**k) for k in range(1, 11)]
    assert _out_of_reach(values, limit * (1 - 1e-4), 200)  # below its limit: never reached
    assert not _out_of_reach(values, limit * (1 + 0.01 * rho**13), 200)  # reached in 3 more steps
    # the steady pace stays the rule while the decreases do not shrink: a loss falling by
    # 1% per step reaches L/10 in ~230 steps, not in 190, and L/5 in ~160
    steady = [0.99**k for k in range(1, 11)]
    assert _out_of_reach(steady, 0.1, 200) and not _out_of_reach(steady, 0.2, 200)
    assert not _out_of_reach(values[: TARGET_AFTER - 1], 0.0, 200)  # not judged before TARGET_AFTER
    assert _out_of_reach(values, 0.0, 200)  # a loss of 0: out of reach of a falling positive one


def test_levenberg_marquardt_refuses_a_non_finite_start():
    x = jnp.linspace(0.0, 1.0, 40)
    with pytest.raises(FloatingPointError, match="the loss at the start is not finite; check the weights and the data"):
        _fit_curve([1.0, 0.0, 0.0], x.at[3].set(jnp.nan), learn.LevenbergMarquardt(10))


def test_levenberg_marquardt_is_deterministic():
    x = jnp.linspace(0.0, 1.0, 40)
    y = 2.0 * jnp.exp(-1.5 * x) + 0.3 + 1e-2 * jnp.sin(17 * x)
    a = _fit_curve([1.0, 0.0, 0.0], y, learn.LevenbergMarquardt(50))[0]
    b = _fit_curve([1.0, 0.0, 0.0], y, learn.LevenbergMarquardt(50))[0]
    np.testing.assert_array_equal(np.asarray(a.theta), np.asarray(b.theta))


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"iterations": 0}, ValueError, "LevenbergMarquardt.iterations"),
    ({"rtol": -1e-3}, ValueError, r"LevenbergMarquardt.rtol must be a number in \[0, 1\)"),
    ({"rtol": True}, ValueError, "LevenbergMarquardt.rtol"),
    ({"target": -1.0}, ValueError, "LevenbergMarquardt.target must be None or a loss >= 0"),
    ({"target": True}, ValueError, "LevenbergMarquardt.target"),
])
def test_bad_levenberg_marquardt_settings(kwargs, error, match):
    with pytest.raises(error, match=match):
        learn.LevenbergMarquardt(**kwargs)


def test_levenberg_marquardt_needs_a_least_squares_loss():
    class L1(learn.AbstractObjective):
        def __call__(self, y, args):
            return jnp.sum(jnp.abs(y.theta))

    problem = ToyProblem(L1(), _Curve(jnp.ones(3)), (jnp.zeros(3), jnp.zeros(3)))
    with pytest.raises(ValueError, match="needs a least-squares loss"):
        learn.LevenbergMarquardt(5).run(problem, learn.Context())


# ~4 s with -m slow: Levenberg-Marquardt on observations' block Jacobians runs by default in every
# fit_splitting (test_learn_observations.py, the README), the blocks are checked below, and the
# ParametricHamiltonian's rollout in test_trajectory_loss_of_the_true_hamiltonian_is_round_off
@pytest.mark.slow
def test_fit_with_levenberg_marquardt_recovers_the_rigid_body_from_exact_observations():
    """`learn.fit(..., optimiser=learn.LevenbergMarquardt())` with fitted starts: the block
    Jacobian path, end to end."""
    y = np.random.default_rng(0).normal(size=(5, 3))
    y0 = y / np.linalg.norm(y, axis=1, keepdims=True)
    data = it.observe(BODY, y0, it.uneven_times(5, 9, (0.05, 0.3), seed=1))
    model = learn.ParametricHamiltonian(BODY, lambda y, d: 0.5 * jnp.sum(d * y**2), np.ones(3))
    fitted, record = learn.fit(model, data, optimiser=learn.LevenbergMarquardt(100), validation_fraction=0.0,
                               progress=False)
    theta = np.asarray(fitted.theta)
    want = 1.0 / np.array([2.0, 1.0, 2 / 3])
    # only differences are identified (a multiple of |y|^2 is a Casimir); RK4's truncation error
    # (10 sub-steps of at most 0.03) moves them by ~1e-10 (the same test with BFGS: 2e-10)
    np.testing.assert_allclose(theta[:, None] - theta[None, :], want[:, None] - want[None, :], rtol=0, atol=1e-8)
    assert record.stages[-1].optimiser == "LevenbergMarquardt" and record.train_loss < 1e-18


def test_levenberg_marquardt_hands_on_its_last_jacobian_read_only_at_its_point_and_data():
    """The criterion reads the fitted map's Jacobian where Levenberg-Marquardt left it, in the
    stage's result (no module state); it is never read for another point, other data or data
    that could change in place, and a start kept by `KeepIfBetter` has none."""
    from learn._solvers import _levenberg_marquardt as lm

    x = jnp.linspace(0.0, 1.0, 40)
    args = (x, 2.0 * jnp.exp(-1.5 * x) + 0.3)
    problem = ToyProblem(_CurveLoss(), _Curve(jnp.asarray([1.0, 0.0, 0.0])), args)
    result = learn.LevenbergMarquardt(20, rtol=0.0).run(problem, learn.Context())
    lin, theta = result.linearisation, result.y.theta
    assert lin.at(theta, args) and lin.at(jnp.array(np.asarray(theta)), args)  # an equal x in another array
    # they are the residuals and Jacobian of the compiled Jacobian at that point, to the bit
    r, J = lm.residuals_of(_CurveLoss(), result.y).jacobian(theta, args)
    np.testing.assert_array_equal(np.asarray(lin.residuals), np.asarray(r))
    np.testing.assert_array_equal(np.asarray(lin.jacobian), np.asarray(J))
    assert not lin.at(jnp.asarray(np.nextafter(np.asarray(theta), np.inf)), args)  # one ulp away
    assert not lin.at(jnp.asarray(theta).at[0].set(-theta[0]), args)
    assert not lin.at(theta, (args[0], args[1] + 0.0))  # equal data in another object
    mutable = (np.asarray(x), np.asarray(args[1]).copy())  # NumPy data may change in place: never read
    on_numpy = learn.LevenbergMarquardt(20, rtol=0.0).run(ToyProblem(_CurveLoss(), problem.y0, mutable),
                                                           learn.Context())
    assert not on_numpy.linearisation.at(on_numpy.y.theta, mutable)
    # a start kept (exact data from the truth: no step lowers a zero loss) hands on none
    truth = _Curve(jnp.asarray([2.0, -1.5, 0.3]))
    kept = learn.KeepIfBetter(learn.LevenbergMarquardt(5)).run(problem.with_start(truth), learn.Context())
    assert not kept.record.kept and kept.linearisation is None


@pytest.mark.slow
def test_block_jacobian_of_the_observation_loss_is_the_full_jacobian():
    problem = _trajectory_problem()
    fitted, segments, objective = problem.y0, problem.train, problem.objective
    params, static = eqx.partition(fitted, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(params)
    assert isinstance(fitted, learn.Fitted) and fitted.starts.shape == (3, 3)
    assert isinstance(objective, learn.AbstractStructuredJacobian)

    def residuals(x):
        return objective.residuals(eqx.combine(unravel(x), static), segments).reshape(-1)

    # compiled (as the solver runs them): eagerly, every scan and primitive is compiled on its own
    r, J = eqx.filter_jit(objective.jacobian)(fitted, segments)
    np.testing.assert_array_equal(np.asarray(r), np.asarray(jax.jit(residuals)(flat)))
    full = np.asarray(jax.jit(jax.jacfwd(residuals))(flat))
    assert J.shape == full.shape == (r.size, flat.size)
    # the same derivatives, summed in another order: round-off relative to the largest entry
    np.testing.assert_allclose(np.asarray(J), full, rtol=0, atol=100 * EPS * np.max(np.abs(full)))
    # the starts' columns are block-diagonal: trajectory j's rows (21 components each, the first
    # observation included: it is a prediction of the fitted start) see only start j
    starts_columns = np.asarray(J)[:, -9:].reshape(3, -1, 3, 3)
    for j in range(3):
        for k in range(3):
            assert (np.count_nonzero(starts_columns[j, :, k]) > 0) == (j == k)


def _trajectory_problem(m=7, latent=True):
    """A G-LPNet fitted to 3 noisy trajectories of `m` observations of the rigid body at uneven
    steps, starts fitted (`latent`) or taken as observed."""
    data = it.observe(BODY, np.eye(3), it.uneven_times(3, m, (0.05, 0.3), seed=2), noise=1e-3, seed=0)
    net = learn.GLPNet(BODY, terms=learn.RidgeTerms(3, 3, key=1, linear_term=True), method=TripleJump)
    return learn.TrajectoryLoss(latent=latent).problem(net, data, h=None, validation_fraction=0.0, seed=0,
                                                       normalise=False)


def _body_problem(n=3, m=7):
    """A G-LPNet (Strang, one step per interval) on body observations of the rigid body:
    attitudes and angular velocities."""
    from scipy.spatial.transform import Rotation

    y0 = np.random.default_rng(3).normal(size=(n, 3))
    data = it.observe_body(BODY, y0 / np.linalg.norm(y0, axis=1, keepdims=True),
                           Rotation.random(n, random_state=4).as_quat(), it.uneven_times(n, m, (0.05, 0.3), seed=5),
                           noise=1e-3, seed=6)
    net = learn.GLPNet(BODY, terms=learn.RidgeTerms(3, 3, key=2, activation="identity", full_vectors=True,
                                                    bias=True), method=Strang())
    return learn.BodyLoss().problem(net, data, h=None, validation_fraction=0.0, seed=0, normalise=False)


# body observations (their blocks are the same code) with -m slow: a heyoka integrator of
# (g, mu) to compile (~6 s)
@pytest.mark.parametrize("loss", ["trajectories", pytest.param("body", marks=pytest.mark.slow)])
def test_normal_equations_from_the_blocks_are_those_of_the_whole_jacobian(loss):
    problem = _trajectory_problem() if loss == "trajectories" else _body_problem()
    fitted, args, objective = problem.y0, problem.train, problem.objective
    r, J = eqx.filter_jit(objective.jacobian)(fitted, args)
    r_blocks, A, g = eqx.filter_jit(objective.normal_equations)(fitted, args)
    np.testing.assert_array_equal(np.asarray(r_blocks), np.asarray(r))
    J, r = np.asarray(J), np.asarray(r)
    # sums of the same products in another order: round-off of the largest |J|^2 times n
    scale = r.size * np.max(np.abs(J)) ** 2
    np.testing.assert_allclose(np.asarray(A), J.T @ J, rtol=0, atol=100 * EPS * scale)
    np.testing.assert_allclose(np.asarray(g), J.T @ r, rtol=0, atol=100 * EPS * r.size * np.max(np.abs(J))
                               * np.max(np.abs(r)))
    n_unknowns = J.shape[1]
    assert objective.block_entries(fitted, args) == r.size * objective.forward_passes(fitted) + n_unknowns**2


@pytest.mark.slow
def test_levenberg_marquardt_on_the_blocks_takes_the_dense_steps_and_fits_what_the_dense_could_not(monkeypatch):
    from learn._solvers import _levenberg_marquardt as lm
    from learn._training import _observed

    # 3 trajectories of 20 observations: 180 residuals, 21 unknowns of which 9 starts; the
    # blocks (180 x 15 + 21^2) hold fewer numbers than the Jacobian (180 x 21)
    problem = _trajectory_problem(20)
    objective, y0, train = problem.objective, problem.y0, problem.train
    dense_entries = 180 * 21
    assert objective.block_entries(y0, train) == 180 * 15 + 21**2 < dense_entries
    stage = learn.LevenbergMarquardt(5, rtol=0.0)
    dense = stage.run(problem, learn.Context())
    assert not lm.check_size(objective, y0, train)  # small: the whole Jacobian
    monkeypatch.setattr(lm, "DENSE_JACOBIAN", dense_entries - 1)  # past it: the blocks
    assert lm.check_size(objective, y0, train)
    blocks = stage.run(problem, learn.Context())
    # the same steps: the normal equations agree to round-off (above), and 5 damped steps of a
    # well-conditioned fit keep that to ~1e-10 of the loss
    np.testing.assert_allclose(blocks.history["train_loss"], dense.history["train_loss"], rtol=1e-9)
    # the criterion reads the weights' block alone: the same rank and residuals
    on_blocks = _observed.information_criterion(problem, blocks.y)
    monkeypatch.setattr(lm, "DENSE_JACOBIAN", 10**12)
    on_dense = _observed.information_criterion(problem, blocks.y)
    assert on_blocks["effective_parameters"] == on_dense["effective_parameters"]
    np.testing.assert_allclose(on_blocks["ssr"], on_dense["ssr"], rtol=1e-12)
    # a Jacobian too large to hold whose blocks fit: fitted, not refused; blocks too large: refused
    monkeypatch.setattr(lm, "DENSE_JACOBIAN", 0)
    monkeypatch.setattr(lm, "MAX_JACOBIAN", 180 * 15 + 21**2)
    assert lm.check_size(objective, y0, train)
    monkeypatch.setattr(lm, "MAX_JACOBIAN", 180 * 15 + 21**2 - 1)
    with pytest.raises(ValueError, match="numbers of its blocks"):
        lm.check_size(objective, y0, train)
    # without fitted starts there are no blocks to save: the whole Jacobian, and its criterion
    observed = _trajectory_problem(20, latent=False)
    assert observed.y0.starts is None
    assert not lm.check_size(observed.objective, observed.y0, observed.train)
    assert _observed.information_criterion(observed, observed.y0)["effective_parameters"] > 0


# -- IndexedFlows: a G-LPNet's modules composed in a scan ---------------------------------------
# Lie-Trotter and Strang by default; the compositions of Strang steps with -m slow
@pytest.mark.parametrize("method", slow_except([m for m in METHODS if m.__name__ != "BlanesMoan4"], {LieTrotter, Strang}),
                         ids=lambda m: m.__name__)
def test_scanned_glpnet_step_is_the_unrolled_composition(method):
    net = learn.GLPNet(BODY, 4, key=3, method=method, linear_term=True, h=0.1)
    flows = net.flows()
    assert isinstance(flows, IndexedFlows) and len(flows) == 4
    y = jnp.asarray([0.3, -0.8, 0.5])
    scanned = net.step(y)
    unrolled = net.method.compose(list(flows), y, net.h)
    # the same flows with the same times (0.5 * h against a traced weight 0.5 times h: equal):
    # XLA may fuse differently, so a few eps
    np.testing.assert_allclose(np.asarray(scanned), np.asarray(unrolled), rtol=0, atol=8 * EPS)


def test_flop_count_counts_every_scanned_flow():
    net = learn.GLPNet(BODY, 4, key=3, method=Strang, h=0.1)
    one = learn.GLPNet(BODY, 1, key=3, method=Strang, h=0.1)
    # Strang over 4 modules evaluates 7 flows, over 1 module one: XLA counts a scan body once,
    # so a count that saw the scan would give ~1x, not ~7x
    assert 5 < composition_flops(net, Strang()) / composition_flops(one, Strang()) < 9


def test_indexed_flows_is_a_sequence_of_flows():
    calls = []

    def flow(k, t, y):
        calls.append(k)
        return y + k * t

    flows = IndexedFlows(flow, 3)
    assert len(flows) == 3 and len(flows[1:]) == 2
    assert float(flows[-1](0.5, 1.0)) == 2.0 and calls[-1] == 2
    with pytest.raises(IndexError, match="flow index 3 out of range for 3 flows"):
        flows[3]


# -- resuming a Levenberg-Marquardt fit ------------------------------------------------------------
@pytest.fixture(scope="module")
def glpnet_pairs():
    y0 = np.random.default_rng(4).uniform(-1.0, 1.0, size=(6, 3))
    return it.ground_truth(BODY, y0, h=0.1, n_steps=8)


# every 5 steps: writes at steps 5, 10 and (the end) 12 of the warm start, then 5, 10, 12 after
# it; (which write is interrupted, steps left to take after the resume)
@pytest.mark.slow
@pytest.mark.parametrize(("interrupt_at", "left"),
                         [(2, 14), pytest.param(3, 12, marks=pytest.mark.slow), (5, 2)],  # 5 s each
                         ids=["in the warm start", "at its end", "after it"])
def test_interrupted_levenberg_marquardt_fit_resumes_bit_identically(glpnet_pairs, tmp_path, monkeypatch,
                                                                     interrupt_at, left):
    import learn._files as ckpt
    import learn._solvers._levenberg_marquardt as least_squares

    stage = learn.KeepIfBetter(learn.WarmStart(learn.LevenbergMarquardt(24, rtol=0.0)))
    kwargs = {"optimiser": stage, "validation_fraction": 0.0, "progress": False}
    net = learn.GLPNet(BODY, n_modules=3, key=1)
    straight, straight_record = learn.fit(net, glpnet_pairs, **kwargs)

    path = tmp_path / "lm.h5"
    write, calls = ckpt.write, []

    def interrupted(*args, **kw):
        write(*args, **kw)
        calls.append(1)
        if len(calls) == interrupt_at:
            raise KeyboardInterrupt

    monkeypatch.setattr(ckpt, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        learn.fit(net, glpnet_pairs, checkpoint=learn.Checkpoint(path, every=5), **kwargs)
    monkeypatch.setattr(ckpt, "write", write)
    steps = []  # one set of normal equations per step taken after the resume
    normal = least_squares._normal_equations
    monkeypatch.setattr(least_squares, "_normal_equations", lambda r, J: steps.append(1) or normal(r, J))
    # the file loads as a model of the class fitted (during the warm start: its starting weights)
    assert isinstance(learn.load(path), learn.GLPNet) and learn.load(path).activation == "sigmoid"
    resumed, resumed_record = learn.fit(net, glpnet_pairs, checkpoint=learn.Checkpoint(path, every=5, resume=True),
                                        **kwargs)
    assert len(steps) == left  # it continued from the file, not from the start
    for a, b in zip(jax.tree_util.tree_leaves(straight), jax.tree_util.tree_leaves(resumed)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(resumed_record.history["train_loss"], straight_record.history["train_loss"])
    assert resumed_record.train_loss == straight_record.train_loss
    assert len(straight_record.history["train_loss"]) == 24  # every step taken: the interruptions came before the end
    with pytest.raises(ValueError, match="rtol"):
        learn.fit(net, glpnet_pairs, checkpoint=learn.Checkpoint(path, resume=True),
                  **{**kwargs, "optimiser": learn.KeepIfBetter(learn.WarmStart(learn.LevenbergMarquardt(24, rtol=1e-3)))})


def test_checkpoint_needs_one_adam_or_levenberg_marquardt_stage(glpnet_pairs, tmp_path):
    with pytest.raises(ValueError, match="exactly one Adam or LevenbergMarquardt stage"):
        learn.fit(learn.GLPNet(BODY, n_modules=3), glpnet_pairs, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(5)),
                  checkpoint=learn.Checkpoint(tmp_path / "x.h5"), progress=False)


def test_levenberg_marquardt_refuses_a_jacobian_too_large_for_memory(glpnet_pairs):
    net = learn.LPNet(BODY, hidden=(512, 512), key=0)  # 2.7e5 weights: as many forward passes a step
    with pytest.raises(ValueError, match=r"the Jacobian would be 144 residuals x \d+ unknowns, \d+ forward passes "
                                         r"\(at most 2000.* use learn.ScipyLBFGSB"):
        learn.fit(net, glpnet_pairs, optimiser=learn.LevenbergMarquardt(5), validation_fraction=0.0, progress=False)


def test_an_optimistix_solver_is_a_stage_on_the_same_problems():
    """Any optimistix solver runs behind the stage interface: its Levenberg-Marquardt on the
    residuals of the curve fit reaches the exact minimum, its BFGS on the loss too."""
    import optimistix as optx

    x = jnp.linspace(0.0, 1.0, 40)
    truth = np.array([2.0, -1.5, 0.3])
    y = truth[0] * jnp.exp(truth[1] * x) + truth[2]
    problem = ToyProblem(_CurveLoss(), _Curve(jnp.asarray([1.0, 0.0, 0.0])), (x, y))
    for solver in (optx.LevenbergMarquardt(rtol=1e-14, atol=1e-14), optx.BFGS(rtol=1e-14, atol=1e-14)):
        result = learn.Optimistix(solver, max_steps=500).run(problem, learn.Context())
        assert result.record.kept and result.record.optimiser == "Optimistix"
        # exact data, as for learn.LevenbergMarquardt above: BFGS stops on the gradient's size,
        # so the parameters to ~sqrt(eps) of a loss scale of 1 (1e-6 is generous)
        np.testing.assert_allclose(np.asarray(result.y.theta), truth, rtol=0, atol=1e-6)
    with pytest.raises(TypeError, match="Optimistix.solver must be an optimistix"):
        learn.Optimistix("bfgs")

    class L1(learn.AbstractObjective):
        def __call__(self, y, args):
            return jnp.sum(jnp.abs(y.theta))

    with pytest.raises(ValueError, match="least-squares solver"):
        learn.Optimistix(optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)).run(
            ToyProblem(L1(), _Curve(jnp.ones(3)), (x, y)), learn.Context())
