"""learn on observations (`integrators.Observations`: noisy states at uneven times): the
trajectory loss (`TrajectoryLoss`, `ObservationLoss`, sub-steps), fitting a G-LPNet that then
runs at steps it never saw, Casimirs kept from noisy data, the parametric reference model
(`ParametricHamiltonian`), what a learned Hamiltonian identifies (`quadratic_part`), the
information criterion's parameter count, `RidgeTerms(bias=False)` and LPNets that take the
step as an input. Small data and few BFGS iterations: the whole file runs in under a minute
(with -n 0)."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import integrators as it
import learn
import liepoisson as lp
from integrators.splitting import TripleJump
from learn._training._observed import information_criterion

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))
INVERSE_INERTIA = 1.0 / np.array([2.0, 1.0, 2 / 3])
N_TRAJ, N_OBS = 8, 11


def observed_objective(model, data, loss, h, validation_fraction, seed):
    """The training problem `loss` builds: `(fitted start, segments, held-out, objective,
    problem)`."""
    loss = learn.TrajectoryLoss() if loss is None else loss
    p = loss.problem(model, data, h=h, validation_fraction=validation_fraction, seed=seed, normalise=False)
    return p.y0, p.train, p.validation, p.objective, p


def _quadratic_family(y, d):
    """The rigid body's Hamiltonian family: H(y; d) = sum_i d_i y_i^2 / 2 (d = 1/I)."""
    return 0.5 * jnp.sum(d * y**2)


def _starts(n: int, size: float, seed: int = 0) -> np.ndarray:
    """`n` random states of norm `size`."""
    y = np.random.default_rng(seed).normal(size=(n, 3))
    return size * y / np.linalg.norm(y, axis=1, keepdims=True)


_step = jax.jit(lambda model, y: model.step(y))  # h is a traced leaf: one compilation for every step size


def _observations(noise: float, size: float = 0.5, drop: float = 0.0, n: int = N_TRAJ) -> it.Observations:
    """`n` trajectories of the rigid body, observed N_OBS times at uneven steps from [0.05, 0.3]."""
    return it.observe(BODY, _starts(n, size), it.uneven_times(n, N_OBS, (0.05, 0.3), seed=1), noise=noise,
                      drop=drop, seed=0)


def _casimir_relative_drift(y: np.ndarray) -> float:
    c = np.asarray(BODY.casimirs(y)).reshape(y.shape[:-1])
    return float(np.max(np.abs(c - c[..., :1]) / np.abs(c[..., :1])))


# Both fits have the same data shapes, so the second reuses the first one's compiled loss.
@pytest.fixture(scope="module")
def exact_fit():
    data = _observations(noise=0.0)
    model, records = learn.fit_splitting(BODY, data, activation="identity", iterations=100,
                                         validation_fraction=0.0, progress=False)
    return data, model, records


@pytest.fixture(scope="module")
def noisy_fit():
    data = _observations(noise=1e-2)
    model, records = learn.fit_splitting(BODY, data, activation="identity", iterations=100,
                                         validation_fraction=0.0, progress=False)
    return data, model, records


# -- 1. a map trained on uneven steps runs at steps it never saw -------------------------------------
# a fit and a convergence study with -m slow; the same fit on noisy observations runs by default (section 4)
@pytest.mark.slow
def test_glpnet_fitted_on_uneven_steps_has_its_order_at_unseen_steps(exact_fit):
    data, model, _ = exact_fit
    assert isinstance(model, learn.GLPNet) and model.method == TripleJump()  # order 4
    assert model.activation == "identity"
    steps = data.intervals()
    assert not data.is_regular() and steps.min() >= 0.05 and steps.max() <= 0.3
    # At step h the rollout error is (the flow of H~ against that of H) + (TripleJump's splitting
    # error of H~, ~ C h^4). The first does not depend on h: it is the floor e(0.1) below, which
    # must be small beside e(0.4) for the ratio e(0.8)/e(0.4) to show the splitting's order.
    # The states have norm 0.5: Euler's equations are quadratic (y(t) = r u(r t)), so h = 0.8
    # at |y| = 0.5 is h = 0.4 at |y| = 1, in TripleJump's asymptotic range. (With states of
    # norm ~1.7, TripleJump with the true H itself shows order ~2.9 between 0.8 and 0.4.)
    # Measured: e = 1.4e-4, 9.4e-6, 5e-7 at h = 0.8, 0.4, 0.1, observed order 3.9.
    starts = np.stack([y[0] for y in data.states[:4]])
    conv = it.convergence(lambda h: model.with_h(h), BODY, starts, t_final=8.0, hs=[0.8, 0.4, 0.1])
    assert 0.4 > steps.max()  # both steps compared are outside the training range
    e08, e04, e01 = conv.errors
    assert e01 < 0.1 * e04  # the learned H~ is close to H: the splitting error dominates at 0.4
    order = np.log2(e08 / e04)
    assert abs(order - 4.0) < 0.5, (conv.errors, order)


