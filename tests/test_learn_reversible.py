"""Reversing symmetries of the systems and the reversible LPNet built on them: the symmetries
found reverse the exact flow (heyoka), the network's step is R-reversible and on the leaf to
round-off whatever its weights, and training on the explicit residual trains the step."""

from __future__ import annotations

import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS, SYSTEM_FACTORIES
from hypothesis import given, settings
from hypothesis import strategies as st

import integrators as it
import learn
import liepoisson as lp
from liepoisson.systems import check_reversing_symmetry, reversing_symmetries, reversing_symmetry

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
from any_algebra import SYSTEMS as NEW_ALGEBRAS  # the benchmark's, not copied

RB = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
Y = np.random.default_rng(1).uniform(-1.0, 1.0, size=(6, 3))


def so3_with_linear_term():
    return lp.systems.LiePoissonSystem(
        lp.so3(), lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 / 2 + m[2] ** 2 / 3) + 0.3 * m[0], name="tilted body"
    )


def test_rigid_body_symmetries_are_the_three_single_flips():
    found = [r.tolist() for r in reversing_symmetries(RB)]
    assert found == [[-1, 1, 1], [1, -1, 1], [1, 1, -1]]
    # -id is anti-Poisson and keeps H and |Pi|^2, but has no fixed point on a sphere
    with pytest.raises(ValueError, match="flips 3 components"):
        check_reversing_symmetry(RB, [-1, -1, -1])


@pytest.mark.parametrize(
    ("system", "signs", "why"),
    [
        (RB, [-1, -1, 1], "not anti-Poisson"),  # a rotation by pi: Poisson, not anti-Poisson
        (so3_with_linear_term(), [-1, 1, 1], r"H\(Ry\) != H\(y\)"),
        (NEW_ALGEBRAS["so4"](), [1, 1, 1, -1, -1, -1], "changes a Casimir"),  # swaps Pf(m) and -Pf(m)
        (RB, [1, 1], "vector of \\+1/-1 of length 3"),
        (RB, [0.5, 1, 1], "vector of \\+1/-1 of length 3"),
    ],
)
def test_check_reversing_symmetry_says_what_fails(system, signs, why):
    with pytest.raises(ValueError, match=why):
        check_reversing_symmetry(system, signs)


def test_no_symmetry_is_an_error_naming_the_way_out():
    diamond = NEW_ALGEBRAS["diamond"]()
    assert reversing_symmetries(diamond) == []
    with pytest.raises(ValueError, match="without reversing"):
        learn.LPNet(diamond, reversing="auto")


@pytest.mark.parametrize(
    "system", [RB, lp.systems.HeavyTop(), SYSTEM_FACTORIES["Kirchhoff"](), NEW_ALGEBRAS["so4"]()],
    ids=["RigidBody", "HeavyTop", "Kirchhoff", "so4"],
)
def test_every_symmetry_found_reverses_the_exact_flow(system):
    # Independent of the search: heyoka at its tightest tolerance. R phi_h R phi_h = id, i.e.
    # from R y_1 the flow goes back to R y_0.
    found = reversing_symmetries(system)
    assert found, "each of these systems has a reversing sign flip"
    y0 = np.random.default_rng(2).uniform(-1.0, 1.0, size=(4, system.dim))
    y1 = it.ground_truth(system, y0, h=0.3, n_steps=1, progress=False).states[:, -1]
    for r in found:
        back = r * it.ground_truth(system, r * y1, h=0.3, n_steps=1, progress=False).states[:, -1]
        # two integrations at tolerance eps, a few dozen Taylor steps each
        assert np.allclose(back, y0, rtol=0, atol=1e3 * EPS * max(1.0, np.abs(y0).max()))


@eqx.filter_jit
def steps(net, y):
    """`net.step` over the states `y` (one compilation for every weight draw)."""
    return jax.vmap(net.step)(y)


def reversible(key=0, **kw):
    return learn.LPNet(RB, hidden=(8, 8), key=key, h=0.1, reversing="auto", **kw)


@settings(max_examples=8, deadline=None)
@given(key=st.integers(0, 2**16), scale=st.floats(0.1, 2.0))
def test_step_is_reversible_and_on_the_leaf_whatever_the_weights(key, scale):
    net = reversible(key)
    y = jnp.asarray(scale * Y)
    r = jnp.asarray(net.reversing)
    y1 = steps(net, y)
    assert np.all(np.isfinite(np.asarray(y1)))
    size = float(jnp.abs(y).max())
    # R Phi R Phi = id: the iteration converged (< 2^10 eps), then two more test flows' roundings
    assert np.allclose(np.asarray(r * steps(net, r * y1)), np.asarray(y), rtol=0, atol=2**12 * EPS * size)
    # |Pi|^2 kept by both halves: a few roundings of a rotation
    assert np.allclose(np.asarray(RB.casimirs(y1)), np.asarray(RB.casimirs(y)), rtol=0, atol=64 * EPS * size**2)
    # the step is the fixed point of the residual form the loss uses
    assert np.allclose(np.asarray(jax.vmap(net.training_prediction)(y, y1)), np.asarray(y1), rtol=0,
                       atol=2**10 * EPS * max(1.0, size))


