"""Any Lie algebra end to end, on four algebras outside the catalogue (those of
`benchmarks/any_algebra.py`): diamond (4, solvable), filiform (5, nilpotent, cubic Casimir),
so(4) (6, compact, from matrices), sl(3) (8, simple non-compact, cubic Casimir).

Casimirs found, the automatic splitting's order, and an LPNet and a G-LPNet trained and
rolled out with their structure intact."""

from __future__ import annotations

import functools

import jax
import numpy as np
import pytest
from helpers import EPS

import integrators as it
import learn
from benchmarks.any_algebra import SYSTEMS, casimir_drift  # the benchmark's, not copied
from learn import state_mse

EXPECTED_DEGREES = {"diamond": [1, 2], "filiform5": [1, 2, 3], "so4": [2, 2], "sl3": [2, 3]}


@functools.cache
def system_and_data(name: str):
    system = SYSTEMS[name]()
    y0 = np.random.default_rng(0).uniform(-1.0, 1.0, size=(8, system.dim))
    return system, it.ground_truth(system, y0, h=0.1, n_steps=20, progress=False)


ALL = pytest.mark.parametrize("name", list(SYSTEMS))
# Training on filiform, so(4) and sl(3) runs under -m slow (6-8 s of compilation per model, 15-25 s
# per test), on the diamond algebra too (by default a G-LPNet on it is rolled out and saved in
# test_user_systems.py, and the gradients of its flows are checked in test_coadjoint.py). The
# splitting orders of diamond, so(4) and sl(3) too (~5 s each): the default run measures
# filiform's, and the automatic splitting's Strang order on the diamond algebra is measured by
# default in test_automatic_splitting.py (with a richer Hamiltonian).
TRAINED = pytest.mark.parametrize(
    "name", [n if n == "diamond" else pytest.param(n, marks=pytest.mark.slow) for n in SYSTEMS]
)
# every algebra with -m slow: the automatic splitting's Strang order is measured by default in
# test_automatic_splitting.py (the diamond algebra with ridge terms)
ORDERS = pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) for n in SYSTEMS]
)


@ALL
def test_casimirs_fill_the_generic_corank_and_are_conserved(name):
    system, data = system_and_data(name)
    algebra = system.algebra
    assert sorted(p.degree for p in algebra.casimir_polynomials) == EXPECTED_DEGREES[algebra.name]
    mu = np.random.default_rng(1).normal(size=(5, system.dim))
    # generic corank = dim - orbit dimension at random points
    assert all(algebra.dim - algebra.orbit_dimension(m) == algebra.n_casimirs for m in mu)
    # gradients in the kernel of B (entries of B and grad C are O(|mu|^k), k <= 2)
    for m in mu:
        G = np.asarray(algebra.casimir_gradients(m))
        np.testing.assert_allclose(np.asarray(algebra.poisson_tensor(m)) @ G.T, 0.0, atol=64 * EPS * (1 + np.abs(m).max()) ** 3)
    # heyoka at tolerance eps conserves them along 20 steps to a few hundred roundings
    report = it.diagnostics(data.states, system)
    assert report.max_casimir_drift_relative < 1e-12


@ORDERS
def test_automatic_splitting_has_strang_order(name):
    system, data = system_and_data(name)
    study = it.convergence(lambda h: it.splitting.Strang(system, h=h), system, data.states[:2, 0],
                           t_final=1.0, hs=[0.1, 0.05, 0.025])
    assert abs(study.order - 2.0) < 0.1


@pytest.mark.slow  # ~5 s; LPNets are trained on the catalogue by default elsewhere
@TRAINED
def test_lpnet_trains_and_rolls_out_on_the_orbit(name):
    system, data = system_and_data(name)
    model = learn.LPNet(system, hidden=(8, 8), key=0)
    fitted, record = learn.fit(model, data, epochs=300, progress=False, validation_fraction=0.0)
    y0, y1 = (data.states[:, s].reshape(-1, system.dim) for s in (slice(None, -1), slice(1, None)))
    start = float(state_mse(model.with_h(0.1), y0, y1))
    assert record.train_loss < start  # training lowered the loss
    y = np.asarray(fitted.rollout(data.states[:, 0], 200))
    assert np.all(np.isfinite(y))
    # every step is an exact coadjoint flow: Casimirs at round-off over 200 steps (a few
    # roundings per step, in units of the size of their terms)
    assert casimir_drift(y, system) < 200 * 64 * EPS


@pytest.mark.slow
@TRAINED
def test_glpnet_trains_and_is_an_exact_poisson_map(name):
    system, data = system_and_data(name)
    model = learn.GLPNet(system, n_modules=3, key=0)  # few modules: compiles fast
    fitted, record = learn.fit(model, data, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(10)), progress=False,
                               validation_fraction=0.0)
    assert np.isfinite(record.train_loss)
    y = np.asarray(fitted.rollout(data.states[:, 0], 200))
    assert casimir_drift(y, system) < 200 * 64 * EPS
    # a composition of exact flows: Poisson to round-off (entries of B are O(|y|) ~ 1)
    defect = np.asarray(fitted.poisson_defect(jax.numpy.asarray(y[:, -1])))
    assert defect.max() < 1e3 * EPS