# -- 2. bad input to learn.fit on observations ----------------------------------------------------
# (Exact (y0, y1) pairs whose Casimirs disagree are still refused, "no Poisson map connects
# them": tests/test_reliability.py, "fit-casimir-pair" and "fit-casimir-traj".)
def test_observations_that_fit_no_common_leaf_are_refused():
    # noise of half the states' size spreads |y|^2 by far more than LEAF_SPREAD_MAX = 0.1
    data = it.observe(BODY, _starts(3, 1.0), it.uneven_times(3, 6, seed=2), noise=0.5, seed=3)
    with pytest.raises(ValueError, match=r"data: the observations of trajectory \d spread over Casimir 0.*"
                                         r"no common leaf fits them"):
        learn.fit(learn.GLPNet(BODY, 3, method=TripleJump), data, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(1)),
                  progress=False)


def _small_data() -> it.Observations:
    return it.Observations(BODY, it.uneven_times(2, 4, seed=4), _starts(8, 1.0).reshape(2, 4, 3))


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        pytest.param({"loss": "alpha"}, ValueError,
                     r"loss must be a learn\.AbstractLoss \(TrajectoryLoss for this data.*\['state'\]; got 'alpha'",
                     id="loss a pair loss"),
        pytest.param({"loss": 3}, TypeError, r"loss must be a learn\.AbstractLoss \(TrajectoryLoss for this data.*got 3", id="loss a number"),
        pytest.param({"normalise": True}, ValueError, r"normalise=True sets an MLP's scalings.*with observations",
                     id="normalise"),
    ],
)
def test_bad_fit_arguments_with_observations(kwargs, error, match):
    with pytest.raises(error, match=match):
        learn.fit(learn.GLPNet(BODY, 3), _small_data(), optimiser=learn.KeepIfBetter(learn.ScipyBFGS(1)), progress=False,
                  **kwargs)


def test_checkpoint_is_refused_with_observations(tmp_path):
    with pytest.raises(ValueError, match=r"checkpoint= is not supported for observations"):
        learn.fit(learn.LPNet(BODY, hidden=(4,)), _small_data(), optimiser=learn.Adam(1),
                  checkpoint=learn.Checkpoint(tmp_path / "c.h5"), progress=False)
    assert not (tmp_path / "c.h5").exists()


def test_observations_of_another_dimension_are_refused():
    top = lp.systems.HeavyTop()
    data = it.Observations(top, [0.0, 0.1, 0.25], np.random.default_rng(5).normal(size=(2, 3, 6)))
    with pytest.raises(ValueError, match=r"data has states of dimension 6 .*the model is for RigidBody.*dimension 3"):
        learn.fit(learn.GLPNet(BODY, 3), data, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(1)), progress=False)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"window": 0}, ValueError, r"TrajectoryLoss\.window must be an integer >= 1; got 0"),
        ({"window": 1.5}, TypeError, r"TrajectoryLoss\.window must be an integer"),
        ({"max_step": -1}, ValueError, r"TrajectoryLoss\.max_step must be finite and > 0; got -1"),
        ({"max_step": 0.0}, ValueError, r"TrajectoryLoss\.max_step must be finite and > 0"),
        ({"latent": "yes"}, TypeError, r"TrajectoryLoss\.latent must be True or False; got 'yes'"),
        ({"latent": 1}, TypeError, r"TrajectoryLoss\.latent must be True or False"),
    ],
)
def test_bad_trajectory_loss(kwargs, error, match):
    with pytest.raises(error, match=match):
        learn.TrajectoryLoss(**kwargs)


# -- 3. the loss ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def one_step():
    """A G-LPNet (random weights) against noisy observations with the one-step loss, and the
    same pairs predicted by hand: each pair's own step `with_h(dt).step(y0)`."""
    data = _observations(noise=1e-2, size=1.0, n=6)
    net = learn.GLPNet(BODY, 3, method=TripleJump, key=3, h=0.1)
    fitted, train, _, loss_fn, settings = observed_objective(net, data, learn.TrajectoryLoss(window=1, latent=False),
                                                             None, 0.0, 0)
    y0, _, dt = data.pairs()
    by_hand = np.stack([np.asarray(_step(net.with_h(float(d)), jnp.asarray(a))) for a, d in zip(y0, dt)])
    return data, fitted, train, loss_fn, settings, by_hand


def test_one_step_loss_predicts_each_pair_at_its_own_step(one_step):
    data, fitted, train, loss_fn, settings, by_hand = one_step
    _, y1, dt = data.pairs()
    assert settings.description.substeps == 1 and settings.description.loss == "observations: window 1, observed starts"
    assert fitted.starts is None  # latent=False: segments start from their observations
    residuals = np.asarray(loss_fn.residuals(fitted, train))
    assert residuals.shape == (len(dt), 2, 3)  # one segment per pair, in the order of intervals()
    np.testing.assert_array_equal(residuals[:, 0], 0.0)  # the observed start is not predicted
    # The same step in two compiled programs (vmap + scan, and one step): they may round
    # differently, by a few eps |y| over TripleJump's 15 flows.
    np.testing.assert_allclose(residuals[:, 1], by_hand - y1, rtol=0, atol=64 * EPS)