def test_casimirs_over_a_long_rollout_and_not_a_poisson_map():
    net = reversible(3)
    y = np.asarray(net.rollout(Y, 2000))
    C = np.asarray(RB.casimirs(y))
    # round-off random walk: 2000 steps of a few roundings each
    assert np.abs(C - C[:, :1]).max() < 2000 * 16 * EPS
    # alpha depends on the point: not a Poisson map (the paper's LPNet is not one either)
    assert np.asarray(net.poisson_defect(Y)).max() > 1e-6


def test_unconverged_iteration_is_a_divergence_not_a_wrong_state():
    net = reversible(0, fixed_point_iterations=1)
    assert np.all(np.isnan(np.asarray(jax.vmap(net.step)(jnp.asarray(Y)))))
    with pytest.raises(it.RolloutDivergedError, match=r"step 1.*fixed_point_iterations=1.*with_fixed_point_iterations\(4\)"):
        net.rollout(Y, 5)
    # the hint works: the same weights with more iterations converge, to the 16-iteration step
    more = net.with_fixed_point_iterations(64)
    assert more.fixed_point_iterations == 64 and net.fixed_point_iterations == 1
    assert np.array_equal(np.asarray(more.alpha(Y[0])), np.asarray(net.alpha(Y[0])))
    y64 = np.asarray(more.rollout(Y, 5))
    y16 = np.asarray(net.with_fixed_point_iterations(16).rollout(Y, 5))
    assert np.all(np.isfinite(y64))
    np.testing.assert_allclose(y64, y16, rtol=0, atol=2**10 * EPS)  # both converged to the tolerance of the step
    with pytest.raises(ValueError, match="iterations"):
        net.with_fixed_point_iterations(0)
    with pytest.raises(ValueError, match="not"):
        learn.LPNet(RB, hidden=(8,), key=0).with_fixed_point_iterations(8)


def test_cost_counts_every_flow_and_save_load_roundtrip(tmp_path):
    net = reversible(5, fixed_point_iterations=12)
    assert net.exact_flows_per_step == 13
    plain = learn.LPNet(RB, hidden=(8, 8), key=5, h=0.1)
    # 13 flows and 13 network evaluations against one of each
    assert 10 * plain.cost().flops < net.cost().flops < 16 * plain.cost().flops
    net.save(tmp_path / "rev.h5")
    back = learn.LPNet.load(tmp_path / "rev.h5")
    assert back.reversing == net.reversing and back.fixed_point_iterations == 12
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(net.step)(Y)))


def test_bad_arguments():
    with pytest.raises(ValueError, match="'auto' or a vector"):
        learn.LPNet(RB, reversing="yes")
    with pytest.raises(ValueError, match="TestFlowParametrisation"):
        learn.LPNet(lp.systems.Kirchhoff(), parametrisation="SE3RotationShear", reversing="auto")
    with pytest.raises(ValueError, match="fixed_point_iterations"):
        learn.LPNet(RB, reversing="auto", fixed_point_iterations=0)
    data = it.ground_truth(RB, Y, h=0.1, n_steps=3, progress=False)
    with pytest.raises(ValueError, match="loss='state'"):
        learn.fit(reversible(), data, loss="alpha", epochs=1, progress=False)


def test_training_on_the_residual_trains_the_step():
    data = it.ground_truth(RB, Y, h=0.1, n_steps=20, progress=False)
    net = learn.LPNet(RB, hidden=(8, 8), key=0, reversing=reversing_symmetry(RB))
    fitted, record = learn.fit(net, data, epochs=1500, progress=False, validation_fraction=0.0, normalise=True)
    y0 = data.states[:, :-1].reshape(-1, 3)
    y1 = data.states[:, 1:].reshape(-1, 3)
    before = float(learn.state_mse(net.with_h(0.1), jnp.asarray(y0), jnp.asarray(y1)))
    assert record.train_loss < 1e-2 * before
    # the loss is the residual form; the step's own error is the same up to the contraction of
    # the iteration (a factor 1/(1 - c)^2 with c of a few percent here)
    step_mse = float(np.mean((np.asarray(fitted.rollout(y0, 1))[:, -1] - y1) ** 2))
    assert 0.5 * record.train_loss < step_mse < 2.0 * record.train_loss
