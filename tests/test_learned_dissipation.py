"""Learned dissipation (`learn.LearnedDrag`, `learn.Dissipative`, `learn.fit_dissipative`): the drag's
matrix positive semidefinite and its sub-step never raising the learned energy for any weights
and steps, the zero drag as the G-LPNet, files, a fit that finds a forced body's inertia, and bad
input."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS
from hypothesis import given, settings
from hypothesis import strategies as st

import integrators as it
import learn
from integrators.splitting import Strang, TripleJump
from liepoisson.systems import Forced, LinearDrag, QuadraticDrag, RigidBody

BODY = RigidBody((1.0, 1.9, 2.1))
#: A body in air: its inertia and its quadratic drag (the flights of `_flights`).
I, D = np.array([1.0, 1.9, 2.1]), np.diag([0.02, 0.03, 0.025])


def _net(seed: int, method=Strang) -> learn.GLPNet:
    """A G-LPNet of a quadratic H~ with random weights: curvatures of either sign, any axes."""
    rng = np.random.default_rng(seed)
    terms = learn.RidgeTerms(3, 3, activation="identity", full_vectors=True, linear_term=False, bias=True)
    terms = eqx.tree_at(lambda t: (t.a, t.c, t.b), terms,
                        (jnp.asarray(rng.normal(size=3)), jnp.asarray(rng.normal(size=(3, 3))),
                         jnp.asarray(rng.normal(size=3))))
    return learn.GLPNet(BODY, terms=terms, method=method, h=0.1)


def _flights(n: int, seed: int, records: int, noise: float, system=None) -> it.BodyObservations:
    """Gyroscope records every 10 ms of `n` flights from the identity attitude, spun about the
    middle axis (8-12 rad/s; N(0, 0.3) about the others; numpy seed `seed`), noise `noise`
    (seed 1): the body in air (`Forced(RigidBody(I), QuadraticDrag(D))`) unless `system`."""
    rng = np.random.default_rng(seed)
    omega = np.column_stack([rng.normal(0, 0.3, n), rng.uniform(8, 12, n), rng.normal(0, 0.3, n)])
    system = Forced(RigidBody(I), QuadraticDrag(D)) if system is None else system
    return it.observe_body(system, omega * I, np.tile([0, 0, 0, 1.0], (n, 1)), np.arange(records) * 0.01,
                           measure="velocities", noise=noise, seed=1)


def _drag(seed: int, kind: str, any_axes: bool) -> learn.LearnedDrag:
    """A drag with random weights of either sign (D must be positive semidefinite anyway)."""
    rng = np.random.default_rng(seed + 1)
    drag = learn.LearnedDrag(3, kind, any_axes=any_axes)
    drag = eqx.tree_at(lambda d: d.factor, drag, jnp.asarray(rng.normal(size=drag.factor.shape)))
    if drag.quadratic_factor is not None:
        drag = eqx.tree_at(lambda d: d.quadratic_factor, drag, jnp.asarray(rng.normal(size=3)))
    if drag.directions is not None:
        drag = eqx.tree_at(lambda d: d.directions, drag, jnp.asarray(rng.normal(size=(3, 3))))
    return drag


KINDS = [(k, a) for k in learn.DRAG_KINDS for a in (False, True)]


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from(KINDS))
def test_drag_matrix_is_positive_semidefinite_for_any_weights(seed, kind_axes):
    drag = _drag(seed, *kind_axes)
    xi = np.random.default_rng(seed).normal(size=(8, 3)) * 10.0
    D = np.asarray(jax.vmap(drag.matrix)(xi))
    np.testing.assert_allclose(D, np.swapaxes(D, 1, 2), atol=0)
    low = np.linalg.eigvalsh(D)[:, 0]
    # a sum of rank-one squares: its zero eigenvalues are zero to a few roundings of |D|
    assert np.all(low >= -16 * EPS * np.abs(D).max(axis=(1, 2)))
    assert np.all(np.einsum("sa,sa->s", xi, np.asarray(jax.vmap(drag.force)(xi))) <= 0.0)


@functools.cache
def _compiled_drag_flow():
    return jax.jit(lambda model, t, y: model.drag_flow(t, y))


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from(KINDS), st.floats(1e-3, 5.0))
def test_the_drag_step_never_raises_the_learned_energy(seed, kind_axes, t):
    # for any weights of H~ (curvatures of either sign) and of the drag, and any t > 0:
    # H~(mu1) - H~(mu0) = -t xi_bar^T D xi_bar <= 0 exactly for a quadratic H~; round-off is
    # relative to the energy's terms at both ends (|mu|^2 |A| + |b||mu|)
    model = learn.Dissipative(_net(seed), _drag(seed, *kind_axes))
    mu = np.random.default_rng(seed + 2).normal(size=(6, 3)) * 3.0
    flow = _compiled_drag_flow()
    for y in mu:
        y1 = np.asarray(flow(model, t, jnp.asarray(y)))
        if not np.all(np.isfinite(y1)):  # I + t D A/2 singular: possible only for an indefinite H~
            continue
        H0, H1 = float(model.hamiltonian(y)), float(model.hamiltonian(y1))
        scale = (np.abs(y) ** 2).sum() + (np.abs(y1) ** 2).sum() + 1.0
        A, b = model.quadratic_part()
        assert H1 <= H0 + 256 * EPS * scale * (float(np.abs(np.asarray(A)).max()) + float(np.abs(np.asarray(b)).max()))


def test_no_drag_is_the_glpnet():
    net = _net(3, TripleJump)
    model = learn.Dissipative(net, eqx.tree_at(lambda d: d.factor, learn.LearnedDrag(3, "quadratic"),
                                               jnp.zeros(3)))
    y = jnp.asarray([0.3, -1.2, 0.8])
    # two compositions of the same flows (a scan over the modules, a list): a few roundings
    np.testing.assert_allclose(np.asarray(model.step(y)), np.asarray(net.step(y)), rtol=0, atol=64 * EPS)
    g = jnp.asarray([0.0, 0.0, 0.0, 1.0])
    for a, b in zip(model.lifted_step(g, y), net.lifted_step(g, y)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=64 * EPS)


def test_the_drag_takes_angular_momentum_away():
    # not a Casimir-keeping map: |Pi| decays under the drag's step (air drag on a body), on the
    # rigid body's own H~ (curvatures 1/I on the axes)
    terms = learn.RidgeTerms(3, 3, activation="identity", full_vectors=False, linear_term=False, bias=False)
    terms = eqx.tree_at(lambda t: (t.a, t.c), terms, (jnp.asarray(1.0 / BODY.inertia), jnp.ones(3)))
    net = learn.GLPNet(BODY, terms=terms, method=Strang, h=0.1)
    np.testing.assert_allclose(float(net.hamiltonian(jnp.asarray([0.3, 2.0, 0.1]))),
                               float(BODY.hamiltonian(jnp.asarray([0.3, 2.0, 0.1]))), rtol=1e-14)
    model = learn.Dissipative(net, learn.LearnedDrag(3, "linear", scale=0.5))
    ys = np.asarray(model.rollout(jnp.asarray([0.3, 2.0, 0.1]), 20))
    C = np.asarray(BODY.casimirs(ys))[:, 0]
    assert C[-1] < C[0] * (1 - 1e-3)


def test_files_round_trip(tmp_path):
    model = learn.Dissipative(_net(5), _drag(5, "ridge", True))
    path = tmp_path / "m.h5"
    model.save(path)
    back = learn.load(path)
    assert isinstance(back, learn.Dissipative) and back.drag.kind == "ridge" and back.drag.any_axes
    y = jnp.asarray([0.3, -1.2, 0.8])
    np.testing.assert_array_equal(np.asarray(back.step(y)), np.asarray(model.step(y)))


def test_bad_input():
    with pytest.raises(ValueError, match="identity activation"):
        learn.Dissipative(learn.GLPNet(BODY, 3, activation="sigmoid", h=0.1), learn.LearnedDrag(3))
    with pytest.raises(ValueError, match="dimension 4"):
        learn.Dissipative(_net(0), learn.LearnedDrag(4))
    with pytest.raises(TypeError, match="learn.GLPNet"):
        learn.Dissipative("net", learn.LearnedDrag(3))
    with pytest.raises(ValueError, match="kind must be one of"):
        learn.LearnedDrag(3, "cubic")
    with pytest.raises(ValueError, match="scale must be"):
        learn.LearnedDrag(3, scale=-1.0)
    data = it.Observations(BODY, np.arange(3) * 0.1, np.ones((3, 3)))
    with pytest.raises(ValueError, match="kinds must be"):
        learn.fit_dissipative(BODY, data, kinds=("viscous",))


@pytest.mark.slow  # ~60 s: four flights fitted with the quadratic drag
def test_fit_dissipative_finds_a_forced_body():
    data = _flights(6, seed=0, records=61, noise=1e-3)
    model, records = learn.fit_dissipative(RigidBody(I), data, kinds=("linear", "quadratic"), progress=False)
    choice = records[-1].choice
    assert choice.chosen.endswith("quadratic drag") and records[0].choice is choice
    assert [s.family for s in choice.scores] == ["quadratic, even, linear drag", "quadratic, even, quadratic drag"]
    assert choice.score(choice.chosen).bic < choice.score("quadratic, even, linear drag").bic
    assert all(s.substeps >= 1 for s in choice.scores)  # the step each was fitted with, from the data
    A, _ = model.quadratic_part()
    fitted = np.linalg.inv(np.asarray(A))
    # the inertia at the identifiable scale (ratios) within 2%: noise 1e-3 over 0.6 s flights
    np.testing.assert_allclose(np.diag(fitted) / fitted[1, 1], I / I[1], rtol=2e-2)


@pytest.mark.slow  # ~40 s: two fits
def test_a_gyroscope_bias_is_found():
    # the rates read with a constant bias of 0.05 rad/s: fitted with each trajectory's start
    body = RigidBody((1.0, 1.9, 2.1))
    omega = np.array([[0.1, 8.0, 0.2], [0.3, -9.0, 0.1], [-0.2, 10.0, 0.3]])
    exact = it.observe_body(body, omega * body.inertia, np.tile([0, 0, 0, 1.0], (3, 1)), np.arange(41) * 0.01,
                            measure="velocities")
    beta = np.array([0.05, -0.03, 0.04])
    data = it.BodyObservations(body, exact.times, velocities=[v + beta for v in exact.velocities])
    terms = learn.RidgeTerms(3, 3, activation="identity", full_vectors=False, linear_term=False, bias=False)
    terms = eqx.tree_at(lambda t: (t.a, t.c), terms, (jnp.asarray(1.0 / body.inertia), jnp.ones(3)))
    net = learn.GLPNet(body, terms=terms, method=TripleJump)
    losses = {}
    for bias in (False, True):
        _, record = learn.fit(net, data, loss=learn.BodyLoss(max_step=0.005, bias=bias),
                              optimiser=learn.LevenbergMarquardt(60), progress=False)
        losses[bias] = float(np.asarray(record.history["train_loss"])[-1])
    # exact data but for the bias: with it fitted, the misfit falls to the fit's tolerance
    assert losses[True] < 1e-6 * losses[False]


def test_weak_form_drag_tells_a_body_in_air_from_one_in_vacuum():
    ratios = {}
    for name, system in (("air", Forced(RigidBody(I), QuadraticDrag(D))), ("vacuum", RigidBody(I))):
        data = _flights(8, seed=0, records=101, noise=2e-3, system=system)  # the same spins in both
        _, _, misfit = learn.weak_form_quadratic(data, linear=False, diagonal=True)
        A, _, found, with_drag = learn.weak_form_drag(data, "quadratic", diagonal=True)
        ratios[name] = misfit / with_drag
        if name == "air":
            M = np.linalg.inv(A)
            # the drag about the spin axis relative to its moment, D_22 / I_2: well fixed by
            # spins about it (measured 0.3% off); the other axes barely move
            assert abs(found[1, 1] / M[1, 1] - D[1, 1] / I[1]) < 0.05 * D[1, 1] / I[1]
        else:
            np.testing.assert_array_equal(np.diag(found) >= 0.0, True)
    # measured 48 in air, 1.02 in vacuum: a drag explains what the quadratic cannot, or nothing
    assert ratios["air"] > 10.0 and ratios["vacuum"] < 1.5


def test_fit_splitting_dissipation_argument():
    data = it.observe_body(BODY, np.array([[0.1, 8.0, 0.2]]) * BODY.inertia, np.array([[0, 0, 0, 1.0]]),
                           np.arange(21) * 0.01, measure="velocities")
    with pytest.raises(ValueError, match="dissipation must be 'auto', None or a sequence of"):
        learn.fit_splitting(BODY, data, dissipation=("viscous",))
    pairs = it.ground_truth(BODY, np.ones((2, 3)), 0.1, 3)
    with pytest.raises(ValueError, match="pairs and trajectories fit one conservative family"):
        learn.fit_splitting(BODY, pairs, dissipation=("quadratic",))


@pytest.mark.slow  # ~2 min: the families and the drag families on six short flights
def test_fit_splitting_offers_drag_families_to_a_body_in_air_and_chooses_one():
    # 0.8 s flights: the drag screen's ratio is 7.5 (0.6 s flights gave 2.1, below DRAG_SCREEN_RATIO
    # once the screen compared with the fullest quadratic, any axes and linear terms: ee4bf4b)
    data = _flights(6, seed=0, records=81, noise=2e-3)
    model, records = learn.fit_splitting(RigidBody(I), data, progress=False)  # no family skipped on these
    choice = records[-1].choice
    # on the axes of the best conservative family (on these flights, any axes)
    drags = sorted(s.family.rsplit(", ", 1)[-1] for s in choice.scores if s.family.endswith("drag"))
    assert drags == ["linear drag", "quadratic drag"]
    assert choice.chosen.endswith("drag") and isinstance(model, learn.Dissipative)


@pytest.mark.slow  # ~2 min: two families, each refitted without each of two sessions
def test_held_out_sessions_choose_the_drag_on_body_records():
    data = _flights(6, seed=1, records=61, noise=2e-3)
    # two sessions, labelled on the data: held out whole without groups= (the data's groups)
    data = it.BodyObservations.concatenate([data.select([0, 1, 2]), data.select([3, 4, 5])],
                                           groups=["monday", "tuesday"])
    _, records = learn.fit_splitting(RigidBody(I), data, families=[learn.FAMILIES[0]], dissipation=("quadratic",),
                                     selection="held-out", progress=False)
    choice = records[-1].choice
    assert choice.selection == "held-out" and choice.groups == 2 and choice.folds == 2
    errors = {s.family: s.held_out_error for s in choice.scores}
    # the drag predicts the other session far better than the conservative quadratic
    assert errors["quadratic, even, quadratic drag"] < 0.1 * errors["quadratic, even"]
    assert choice.chosen == "quadratic, even, quadratic drag"


@pytest.mark.slow  # ~2 min: every family and the drag families on observed states
def test_fit_splitting_offers_drag_families_on_observed_states_leaving_their_orbit():
    body = RigidBody((2.0, 1.0, 2.0 / 3.0))
    y0 = np.random.default_rng(0).normal(size=(20, 3))
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    data = it.observe(Forced(body, LinearDrag(0.05)), y0, np.arange(21) * 0.1, noise=1e-3, seed=1)
    model, records = learn.fit_splitting(body, data, selection="bic", progress=False)
    choice = records[-1].choice
    # |Pi| decays along every trajectory: the drag families are offered, and one is chosen
    assert choice.chosen.endswith("drag") and isinstance(model, learn.Dissipative)


def test_the_drag_screen_skips_the_drag_families_on_conservative_states_and_says_how_to_fit_them():
    from learn._training._fit_splitting import DRAG_SCREEN_RATIO, drag_fits

    rng = np.random.default_rng(0)
    data = it.observe(BODY, rng.normal(size=(4, 3)), np.linspace(0.0, 2.0, 21), noise=1e-3, seed=0)
    skipped = []
    # the screen decides before any fit: no method, iterations or context is needed
    assert drag_fits(BODY, data, None, 0, 0.0, None, "auto", [], skipped) == []
    assert [s.family for s in skipped] == ["drag families"]
    assert f"DRAG_SCREEN_RATIO = {DRAG_SCREEN_RATIO:g}" in skipped[0].reason
    assert "nothing the data show leaves the orbit" in skipped[0].reason
    assert "pass dissipation=('linear', 'quadratic') to fit them anyway" in skipped[0].reason