def test_one_step_loss_is_the_mean_over_pairs(one_step):
    data, fitted, train, loss_fn, _, by_hand = one_step
    y1 = data.pairs()[1]
    want = np.mean(np.sum((by_hand - y1) ** 2, axis=-1)) / 3  # |step(y0) - y1|^2 / dim, averaged over pairs
    # residuals of ~0.03, each a few eps off (see above): a relative ~1e-13 at most
    assert float(loss_fn(fitted, train)) == pytest.approx(want, rel=1e-10)


def test_trajectory_loss_of_the_true_hamiltonian_is_round_off():
    # Noise-free observations with dropped samples (trajectories of different lengths, padded),
    # the true family at the true parameters, RK4 with 1000 sub-steps per interval (its
    # truncation error, ~(3e-4)^4 per unit time, is below round-off), latent starts
    # initialised at the exact first observations.
    data = _observations(noise=0.0, size=1.0, drop=0.2, n=6)
    assert len({t.size for t in data.times}) > 1
    model = learn.ParametricHamiltonian(BODY, _quadratic_family, INVERSE_INERTIA, substeps=1000)
    fitted, train, _, loss_fn, settings = observed_objective(model, data, learn.TrajectoryLoss(), None, 0.0, 0)
    assert settings.description.loss == "observations: trajectory, latent starts" and fitted.starts.shape == (6, 3)
    loss = float(loss_fn(fitted, train))
    # What is left is rounding: ~10^4 RK4 sub-steps per trajectory, each rounding y by
    # ~eps |y|, add up like a random walk to ~100 eps |y| at most (measured: RMS 12 eps |y|);
    # the heyoka observations are exact to a few eps. A wrong interval or a padded step
    # taken would leave an O(h) error, ~10^12 times more.
    assert 0 < loss <= (100 * EPS * data.rms_size()) ** 2, loss / EPS**2


def test_max_step_runs_each_interval_in_equal_sub_steps():
    data = _observations(noise=0.0, size=1.0, drop=0.2, n=6)
    dt_max = float(np.max(data.intervals()))
    net = learn.GLPNet(BODY, terms=learn.RidgeTerms(3, 3, key=2, activation="identity"), method=TripleJump)
    loss = learn.TrajectoryLoss(latent=False, max_step=dt_max / 3)
    fitted, train, _, loss_fn, settings = observed_objective(net, data, loss, None, 0.0, 0)
    assert settings.description.substeps == 3 and train.substeps == 3 and settings.description.max_step == dt_max / 3
    predicted = np.asarray(loss_fn.residuals(fitted, train)) + np.asarray(train.states)
    model = fitted.model
    for j, (t, y) in enumerate(zip(data.times, data.states)):
        z, by_hand = jnp.asarray(y[0]), [y[0]]
        for d in np.diff(t):
            third = model.with_h(float(d) / 3)
            for _ in range(3):
                z = _step(third, z)
            by_hand.append(np.asarray(z))
        # as above, up to 30 sub-steps of 15 flows each, in two compiled programs
        np.testing.assert_allclose(predicted[j, : t.size], np.array(by_hand), rtol=0, atol=256 * EPS)
    # and max_step = dt_max (or more) is one step per interval
    assert observed_objective(net, data, learn.TrajectoryLoss(max_step=dt_max), None, 0.0, 0)[4].description.substeps == 1


def _diamond() -> lp.systems.LiePoissonSystem:
    """A body on the solvable "diamond" algebra from its structure constants ([p, q] = z,
    [n, p] = p, [n, q] = -q): its coadjoint flows are `expm_action`'s, not a closed form."""
    C = np.zeros((4, 4, 4))
    for a, b, d, v in ((0, 1, 2, 1.0), (3, 0, 0, 1.0), (3, 1, 1, -1.0)):
        C[a, b, d], C[b, a, d] = v, -v
    g = lp.LieAlgebra(C, "diamond", ("p", "q", "z", "n"))
    return lp.systems.LiePoissonSystem(g, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 + m[3] ** 2), name="diamond")


@pytest.mark.slow
def test_trajectory_loss_on_a_generic_algebra_is_the_rollout_whichever_path_the_batch_takes():
    # The segments are mapped as samples: every coadjoint flow of a step takes the Taylor path
    # (or the matrix exponential) that the batch's largest |t M(alpha)| picks. Segments of
    # sizes 0.02 and 3 in one batch: the small one goes through the large one's path, and
    # must still be its own rollout. By hand: one step at a time outside any sample axis (the
    # matrix exponential by scaling and squaring).
    system = _diamond()
    y0 = np.array([[0.02, -0.01, 0.015, 0.01], [3.0, -2.0, 1.0, 2.5]])
    data = it.observe(system, y0, it.uneven_times(2, 8, (0.05, 0.3), seed=3))
    net = learn.GLPNet(system, terms=learn.RidgeTerms(4, 4, key=1, activation="identity"), method=TripleJump)
    fitted, train, _, loss_fn, _ = observed_objective(net, data, learn.TrajectoryLoss(latent=False), None, 0.0, 0)
    predicted = np.asarray(loss_fn.residuals(fitted, train)) + np.asarray(train.states)
    for j, (t, y) in enumerate(zip(data.times, data.states)):
        z, by_hand = jnp.asarray(y[0]), [y[0]]
        for d in np.diff(t):
            z = _step(fitted.model.with_h(float(d)), z)
            by_hand.append(np.asarray(z))
        # 7 steps of 9 flows, each exact to a few eps relative in either form (Taylor on
        # vectors or scaling and squaring), on states growing by e^{|t M|} at most: 256 eps of
        # the segment's own size (a wrong path, e.g. degree 10 at |t M| = 1, is off by ~1e-8)
        size = np.max(np.abs(by_hand))
        np.testing.assert_allclose(predicted[j, : t.size], np.array(by_hand), rtol=0, atol=256 * EPS * size)


