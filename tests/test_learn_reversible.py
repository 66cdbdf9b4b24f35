"""Reversing symmetries of the systems and the reversible LPNet built on them
(`learn.Reversible(lpnet)`): the symmetries found reverse the exact flow (heyoka), the
network's step is R-reversible and on the leaf to round-off whatever its weights, a step whose
iteration has not converged is NaN (as for `integrators.ImplicitMidpoint`, the same policy),
training on the explicit residual trains the step, and version-1 files still load."""

from __future__ import annotations

import json

import equinox as eqx
import h5py
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
from benchmarks.any_algebra import SYSTEMS as NEW_ALGEBRAS  # the benchmark's, not copied
from liepoisson.systems import (
    check_reversing_symmetry,
    reversing_symmetries,
    reversing_symmetry,
    sign_symmetries,
)

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


@pytest.mark.slow  # learn.Reversible's refusals by default in test_bad_arguments
def test_no_symmetry_is_an_error_naming_the_way_out():
    diamond = NEW_ALGEBRAS["diamond"]()
    assert reversing_symmetries(diamond) == []
    with pytest.raises(ValueError,
                       match=r"no reversing symmetry.*learn.LPNet\(system\), not wrapped in learn.Reversible"):
        learn.Reversible(learn.LPNet(diamond))


