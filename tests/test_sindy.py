"""SINDy and weak SINDy (`paper._sindy`, pysindy) as peers: each recovers Euler's equations of
the rigid body from exact data with its settings chosen by every study's rule
(`choose_sparse_field`: the training trajectories' rollouts from fitted starts), the rule
keeps the sparser of two equally good fields, and on noisy data the true one where the
first observations' score does not; on noisy uneven data SINDy takes a smoothing spline's
rates. Skipped without pysindy (extra `peers`)."""

import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from paper._sindy import (  # imports pysindy only when fitting
    PolynomialField,
    SINDyModel,
    WeakSINDyModel,
    choose_sparse_field,
    derivative_rows,
    fit_sindy,
    fit_weak_sindy,
    fitted_start_error,
    rollout_error,
)

pytest.importorskip("pysindy")

EPS = np.finfo(np.float64).eps
INERTIA = (2.0, 1.0, 2.0 / 3.0)
BODY = lp.systems.RigidBody(inertia=INERTIA)


def _sphere(n: int, seed: int) -> np.ndarray:
    y = np.random.default_rng(seed).normal(size=(n, 3))
    return y / np.linalg.norm(y, axis=1, keepdims=True)


def _euler_coefficients() -> np.ndarray:
    """Euler's equations in pysindy's degree-2 monomials: Pi1' = (1/I3 - 1/I2) Pi2 Pi3 and cyclic."""
    i1, i2, i3 = INERTIA
    xi = np.zeros((3, 10))  # monomials 1, x0, x1, x2, x0^2, x0 x1, x0 x2, x1^2, x1 x2, x2^2
    xi[0, 8], xi[1, 6], xi[2, 5] = 1 / i3 - 1 / i2, 1 / i1 - 1 / i3, 1 / i2 - 1 / i1
    return xi


def _regular_data() -> it.Observations:
    """6 trajectories x 41 exact observations at h = 0.05 (t in [0, 2]), on |Pi| = 1."""
    return it.observe(BODY, _sphere(6, 0), 0.05 * np.arange(41))


def test_sindy_recovers_euler_equations_from_exact_rates():
    data = _regular_data()
    rates = [np.asarray(BODY.vector_field(y)) for y in data.states]
    chosen = fit_sindy(list(data.times), list(data.states), rates=rates)
    field = chosen.field
    assert field.names == ("1", "x0", "x1", "x2", "x0^2", "x0 x1", "x0 x2", "x1^2", "x1 x2", "x2^2")
    # no spurious term: exactly Euler's three products are nonzero (on |Pi| = 1 the constant and
    # |Pi|^2 are one column: the rule keeps the library without the constant, the sparser)
    assert np.array_equal(field.coefficients != 0, _euler_coefficients() != 0)
    assert not chosen.constant and field.terms == 3
    # least squares on exact rates of three well-conditioned columns: round-off only
    assert np.max(np.abs(field.coefficients - _euler_coefficients())) < 100 * EPS
    assert field.coefficient(0, (0, 1, 1)) == pytest.approx(0.5, abs=100 * EPS)
    # its training rollouts (LSODA at 1e-12) follow the observations to LSODA's error
    assert chosen.train_error < 1e-9


def test_sindy_from_exact_states_keeps_euler_terms_only():
    """From the states alone, the derivative chosen among finite differences (second order) and
    smoothed ones: the same three terms, the coefficients to the derivative's error."""
    data = _regular_data()
    chosen = SINDyModel().fit(BODY, data).step_map.model
    assert np.array_equal(chosen.field.coefficients != 0, _euler_coefficients() != 0)
    # the derivative's error at h = 0.05 on rates of size ~0.5 (measured 5.6e-5)
    assert np.max(np.abs(chosen.field.coefficients - _euler_coefficients())) < 1e-3


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_weak_sindy_recovers_euler_equations_and_follows_heyoka():
    model = WeakSINDyModel(windows=(9, 33))
    data = _regular_data()
    fitted = model.fit(BODY, data)
    chosen = fitted.step_map.model
    assert isinstance(chosen.field, PolynomialField) and chosen.setting in ("window 9", "window 33")
    # every other term is thresholded to exactly zero; the three products to the quadrature's
    # error (piecewise-linear interpolants on h = 0.05, smooth test functions; measured 2.5e-10
    # on the window of 33 steps the rule keeps)
    assert np.array_equal(chosen.field.coefficients != 0, _euler_coefficients() != 0)
    assert np.max(np.abs(chosen.field.coefficients - _euler_coefficients())) < 1e-6
    # simulated (LSODA) from held-out states over t = 2 against heyoka: the coefficients' error
    y0 = _sphere(3, 1)
    reference = it.ground_truth(BODY, y0, 0.1, 20).states
    states = model.simulate(fitted, y0, 20, 0.1)
    assert states.shape == reference.shape
    assert np.max(np.abs(states - reference)) < 1e-6

    # uneven (steps from [0.05, 0.3]), each trajectory on its own grid: the same terms, the
    # piecewise-linear quadrature's error on the coarser steps (measured 4.4e-4)
    uneven = it.observe(BODY, _sphere(6, 0), it.uneven_times(6, 21, (0.05, 0.3), seed=0))
    assert not uneven.is_regular() and model.accepts(uneven)
    field = fit_weak_sindy(list(uneven.times), list(uneven.states), windows=(9, 33)).field
    assert np.array_equal(field.coefficients != 0, _euler_coefficients() != 0)
    assert np.max(np.abs(field.coefficients - _euler_coefficients())) < 1e-3