# -- 4. Casimirs ------------------------------------------------------------------------------------
def test_map_fitted_to_noisy_observations_keeps_the_casimir(noisy_fit):
    data, model, records = noisy_fit
    spread = [np.std(BODY.casimirs(y)) / np.mean(BODY.casimirs(y)) for y in data.states]
    assert min(spread) > 1e-3  # the observations themselves are on no common leaf
    assert records[-1].train_loss < 1e-3 * data.rms_size() ** 2  # it did fit (the noise variance is 2.5e-5)
    y = np.asarray(model.rollout(np.stack([s[0] for s in data.states]), 1000))
    # Every step is 15 exact flows (three Strang steps of 5; rotations for the rigid body),
    # each keeping |y|^2 to a rounding of a few eps: over 1.5e4 flows such roundings add up
    # like a random walk, ~sqrt(1.5e4) = 122 eps (measured: 70 eps). A step that does not
    # keep the Casimir (RK4 at this step) drifts by ~1.5e-7, 10^6 times more.
    assert model.exact_flows_per_step == 15
    assert _casimir_relative_drift(y) <= 1000 * EPS


# -- 5. ParametricHamiltonian -----------------------------------------------------------------------
@pytest.mark.slow
def test_parametric_hamiltonian_recovers_the_inverse_inertia_differences():
    data = _observations(noise=0.0, size=1.0, n=6)
    model = learn.ParametricHamiltonian(BODY, _quadratic_family, np.ones(3))
    fitted, record = learn.fit(model, data, loss=learn.TrajectoryLoss(), optimiser=learn.KeepIfBetter(learn.ScipyBFGS(200)),
                               validation_fraction=0.0, progress=False)
    assert isinstance(fitted, learn.ParametricHamiltonian) and record.loss == "observations: trajectory, latent starts"
    theta = np.asarray(fitted.theta)
    # Only differences are identified: adding k to every d_i adds k |y|^2, a Casimir, to H.
    got = theta[:, None] - theta[None, :]
    want = INVERSE_INERTIA[:, None] - INVERSE_INERTIA[None, :]
    # The fit absorbs the truncation error of RK4 (10 sub-steps of at most 0.03 per interval),
    # which moves theta by O((0.03)^4): measured 2e-10 (at 4 sub-steps, (10/4)^4 = 39 times
    # more: 8e-9).
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8)
    # a map of the right Hamiltonian
    np.testing.assert_allclose(np.asarray(fitted.hamiltonian(data.states[0])) -
                               np.asarray(BODY.hamiltonian(data.states[0])),
                               0.5 * (theta[0] - INVERSE_INERTIA[0]) * np.sum(data.states[0] ** 2, -1),
                               rtol=0, atol=1e-8)


def test_parametric_hamiltonian_cannot_be_saved(tmp_path):
    model = learn.ParametricHamiltonian(BODY, _quadratic_family, INVERSE_INERTIA, h=0.1)
    with pytest.raises(ValueError, match=r"this ParametricHamiltonian cannot be saved.*function"):
        model.save(tmp_path / "p.h5")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("hamiltonian", "theta", "error", "match"),
    [
        (_quadratic_family, np.ones((3, 1)), ValueError, r"theta must be a non-empty finite 1-D array"),
        (_quadratic_family, [], ValueError, r"theta must be a non-empty finite 1-D array"),
        (_quadratic_family, [1.0, np.nan, 1.0], ValueError, r"theta must be a non-empty finite 1-D array"),
        (_quadratic_family, 1.0, ValueError, r"theta must be a non-empty finite 1-D array"),
        (lambda y, d: d * y, np.ones(3), ValueError, r"hamiltonian\(y, theta\) must return a scalar; got shape \(3,\)"),
        ("0.5 * y @ y", np.ones(3), TypeError, r"hamiltonian must be a function \(y, theta\) -> scalar"),
    ],
)
def test_bad_parametric_hamiltonian(hamiltonian, theta, error, match):
    with pytest.raises(error, match=match):
        learn.ParametricHamiltonian(BODY, hamiltonian, theta)


# -- 6. quadratic_part -------------------------------------------------------------------------------
def _symmetric(rng, n=3):
    a = rng.normal(size=(n, n))
    return a + a.T