# the heavy top (its own heyoka integrator to compile) with -m slow; Kirchhoff's se(3) by default
@pytest.mark.parametrize(
    "system", [RB, pytest.param(lp.systems.HeavyTop(), marks=pytest.mark.slow), SYSTEM_FACTORIES["Kirchhoff"](),
               NEW_ALGEBRAS["so4"]()],
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
    return learn.Reversible(learn.LPNet(RB, hidden=(8, 8), key=key, h=0.1), **kw)


@settings(max_examples=8, deadline=None)
@given(key=st.integers(0, 2**16), scale=st.floats(0.1, 2.0))
def test_step_is_reversible_and_on_the_leaf_whatever_the_weights(key, scale):
    net = reversible(key)
    y = jnp.asarray(scale * Y)
    r = jnp.asarray(net.symmetry)
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


def test_wrapper_delegates_to_its_lpnet():
    lpnet = learn.LPNet(RB, hidden=(8, 8), key=2, h=0.1)
    net = learn.Reversible(lpnet, symmetry=[1, -1, 1], iterations=12)
    assert net.lpnet is lpnet and net.system is RB and net.h == 0.1
    assert net.symmetry == (1.0, -1.0, 1.0) and net.iterations == 12
    assert isinstance(net, it.AbstractImplicitStepMap) and not isinstance(lpnet, it.AbstractImplicitStepMap)
    assert learn.Reversible(lpnet).symmetry == (-1.0, 1.0, 1.0)  # "auto": the first found
    moved = net.with_h(0.05)
    assert moved.h == moved.lpnet.h == 0.05 and net.h == 0.1
    # Phi = R B^{-1} R o B: the first half is the LPNet's step, and the step is not it
    y1 = np.asarray(steps(net, jnp.asarray(Y)))
    assert np.abs(y1 - np.asarray(steps(lpnet, jnp.asarray(Y)))).max() > 1e-6


@pytest.mark.slow
def test_casimirs_over_a_long_rollout_and_not_a_poisson_map():
    net = reversible(3)
    y = np.asarray(net.rollout(Y, 2000))
    C = np.asarray(RB.casimirs(y))
    # round-off random walk: 2000 steps of a few roundings each
    assert np.abs(C - C[:, :1]).max() < 2000 * 16 * EPS
    # alpha depends on the point: not a Poisson map (the paper's LPNet is not one either)
    assert np.asarray(net.poisson_defect(Y)).max() > 1e-6


def test_unconverged_iteration_is_a_divergence_not_a_wrong_state():
    net = reversible(0, iterations=1)
    assert np.all(np.isnan(np.asarray(jax.vmap(net.step)(jnp.asarray(Y)))))
    with pytest.raises(it.RolloutDivergedError, match=r"Reversible \(h=0.1\) diverged: trajectory 0 became non-finite "
                       r"at step 1.*iterations=1.*with_iterations\(4\)"):
        net.rollout(Y, 5)
    # the hint works: the same weights with more iterations converge, to the 16-iteration step
    more = net.with_iterations(64)
    assert more.iterations == 64 and net.iterations == 1 and isinstance(more, learn.Reversible)
    assert more.lpnet is net.lpnet and more.symmetry == net.symmetry
    y64 = np.asarray(more.rollout(Y, 5))
    y16 = np.asarray(net.with_iterations(16).rollout(Y, 5))
    assert np.all(np.isfinite(y64))
    np.testing.assert_allclose(y64, y16, rtol=0, atol=2**10 * EPS)  # both converged to the tolerance of the step
    with pytest.raises(ValueError, match="iterations must be an integer >= 1; got 0"):
        net.with_iterations(0)


# with -m slow: the same policy runs by default for learn.Reversible above, and ImplicitMidpoint's
# order and arguments in test_runge_kutta.py
@pytest.mark.parametrize("h", [pytest.param(1.0, marks=pytest.mark.slow), pytest.param(2.0, marks=pytest.mark.slow)])
def test_unconverged_implicit_midpoint_is_a_divergence_not_its_last_newton_iterate(h):
    # The same policy for the classical implicit map. Two Newton steps from the explicit Euler
    # guess at h |f'| ~ 1-2 still move the stage by far more than round-off (measured: 3 are
    # needed at h = 0.1, 4 at h = 2); the map used to return that unconverged iterate as the
    # state, a finite wrong answer.
    few = it.ImplicitMidpoint(RB, h, iterations=2)
    assert isinstance(few, it.AbstractImplicitStepMap)
    assert np.all(np.isnan(np.asarray(jax.vmap(few.step)(jnp.asarray(Y)))))
    with pytest.raises(it.RolloutDivergedError, match=rf"ImplicitMidpoint \(h={h:g}\) diverged: trajectory 0 became "
                       r"non-finite at step 1.*iterations=2.*with_iterations\(8\)") as info:
        few.rollout(Y, 3)
    assert info.value.step == 1 and info.value.last_finite_step == 0
    np.testing.assert_array_equal(info.value.state, Y[0])
    # the hint works: eight Newton steps solve the midpoint equation z = y + h f((y + z)/2)
    enough = few.with_iterations(8)
    assert enough.iterations == 8 and few.iterations == 2 and enough.h == h
    z = np.asarray(enough.rollout(Y, 1))[:, -1]
    assert np.all(np.isfinite(z))
    residual = z - Y - h * np.asarray(jax.vmap(RB.vector_field)(jnp.asarray(0.5 * (Y + z))))
    # a converged Newton solve: a few roundings of the stage equation's terms (|h f| ~ |y|^2 h)
    assert np.abs(residual).max() < 64 * EPS * max(1.0, h * np.abs(Y).max() ** 2)
    # and the quadratic Casimir is kept, as for any converged midpoint step
    np.testing.assert_allclose(np.asarray(RB.casimirs(z)), np.asarray(RB.casimirs(Y)), rtol=0, atol=64 * EPS)


def test_cost_counts_every_flow_and_save_load_roundtrip(tmp_path):
    net = reversible(5, iterations=12)
    assert net.exact_flows_per_step == 13
    plain = learn.LPNet(RB, hidden=(8, 8), key=5, h=0.1)
    # 13 flows and 13 network evaluations against one of each
    assert 10 * plain.cost().flops < net.cost().flops < 16 * plain.cost().flops
    net.save(tmp_path / "rev.h5")
    back = learn.Reversible.load(tmp_path / "rev.h5")
    assert back.symmetry == net.symmetry and back.iterations == 12 and back.h == 0.1
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(net.step)(Y)))
    with pytest.raises(ValueError, match="holds a Reversible, not a LPNet"):
        learn.LPNet.load(tmp_path / "rev.h5")
    plain.save(tmp_path / "plain.h5")
    with pytest.raises(ValueError, match="holds a LPNet, not a Reversible"):
        learn.Reversible.load(tmp_path / "plain.h5")


def write_version_1_reversible_equivariant_lpnet(path, net):
    """`net`, a `Reversible` of an LPNet with a `GroupAveraged` `AffineMLP`, written by hand as
    format version 1 stored it: one LPNet with the flags `reversing`, `fixed_point_iterations`
    and `equivariant` (the group without the identity), the MLP's arrays in layer order."""
    mlp = net.lpnet.network.network
    hyperparameters = {
        "hidden": list(mlp.hidden), "activation": mlp.activation,
        "input_scaling": [list(mlp.input_shift), list(mlp.input_scale)],
        "output_scaling": [list(mlp.output_shift), list(mlp.output_scale)],
        "parametrisation": "TestFlowParametrisation",
        "reversing": [int(r) for r in net.symmetry],
        "fixed_point_iterations": net.iterations,
        "equivariant": [[int(v) for v in s] for s in net.lpnet.network.group if min(s) < 0],
    }
    arrays = [a for layer in mlp.mlp.layers for a in (layer.weight, layer.bias)]
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "learn-model"
        f.attrs["format_version"] = 1
        f.attrs["class"] = "LPNet"
        f.attrs["system"] = net.system.name
        f.attrs["system_params_json"] = json.dumps(net.system.params)
        f.attrs["hyperparameters_json"] = json.dumps(hyperparameters)
        f.attrs["h"] = float(net.h)
        f.attrs["liepoisson_version"] = lp.__version__
        weights = f.create_group("weights")
        weights.attrs["kind"] = "list"
        weights.attrs["count"] = len(arrays)
        for i, array in enumerate(arrays):
            weights.create_dataset(f"{i:04d}", data=np.asarray(array))