def test_the_rule_keeps_the_sparser_of_equally_good_fields_and_never_sees_a_test():
    """Rows of Euler's rates plus a tiny spurious term: the field with it and the field without
    follow the training trajectories equally well (within TIE_RTOL); the rule keeps the one
    without. A threshold that cuts a true term diverges from the training rollouts: refused."""
    data = _regular_data()
    times, states = list(data.times), list(data.states)
    rates = [np.asarray(BODY.vector_field(y)) + 1e-7 * y[:, :1] for y in states]  # + 1e-7 x0 in each rate
    features, targets = derivative_rows(times, states, "", rates)
    chosen = choose_sparse_field(times, states, {"rates given": (features, targets)}, thresholds=(0.0, 0.03, 0.4))
    assert chosen.threshold == 0.03 and chosen.field.terms == 3  # 0.0 keeps x0 (12 terms), 0.4 cuts 1/3 - 1/2
    exact = PolynomialField(chosen.field.powers, chosen.field.names, _euler_coefficients())
    assert rollout_error(exact, times, states) < 1e-9


def test_the_rule_scores_rollouts_from_fitted_starts_on_noisy_data():
    """On noisy data a rollout from the first observation is dominated by that observation's
    error: scored so, the rule kept a wrong field of 13 terms on this case (8 trajectories x 21
    observations at h = 0.1 of the body I = (1, 1.1, 1.3), whose smallest Euler coefficient is
    -0.09, noise 1e-2); from starts fitted by least squares it keeps Euler's three terms, their
    coefficients to 0.013 (measured) of the truth."""
    inertia = (1.0, 1.1, 1.3)
    body = lp.systems.RigidBody(inertia=inertia)
    data = it.observe(body, _sphere(8, 0), 0.1 * np.arange(21), noise=1e-2, seed=0)
    times, states = list(data.times), list(data.states)
    rows = {d: derivative_rows(times, states, d) for d in ("finite differences", "smoothed finite differences")}
    thresholds = (0.003, 0.01, 0.03, 0.1, 0.3)
    i1, i2, i3 = inertia
    euler = np.zeros((3, 10))
    euler[0, 8], euler[1, 6], euler[2, 5] = 1 / i3 - 1 / i2, 1 / i1 - 1 / i3, 1 / i2 - 1 / i1
    chosen = choose_sparse_field(times, states, rows, thresholds)
    assert np.array_equal(chosen.field.coefficients != 0, euler != 0)
    assert np.max(np.abs(chosen.field.coefficients - euler)) < 0.02  # the noise's share (measured 0.0127)
    # the fitted starts' score is below the first observations' (each start's best iterate is
    # kept, the first observation its first), on the same field
    assert fitted_start_error(chosen.field, times, states) < rollout_error(chosen.field, times, states)
    # the former score (first observations) on the same candidates keeps a denser, wrong field
    former = choose_sparse_field(times, states, rows, thresholds, score=rollout_error)
    assert former.field.terms > 3 and np.max(np.abs(former.field.coefficients - euler)) > 0.1


def test_sindy_on_noisy_uneven_data_takes_the_smoothing_splines_rates():
    """Uneven times (steps from [0.05, 0.3]) and noise 1e-2: the rule takes the smoothing
    spline's derivative (the Savitzky-Golay smoother needs even spacing), and its coefficients
    of Euler's three terms are 3x closer than those from finite differences alone (measured
    0.014 and 0.046)."""
    y0 = np.random.default_rng(2).normal(size=(8, 3))
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    data = it.observe(BODY, y0, it.uneven_times(8, 21, (0.05, 0.3), seed=2), noise=1e-2, seed=2)
    times, states = list(data.times), list(data.states)
    chosen = fit_sindy(times, states)
    assert chosen.setting == "smoothing spline"
    assert np.array_equal(chosen.field.coefficients != 0, _euler_coefficients() != 0)
    assert np.max(np.abs(chosen.field.coefficients - _euler_coefficients())) < 0.02
    finite = choose_sparse_field(times, states, {"finite differences": derivative_rows(times, states, "finite differences")})
    assert np.max(np.abs(finite.field.coefficients - _euler_coefficients())) > 0.03


def test_bad_settings_are_refused():
    body = BODY
    short = it.Observations(body, [np.array([0.0, 0.1, 0.2])], [np.tile([0.6, 0.0, 0.8], (3, 1))])
    model = WeakSINDyModel()
    assert not model.accepts(short)
    with pytest.raises(ValueError, match="at least 4 observations"):
        model.fit(body, short)
    with pytest.raises(ValueError, match="windows"):
        WeakSINDyModel(windows=(1,))
    with pytest.raises(ValueError, match="test_functions"):
        WeakSINDyModel(test_functions=0)
    with pytest.raises(ValueError, match="thresholds"):
        SINDyModel(thresholds=(-0.1,))
    with pytest.raises(ValueError, match="thresholds"):
        SINDyModel(thresholds=())