@pytest.mark.slow
@given(seed=st.integers(0, 2**32 - 1), k=st.floats(-10.0, 10.0))
def test_quadratic_part_sees_through_the_casimir(seed, k):
    rng = np.random.default_rng(seed)
    A, b, c = _symmetric(rng), rng.normal(size=3), float(rng.normal())
    samples = rng.normal(size=(40, 3))

    def plain(y):
        return 0.5 * np.einsum("ni,ij,nj->n", y, A, y) + y @ b + c

    part = learn.quadratic_part(plain, BODY, samples)
    with_casimir = learn.quadratic_part(lambda y: plain(y) + k * np.sum(y**2, -1), BODY, samples)
    # The rigid body's Casimir |y|^2 has Hessian 2 I.
    np.testing.assert_allclose(part.casimir_hessians, 2 * np.eye(3)[None], rtol=0, atol=1e-12)
    # Least squares on 40 samples (a condition number of ~10) of values of size ~10 + |k| |y|^2:
    # coefficients to some eps of that size (measured on 200 draws: at most 23 of them).
    tol = 200 * EPS * (10 + abs(k))
    np.testing.assert_allclose(part.matrix, A, rtol=0, atol=tol)
    np.testing.assert_allclose(with_casimir.matrix, A + 2 * k * np.eye(3), rtol=0, atol=tol)
    np.testing.assert_allclose(with_casimir.identifiable(), part.identifiable(), rtol=0, atol=tol)
    np.testing.assert_allclose(part.identifiable(), A - np.trace(A) / 3 * np.eye(3), rtol=0, atol=tol)
    for q in (part, with_casimir):
        np.testing.assert_allclose(q.linear, b, rtol=0, atol=tol)
        assert q.constant == pytest.approx(c, abs=tol)
        assert q.residual < 200 * EPS  # relative to the values' spread (measured: at most 23 eps)
    # the identified differences A_ii - A_jj (i < j, row-major) are the same with the Casimir
    d = np.diag(A)
    np.testing.assert_allclose(with_casimir.diagonal_differences(), [d[0] - d[1], d[0] - d[2], d[1] - d[2]],
                               rtol=0, atol=2 * tol)


def test_quadratic_part_of_the_rigid_body_and_of_a_quartic():
    samples = np.random.default_rng(6).normal(size=(50, 3))
    part = learn.quadratic_part(lambda y: np.asarray(BODY.hamiltonian(y)), BODY, samples)
    np.testing.assert_allclose(part.diagonal_differences(),
                               [INVERSE_INERTIA[0] - INVERSE_INERTIA[1], INVERSE_INERTIA[0] - INVERSE_INERTIA[2],
                                INVERSE_INERTIA[1] - INVERSE_INERTIA[2]], rtol=0, atol=1e-13)
    # A quartic term is not quadratic, whatever the fit: its residual is a sizeable part of
    # the variation (0 to round-off for a quadratic).
    quartic = learn.quadratic_part(lambda y: np.asarray(BODY.hamiltonian(y)) + 0.1 * y[:, 0] ** 4, BODY, samples)
    assert quartic.residual > 0.05


def test_quadratic_part_bad_input():
    with pytest.raises(ValueError, match=r"a quadratic in 3 variables has 10 coefficients; give at least that many "
                                         r"samples \(got 9\)"):
        learn.quadratic_part(lambda y: np.sum(y**2, -1), BODY, np.ones((9, 3)))
    learn.quadratic_part(lambda y: np.sum(y**2, -1), BODY, np.random.default_rng(7).normal(size=(10, 3)))  # enough
    with pytest.raises(ValueError, match=r"samples must have shape \(N, 3\); got \(20, 2\)"):
        learn.quadratic_part(lambda y: np.sum(y**2, -1), BODY, np.ones((20, 2)))
    with pytest.raises(ValueError, match=r"one finite value per sample"):
        learn.quadratic_part(lambda y: np.full(len(y), np.nan), BODY, np.random.default_rng(7).normal(size=(20, 3)))
    with pytest.raises(ValueError, match=r"one finite value per sample"):
        learn.quadratic_part(lambda y: np.ones(3), BODY, np.random.default_rng(7).normal(size=(20, 3)))


# -- 7. information criterion -------------------------------------------------------------------------
def test_criteria_the_criterion_cannot_tell_apart_choose_the_fewest_parameters_then_the_first():
    from learn._training._criterion import BIC_RESOLUTION, lowest

    # a clear winner wins, whatever its parameters
    assert lowest([(-100.0, 3), (-105.0, 20), (-90.0, 1)]) == 1
    # within the resolution of the lowest: fewer effective parameters first ...
    assert lowest([(-100.0, 5), (-100.0 - BIC_RESOLUTION / 2, 8), (-100.0 + BIC_RESOLUTION / 4, 3)]) == 2
    # ... then the first fitted, even when a later one is lower by round-off
    assert lowest([(-45774.3654, 3), (-45774.3654 - 1e-9, 3)]) == 0
    # a fit just beyond the resolution is not a tie
    assert lowest([(-100.0, 3), (-100.0 - 2 * BIC_RESOLUTION, 8)]) == 1