@pytest.mark.slow  # a Reversible's file round trip by default above; version-1 files in test_learn_symmetric_glpnet.py
def test_version_1_file_of_a_reversible_equivariant_lpnet_loads(tmp_path):
    lpnet = learn.LPNet(RB, h=0.1, network=learn.GroupAveraged(
        learn.AffineMLP(3, 3, hidden=(8, 8), key=4, input_scaling=([0.1, 0.0, -0.1], [1.0, 2.0, 0.5])),
        sign_symmetries(RB)))
    net = learn.Reversible(lpnet, symmetry=[1, -1, 1], iterations=20)
    path = tmp_path / "v1.h5"
    write_version_1_reversible_equivariant_lpnet(path, net)
    back = learn.Reversible.load(path)
    assert back.symmetry == (1.0, -1.0, 1.0) and back.iterations == 20 and back.h == 0.1
    assert isinstance(back.lpnet.network, learn.GroupAveraged) and back.lpnet.network.group == lpnet.network.group
    assert back.lpnet.network.network.input_scale == (1.0, 2.0, 0.5)
    assert np.array_equal(np.asarray(steps(back, jnp.asarray(Y))), np.asarray(steps(net, jnp.asarray(Y))))
    # the file holds a reversible map now: not an LPNet, whose step would be another map
    with pytest.raises(ValueError, match=r"holds a version-1 LPNet with flags that are now the wrapper learn.Reversible: read it with learn.Reversible.load"):
        learn.LPNet.load(path)


def test_bad_arguments():
    with pytest.raises(TypeError, match="lpnet must be a learn.LPNet; got GLPNet"):
        learn.Reversible(learn.GLPNet(RB))
    with pytest.raises(ValueError, match="symmetry must be 'auto' or a vector"):
        learn.Reversible(learn.LPNet(RB), symmetry="yes")
    with pytest.raises(ValueError, match=r"symmetry = \[-1, -1, 1\] is not a reversing symmetry.*not anti-Poisson"):
        learn.Reversible(learn.LPNet(RB), symmetry=[-1, -1, 1])
    with pytest.raises(ValueError,
                       match="Reversible needs an LPNet whose parametrisation has a closed-form inverse.*got SE3RotationShear"):
        learn.Reversible(learn.LPNet(lp.systems.Kirchhoff(), parametrisation="SE3RotationShear"))
    with pytest.raises(ValueError, match="iterations must be an integer >= 1; got 0"):
        learn.Reversible(learn.LPNet(RB), iterations=0)
    data = it.ground_truth(RB, Y, h=0.1, n_steps=3, progress=False)
    with pytest.raises(ValueError, match=r"loss='alpha' fits alpha to the parameters of one test flow per pair.*a Reversible is not one .a Reversible makes two"):
        learn.fit(reversible(), data, loss="alpha", epochs=1, progress=False)


@pytest.mark.slow  # a training (~3.5 s); the step's reversibility and leaf for any weights run by default
def test_training_on_the_residual_trains_the_step():
    data = it.ground_truth(RB, Y, h=0.1, n_steps=20, progress=False)
    net = learn.Reversible(learn.LPNet(RB, hidden=(8, 8), key=0), symmetry=reversing_symmetry(RB))
    # 1000 epochs: one compiled chunk of Adam (a second chunk compiles again); measured loss
    # ratio 1.1e-3, step error / loss 0.996
    fitted, record = learn.fit(net, data, epochs=1000, progress=False, validation_fraction=0.0, normalise=True)
    assert isinstance(fitted, learn.Reversible) and fitted.h == 0.1 and fitted.symmetry == net.symmetry
    y0 = data.states[:, :-1].reshape(-1, 3)
    y1 = data.states[:, 1:].reshape(-1, 3)
    before = float(learn.state_mse(net.with_h(0.1), jnp.asarray(y0), jnp.asarray(y1)))
    assert record.train_loss < 1e-2 * before
    # the loss is the residual form; the step's own error is the same up to the contraction of
    # the iteration (a factor 1/(1 - c)^2 with c of a few percent here)
    step_mse = float(np.mean((np.asarray(fitted.rollout(y0, 1))[:, -1] - y1) ** 2))
    assert 0.5 * record.train_loss < step_mse < 2.0 * record.train_loss
