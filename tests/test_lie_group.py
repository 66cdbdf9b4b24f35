"""Lie-group methods on the coadjoint action and the damped splitting: observed orders against
heyoka, Casimirs over long runs on several algebras, degenerate states, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import EPS, algebra, system

import integrators as it
import liepoisson as lp
from integrators import splitting as sp
from liepoisson.systems import DoubleBracket, LiePoissonSystem

T = 4.0
Y0 = np.array([0.3, 0.4, 1.0])


@pytest.fixture(scope="module")
def damped():
    return lp.systems.damped_rigid_body(gamma=0.3)


@pytest.fixture(scope="module")
def reference(damped):
    # heyoka at tol = eps: its error (~1e-15) is far below the smallest error measured (~1e-11)
    return np.asarray(it.ground_truth(damped, Y0, h=T, n_steps=1).states[0, -1])


def observed_order(make, reference, hs):
    errors = [np.linalg.norm(np.asarray(make(h).rollout(Y0, round(T / h), save_every=round(T / h)))[-1] - reference) for h in hs]
    return np.log2(errors[-2] / errors[-1])


@pytest.mark.parametrize(
    ("method", "hs"),
    [(it.LieEuler, (0.025, 0.0125)), (it.CommutatorFree2, (0.025, 0.0125)), (it.CommutatorFree4, (0.025, 0.0125))],
)
def test_lie_group_methods_reach_their_order(damped, reference, method, hs):
    assert abs(observed_order(lambda h: method(damped, h), reference, hs) - method.order) < 0.1


@pytest.mark.parametrize(
    ("composition", "dissipation", "order"),
    [pytest.param(sp.LieTrotter, it.LieEuler, 1, marks=pytest.mark.slow),
     pytest.param(sp.Strang, it.LieEuler, 1, marks=pytest.mark.slow), (sp.Strang, it.CommutatorFree2, 2),
     pytest.param(sp.TripleJump, it.CommutatorFree4, 4, marks=pytest.mark.slow),  # CommutatorFree4's order above
     pytest.param(sp.Suzuki, it.CommutatorFree4, 4, marks=pytest.mark.slow)],
)
def test_damped_splitting_reaches_the_smaller_order(damped, reference, composition, dissipation, order):
    make = lambda h: it.DampedSplitting(damped, h, composition, dissipation)
    assert make(0.1).order == order
    assert abs(observed_order(make, reference, (0.025, 0.0125)) - order) < 0.1


def test_flow_count_of_a_damped_splitting(damped):
    # by hand: Strang over 3 pieces + the dissipation = 2*4 - 1 flows, the dissipation's one
    # call taking CommutatorFree2's 3 exponentials; TripleJump = 3 such Strang steps.
    assert it.DampedSplitting(damped, 0.1).exact_flows_per_step == 7 - 1 + 3
    assert it.DampedSplitting(damped, 0.1, sp.TripleJump, it.CommutatorFree4).exact_flows_per_step == 3 * (7 - 1 + 5)
    assert it.CommutatorFree4(damped, 0.1).exact_flows_per_step == 5


def _generic_damped(name: str, gamma: float) -> DoubleBracket:
    g = algebra(name)
    weights = np.linspace(1.0, 2.0, g.dim)
    hamiltonian = lambda m, xp: sum(0.5 * float(w) * m[i] ** 2 for i, w in enumerate(weights))
    return DoubleBracket(LiePoissonSystem(g, hamiltonian, name=f"diag_{name}"), gamma)


# Each stepper is one compiled rollout (~1 s of compilation, ~2.5 s for CommutatorFree4 on a
# generic algebra). The Lie-group methods' code does not depend on the algebra, which enters
# through its coadjoint flow only (that flow is checked over 10^4 composed steps on every
# algebra in test_coadjoint.py). By default: every stepper on so3 (compact, one Casimir), with
# RK4 as the control that would see a drift. The other pairs run with -m slow: CommutatorFree4 and
# DampedSplitting on se3 (two Casimirs, its own splitting); LieEuler, one exponential of the
# algebra per step, on sl2 (non-compact) and so3+heisenberg (a direct sum).
_ALL = ("LieEuler", "CommutatorFree4", "DampedSplitting", "RK4")


@pytest.mark.parametrize(("name", "methods"), [
    # so3 runs every method by default; se3's (~4 s), sl2's and so3+heisenberg's under -m slow
    ("so3", _ALL), pytest.param("se3", ("CommutatorFree4", "DampedSplitting"), marks=pytest.mark.slow),
    pytest.param("sl2", ("LieEuler",), marks=pytest.mark.slow),
    pytest.param("so3+heisenberg", ("LieEuler",), marks=pytest.mark.slow),
    pytest.param("se3", ("LieEuler", "RK4"), marks=pytest.mark.slow),
    pytest.param("sl2", ("CommutatorFree4", "RK4"), marks=pytest.mark.slow),
    pytest.param("so3+heisenberg", ("CommutatorFree4", "RK4"), marks=pytest.mark.slow),
], ids=["so3", "se3", "sl2", "so3+heisenberg", "se3-others", "sl2-others", "so3+heisenberg-others"])
def test_casimirs_kept_over_ten_thousand_steps(name, methods):
    damped = _generic_damped(name, 0.2)
    y0 = np.random.default_rng(0).normal(size=damped.dim)
    C0 = np.asarray(damped.casimirs(y0))
    scale = max(1.0, float(np.max(np.abs(C0))))
    assert C0.size
    for method in methods:
        if method == "RK4":
            continue
        # the diagonal quadratic splits exactly on so3 and se3 (DampedSplitting is only there)
        stepper = getattr(it, method)(damped, 0.01)
        y = np.asarray(stepper.rollout(y0, 10_000, save_every=100))
        drift = np.max(np.abs(np.asarray(damped.casimirs(y)) - C0), initial=0.0)
        # each step is exact coadjoint flows: rounding only, a random walk of ~1e4 roundings
        assert drift <= 1e-13 * scale, (method, drift)
    # RK4 leaves the orbit at a step it integrates well (error ~1e-4 per unit time here)
    if "RK4" in methods:
        y = np.asarray(it.RK4(damped, 0.2).rollout(y0, 10_000, save_every=100))
        assert np.max(np.abs(np.asarray(damped.casimirs(y)) - C0)) > 1e-9 * scale


@pytest.mark.slow
def test_equilibrium_is_a_fixed_point_without_nan(damped):
    # on the major axis the velocity and the dissipative generator vanish: zero rotation
    y0 = np.array([1.0, 0.0, 0.0])
    for stepper in (it.LieEuler(damped, 0.1), it.CommutatorFree2(damped, 0.1), it.CommutatorFree4(damped, 0.1),
                    it.DampedSplitting(damped, 0.1)):
        y = np.asarray(stepper.rollout(y0, 20))
        assert np.all(np.isfinite(y))
        np.testing.assert_allclose(y, np.broadcast_to(y0, y.shape), rtol=0, atol=4 * EPS)
    assert np.array_equal(np.asarray(damped.dissipative_generator(y0)), np.zeros(3))


def test_undamped_lie_euler_moves_along_the_orbit_with_grad_h():
    body = system("RigidBody")
    y0 = np.array([0.3, -1.1, 0.8])
    y1 = np.asarray(it.LieEuler(body, 0.1).step(y0))
    np.testing.assert_array_equal(y1, np.asarray(body.test_flow(body.hamiltonian_gradient(y0), 0.1, y0)))


def test_bad_input(damped):
    with pytest.raises(TypeError, match="must be a Lie-Poisson system.*ExtendedPendulum"):
        it.LieEuler(system("ExtendedPendulum"), 0.1)
    with pytest.raises(ValueError, match="h must be finite and > 0"):
        it.CommutatorFree4(damped, 0.0)
    with pytest.raises(TypeError, match="must be a dissipative system .a liepoisson.systems.AbstractDissipativeSystem"):
        it.DampedSplitting(system("RigidBody"), 0.1)
    with pytest.raises(TypeError, match="dissipation must be a Lie-group method class"):
        it.DampedSplitting(damped, 0.1, sp.Strang, it.RK4)
    with pytest.raises(TypeError, match="method must be a splitting method"):
        it.DampedSplitting(damped, 0.1, it.LieEuler)
    with pytest.raises(ValueError, match="BlanesMoan4"):
        it.DampedSplitting(damped, 0.1, sp.BlanesMoan4)
    with pytest.raises(TypeError, match="dissipation must be a Lie-group method class"):
        it.DampedSplitting(damped, 0.1, sp.Strang, it.AbstractLieGroupMethod)
    with pytest.raises(TypeError, match="method must be a splitting method"):
        it.DampedSplitting(damped, 0.1, sp.AbstractCompositionMethod)


def test_damped_splitting_reuses_its_pieces_and_counts_the_flops_of_every_stage(damped):
    # the same piece objects for every instance (a static field: equal pieces, no recompile)
    assert it.DampedSplitting(damped, 0.1).pieces is it.DampedSplitting(damped, 0.2, sp.TripleJump).pieces
    # XLA counts a scanned Strang step once: the count multiplies it by the composition's stages
    strang = it.DampedSplitting(damped, 0.1).step_flops()
    triple = it.DampedSplitting(damped, 0.1, sp.TripleJump).step_flops()
    assert triple == pytest.approx(3 * strang, rel=0.05)