@pytest.mark.slow
def test_redundant_weights_count_once_in_the_information_criterion():
    data = _observations(noise=1e-2, size=1.0, n=4)
    criteria, n_parameters = {}, {}
    for linear_term in (False, True):
        terms = learn.RidgeTerms(3, 3, key=2, activation="identity", linear_term=linear_term)
        if linear_term:  # split each slope between a and e: the same map
            e = jnp.array([0.3, -0.2, 0.1])
            terms = eqx.tree_at(lambda t: (t.a, t.e), terms, (terms.a - e, e))
        net = learn.GLPNet(BODY, terms=terms, method=TripleJump)
        fitted, _, _, _, problem = observed_objective(net, data, None, None, 0.0, 0)
        criteria[linear_term] = information_criterion(problem, fitted)
        n_parameters[linear_term] = net.n_parameters
    assert n_parameters == {False: 9, True: 12}
    # With the identity, Phi' = (a + e) x + b: a and e only enter as their sum. And the piece
    # of module s moves y by the rate (a_s c_s^2 y_k + b_s c_s) e_k: 2 effective parameters
    # per module.
    assert criteria[True]["effective_parameters"] == criteria[False]["effective_parameters"] == 6
    assert criteria[True]["n"] == criteria[False]["n"] == data.n_observations * 3
    assert criteria[True]["ssr"] == pytest.approx(criteria[False]["ssr"], rel=1e-12)  # the same map
    assert criteria[True]["bic"] == pytest.approx(criteria[False]["bic"], rel=1e-9)


# -- 8. RidgeTerms(bias=False) ------------------------------------------------------------------------
# the identity activation by default (the observations' fits use it), the others with -m slow
@pytest.mark.parametrize(("activation", "linear_term"), [
    ("identity", False), pytest.param("sigmoid", True, marks=pytest.mark.slow),
    pytest.param("tanh", False, marks=pytest.mark.slow)])
def test_no_bias_is_a_zero_bias(activation, linear_term):
    no_bias = learn.RidgeTerms(3, 4, key=5, activation=activation, linear_term=linear_term, bias=False)
    assert no_bias.b is None and not no_bias.bias
    np.testing.assert_array_equal(no_bias.bias_values(), np.zeros(4))
    zero_bias = learn.RidgeTerms(3, 4, key=5, activation=activation, linear_term=linear_term)
    assert zero_bias.bias and zero_bias.b is not None
    zero_bias = eqx.tree_at(lambda t: t.b, zero_bias, jnp.zeros(4))
    np.testing.assert_array_equal(no_bias.a, zero_bias.a)  # the same key draws the same other weights
    np.testing.assert_array_equal(no_bias.c, zero_bias.c)
    y = jnp.asarray(_starts(5, 1.3, seed=8))
    for s in range(4):
        flows = [jax.vmap(lambda state, t=t, s=s: t.flow(BODY, s, 0.3, state))(y) for t in (no_bias, zero_bias)]
        np.testing.assert_array_equal(*flows)  # so every step, a composition of these flows, too
    nets = [learn.GLPNet(BODY, terms=t, method=TripleJump, h=0.2) for t in (no_bias, zero_bias)]
    np.testing.assert_array_equal(nets[0].hamiltonian(y), nets[1].hamiltonian(y))
    assert nets[0].n_parameters == nets[1].n_parameters - 4
    assert no_bias.reinitialised(9).b is None


def test_default_spec_has_no_bias_key():
    # files written before `bias` existed have none: a default G-LPNet's stays the same
    assert "bias" not in learn.GLPNet(BODY).hyperparameters()
    assert "bias" not in learn.RidgeTerms(3, 3).spec()
    assert learn.RidgeTerms(3, 3, bias=False).spec()["bias"] is False


def test_glpnet_without_bias_round_trips_through_a_file(tmp_path):
    terms = learn.RidgeTerms(3, 3, key=1, activation="identity", bias=False)
    net = learn.GLPNet(BODY, terms=terms, method=TripleJump, h=0.2)
    net.save(tmp_path / "g.h5")
    back = learn.GLPNet.load(tmp_path / "g.h5", BODY)
    assert back.terms.b is None and back.hyperparameters() == net.hyperparameters() and back.h == 0.2
    for got, want in ((back.terms.a, terms.a), (back.terms.c, terms.c)):
        np.testing.assert_array_equal(got, want)
    assert type(learn.load(tmp_path / "g.h5")) is learn.GLPNet


# -- 9. LPNet with the step as an input -----------------------------------------------------------------
N_PARAMS = learn.default_parametrisation(BODY).n_params


@pytest.fixture(scope="module")
def step_lpnet():
    return learn.LPNet(BODY, network=learn.AffineMLP(4, N_PARAMS, (8,), key=0))


def test_lpnet_with_a_step_input(step_lpnet):
    assert step_lpnet.takes_step and not learn.LPNet(BODY, hidden=(8,)).takes_step
    y = jnp.array([0.3, -0.7, 0.5])
    a1, a2 = (step_lpnet.with_h(h).alpha(y) for h in (0.1, 0.2))
    assert np.max(np.abs(a1 - a2)) > 1e-6  # the network sees h
    np.testing.assert_array_equal(a1, step_lpnet.network(jnp.array([0.3, -0.7, 0.5, 0.1])))
    np.testing.assert_array_equal(step_lpnet.with_h(0.1).network_inputs(y), [0.3, -0.7, 0.5, 0.1])
    # The flow time is h: at h = 1e-12 the step is y + h B(y) alpha(y, h) (the test flow's
    # velocity; the O(h^2) term is 1e-24), to the rounding of y, a few eps |y|.
    tiny = step_lpnet.with_h(1e-12)
    moved = np.asarray(tiny.step(y)) - np.asarray(y)
    velocity = np.asarray(BODY.poisson_tensor(y) @ tiny.alpha(y))
    assert np.max(np.abs(moved)) > 1e-14  # it does move, by h |B alpha| ~ 1e-12
    np.testing.assert_allclose(moved, 1e-12 * velocity, rtol=0, atol=4 * EPS * float(jnp.linalg.norm(y)))
    # and its Casimir is kept at any step
    z = np.asarray(step_lpnet.with_h(0.3).rollout(y, 200))
    assert _casimir_relative_drift(z) <= 200 * EPS


def test_lpnet_with_a_step_input_round_trips(step_lpnet, tmp_path):
    net = step_lpnet.with_h(0.15)
    net.save(tmp_path / "s.h5")
    back = learn.LPNet.load(tmp_path / "s.h5", BODY)
    assert back.takes_step and back.h == 0.15 and back.hyperparameters() == net.hyperparameters()
    for got, want in zip(jax.tree_util.tree_leaves(eqx.filter(back, eqx.is_array)),
                         jax.tree_util.tree_leaves(eqx.filter(net, eqx.is_array))):
        np.testing.assert_array_equal(got, want)
    y = jnp.array([0.3, -0.7, 0.5])
    np.testing.assert_array_equal(back.step(y), net.step(y))


def test_lpnet_network_of_the_wrong_input_size_is_refused():
    with pytest.raises(ValueError, match=r"network must map states \(or states and the step, dim \+ 1\) to the "
                                         r"parameters of TestFlowParametrisation \(3 to 3\); got in_size=5"):
        learn.LPNet(BODY, network=learn.AffineMLP(5, N_PARAMS, (8,), key=0))


@pytest.mark.slow  # two fit_splitting calls of three families: 8 s
def test_an_extension_of_a_family_that_misfits_is_skipped():
    # principal axes 0.95 rad off the basis: the quadratic on the axes leaves residuals far
    # above 100x those of any quadratic form, so its sigmoid extension ("general", pieces on the
    # same axes) is not fitted; on the aligned body the axes hold it and it is fitted
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec([0.4, -0.7, 0.5]).as_matrix()
    A = R @ np.diag(INVERSE_INERTIA) @ R.T
    rotated = lp.systems.LiePoissonSystem(
        lp.so3(), lambda m, xp: 0.5 * sum(A[i, j] * m[i] * m[j] for i in range(3) for j in range(3)), name="rotated")
    families = [f for f in learn.FAMILIES if f.name in ("quadratic", "quadratic, any axes, even", "general")]
    y0 = np.random.default_rng(0).normal(size=(4, 3))
    times = 0.1 * np.arange(8)
    for system, skipped in ((rotated, ["general"]), (BODY, [])):
        obs = it.observe(system, y0 / np.linalg.norm(y0, axis=1, keepdims=True), times, noise=1e-3, seed=1)
        with warnings.catch_warnings(record=True) as caught:  # a skipped family warns
            warnings.simplefilter("always")
            _, records = learn.fit_splitting(system, obs, families=families, iterations=5, progress=False)
        assert [str(w.message).split(" not fitted")[0] for w in caught] == [f"fit_splitting: family {s!r}" for s in skipped]
        details = [r.stages[-1].details for r in records]
        assert sorted(d["family"] for d in details) == sorted(f.name for f in families if f.name not in skipped)
        assert details[-1]["skipped"] == skipped
        if skipped:
            ssr = {d["family"]: d["ssr"] for d in details}
            assert ssr["quadratic"] > 100 * ssr["quadratic, any axes, even"]
        else:  # the extension must beat the best criterion so far: a loss below its nested family's,
            # whose parameters it has and more (exp((BIC* - k log n) / n) with BIC* <= the nested's)
            by_name = {d["family"]: d for d in details}
            nested = by_name["quadratic"]
            assert 0 < by_name["general"]["target_loss"] < nested["ssr"] / nested["n"]
            assert nested["target_loss"] is None  # a family that extends none has no target


def test_families_contain_the_simpler_ones_as_their_definitions_say():
    by = {f.name: f for f in learn.FAMILIES}
    holds = {  # each member of the right-hand family is one of the left-hand one's, by the Family fields
        ("quadratic", "quadratic, even"), ("quadratic, any axes", "quadratic"),
        ("quadratic, any axes, even", "quadratic, even"), ("general", "quadratic"),
        ("general, any axes", "quadratic, any axes"), ("general, any axes", "general"),
        ("quadratic", "quadratic, selected"),
    }
    fails = {  # no linear terms; no learned directions; sigmoids; nothing inside a selection
        ("quadratic, any axes, even", "quadratic"), ("general", "quadratic, any axes"),
        ("quadratic, any axes", "general"), ("quadratic, selected", "quadratic, even"),
    }
    for big, small in holds:
        assert by[big].contains(by[small]), (big, small)
    for big, small in fails:
        assert not by[big].contains(by[small]), (big, small)
    # a sigmoid family without the linear term e_s x holds no member that has it, and
    # conversely; an equal family is not contained
    bare, full = (learn.Family(name, "sigmoid", linear_term=lt, bias=True) for name, lt in (("bare", False),
                                                                                          ("full", True)))
    assert full.contains(bare) and not bare.contains(full)
    assert not by["general"].contains(learn.Family("general", "sigmoid", linear_term=True, bias=True,
                                                   nested="quadratic"))
    for f in learn.FAMILIES:
        assert not f.contains(f)
        for g in learn.FAMILIES:  # a partial order: never both ways, and transitive
            assert not (f.contains(g) and g.contains(f))
            for k in learn.FAMILIES:
                assert not (f.contains(g) and g.contains(k)) or f.contains(k)


@pytest.mark.slow  # the sub-steps by default in test_max_step_runs_each_interval_in_equal_sub_steps; the skip using this figure runs with -m slow
def test_the_discretisation_error_is_the_methods_own_and_falls_with_its_order():
    # a G-LPNet (TripleJump, order 4) of the true H on exact data: the difference of its
    # predictions at s and 2s sub-steps falls 2^4 per doubling in size, so 2^8 in the SSR
    # (within 20%: the next order's term), and the map's SSR against exact data is that
    # difference's (2^4 / (2^4 - 1))^2 times, within the same margin
    from learn._training._observed import discretisation_ssr

    data = _observations(0.0, size=1.0, n=4)
    net = learn.GLPNet(BODY, terms=learn.FAMILIES[0].terms_of(BODY, np.diag(INVERSE_INERTIA), np.zeros(3), 1.0),
                       method=TripleJump())
    ssr = {}
    for substeps, max_step in ((1, None), (2, 0.15)):
        start, train, _, objective, problem = observed_objective(
            net, data, learn.TrajectoryLoss(max_step=max_step), None, 0.0, 0)
        start = eqx.tree_at(lambda f: f.starts, start, jnp.asarray(np.stack([s[0] for s in data.states])))
        assert train.substeps == substeps
        ssr[substeps] = (discretisation_ssr(problem, start), float(jnp.sum(objective.residuals(start, train) ** 2)))
    assert 0.8 * 2**8 < ssr[1][0] / ssr[2][0] < 1.2 * 2**8
    for floor, error in ssr.values():
        assert 0.8 < error / (floor * (16 / 15) ** 2) < 1.2


@pytest.mark.slow
def test_exact_data_a_family_explains_within_its_step_skip_its_extensions_along_the_same_directions():
    # the aligned rigid body's exact trajectories: "quadratic, even" holds its H, its residuals
    # are within its own discretisation error, and the families adding terms along the same axes
    # are skipped; learned directions are still fitted (another splitting of the same H)
    names = ("quadratic, even", "quadratic", "quadratic, any axes, even", "general")
    families = [f for f in learn.FAMILIES if f.name in names]
    exact = _observations(0.0, size=1.0, n=4)
    with pytest.warns(UserWarning, match="not fitted"):
        _, records = learn.fit_splitting(BODY, exact, families=families, iterations=20, progress=False)
    details = {r.stages[-1].details["family"]: r.stages[-1].details for r in records}
    assert sorted(details) == ["quadratic, any axes, even", "quadratic, even"]
    assert records[-1].stages[-1].details["skipped"] == ["quadratic", "general"]
    assert details["quadratic, even"]["ssr"] <= details["quadratic, even"]["discretisation_ssr"]


@pytest.mark.slow  # four families on a non-polynomial body: 8 s
def test_exact_data_outside_every_quadratic_skip_nothing():
    # the logarithmic term of this body is outside every quadratic: residuals far above the
    # step's error, and every family is fitted
    names = ("quadratic, even", "quadratic", "quadratic, any axes, even", "general")
    families = [f for f in learn.FAMILIES if f.name in names]
    kappa, v = 0.3, np.array([0.6, 0.0, 0.8])
    log_body = lp.systems.LiePoissonSystem(
        lp.so3(), lambda m, xp: 0.5 * sum(INVERSE_INERTIA[i] * m[i] ** 2 for i in range(3))
        + kappa * xp.log(1.0 + (v[0] * m[0] + v[2] * m[2]) ** 2), name="logarithmic")
    obs = it.observe(log_body, _starts(4, 1.0), it.uneven_times(4, N_OBS, (0.05, 0.3), seed=1), noise=0.0, seed=0)
    _, records = learn.fit_splitting(log_body, obs, families=families, iterations=20, progress=False)
    details = [r.stages[-1].details for r in records]
    assert details[-1]["skipped"] == [] and len(details) == 4
    first = next(d for d in details if d["family"] == "quadratic, even")
    assert first["ssr"] > 100 * first["discretisation_ssr"]
