"""Sign symmetries of the systems and the equivariant LPNet built on them (an LPNet whose network
is `learn.GroupAveraged` over the symmetries): the symmetries found commute with the exact flow
(heyoka), and the network's step commutes with them to round-off whatever its weights; a
reversible equivariant step (`learn.Reversible`) is reversible under every reversing symmetry
of the system, not only the one it was built with."""

from __future__ import annotations

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
from benchmarks.any_algebra import SYSTEMS as NEW_ALGEBRAS  # the benchmark's, not copied
from liepoisson.systems import reversing_symmetries, sign_symmetries

RB = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
SO4 = NEW_ALGEBRAS["so4"]()
Y = np.random.default_rng(1).uniform(-1.0, 1.0, size=(6, 3))


def averaged(system, key=0, hidden=(8, 8), group=None):
    """An MLP averaged over `group` (default: every sign symmetry of `system`)."""
    group = sign_symmetries(system) if group is None else group
    return learn.GroupAveraged(learn.AffineMLP(system.dim, system.dim, hidden=hidden, key=key), group)


def equivariant(system, key=0, h=0.1, **kw):
    return learn.LPNet(system, h=h, network=averaged(system, key), **kw)


@pytest.mark.slow  # the rigid body's three half-turns are counted by default in test_step_commutes_with_every_symmetry_whatever_the_weights
def test_rigid_body_symmetries_are_the_half_turns():
    found = [s.tolist() for s in sign_symmetries(RB)]
    assert found == [[-1, -1, 1], [-1, 1, -1], [1, -1, -1]]
    # the product of two reversing symmetries is a symmetry
    for a in reversing_symmetries(SO4):
        for b in reversing_symmetries(SO4):
            if not np.array_equal(a, b):
                assert any(np.array_equal(a * b, s) for s in sign_symmetries(SO4))


@pytest.mark.slow  # a group element that is not a symmetry is refused by default in test_a_parametrisation_that_breaks_the_law_is_refused
def test_a_linear_term_on_every_axis_leaves_none():
    tilted = lp.systems.LiePoissonSystem(
        lp.so3(), lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 / 2 + m[2] ** 2 / 3) + 0.3 * (m[0] + m[1] + m[2]),
        name="tilted body")
    assert sign_symmetries(tilted) == []
    # the rigid body's half-turns are not symmetries of the tilted body: refused when the LPNet is built
    with pytest.raises(ValueError,
                       match=r"GroupAveraged.group element = \[-1, -1, 1\] is not a symmetry.*H\(Sy\) != H\(y\)"):
        learn.LPNet(tilted, network=averaged(RB))
    # with none to average over, the group is the identity alone: the plain network
    trivial = averaged(tilted)
    assert trivial.group == ((1.0, 1.0, 1.0),)
    net = learn.LPNet(tilted, h=0.1, network=trivial)
    y = jnp.asarray(Y[0])
    np.testing.assert_array_equal(np.asarray(net.alpha(y)), np.asarray(trivial.network(y)))


def test_group_arguments():
    mlp = learn.AffineMLP(3, 3, hidden=(8,), key=0)
    with pytest.raises(TypeError, match="group must be a sequence of sign vectors; got 'yes'"):
        learn.GroupAveraged(mlp, "yes")
    with pytest.raises(TypeError, match="group must be a sequence of sign vectors; got True"):
        learn.GroupAveraged(mlp, True)
    with pytest.raises(ValueError, match=r"group\[1\] must be a vector of 3 signs \+1/-1; got \[1, 1\]"):
        learn.GroupAveraged(mlp, [[1, -1, -1], [1, 1]])
    with pytest.raises(ValueError, match=r"group\[0\] must be a vector of 3 signs \+1/-1; got \[0.5, 1.0, -1.0\]"):
        learn.GroupAveraged(mlp, [[0.5, 1.0, -1.0]])
    with pytest.raises(ValueError, match="in_size == out_size"):
        learn.GroupAveraged(learn.AffineMLP(3, 4, hidden=(8,)), [[1, -1, -1]])
    with pytest.raises(TypeError, match="network must be a learn.AbstractNetwork"):
        learn.GroupAveraged(RB, [[1, -1, -1]])


@pytest.mark.parametrize(
    "system", [RB, lp.systems.HeavyTop(), SYSTEM_FACTORIES["Kirchhoff"](), SO4, lp.systems.ChargedParticle()],
    ids=["RigidBody", "HeavyTop", "Kirchhoff", "so4", "ChargedParticle"],
)
def test_every_symmetry_found_commutes_with_the_exact_flow(system):
    # Independent of the search: heyoka at its tightest tolerance, phi_h(S y) = S phi_h(y).
    found = sign_symmetries(system)
    assert found, "each of these systems has a sign symmetry"
    y0 = np.random.default_rng(2).uniform(-1.0, 1.0, size=(4, system.dim))
    y1 = it.ground_truth(system, y0, h=0.3, n_steps=1, progress=False).states[:, -1]
    for s in found:
        moved = it.ground_truth(system, s * y0, h=0.3, n_steps=1, progress=False).states[:, -1]
        # two integrations at tolerance eps, a few dozen Taylor steps each
        assert np.allclose(moved, s * y1, rtol=0, atol=1e3 * EPS * max(1.0, np.abs(y1).max()))


@eqx.filter_jit
def steps(net, y):
    """`net.step` over the states `y` (one compilation for every weight draw)."""
    return jax.vmap(net.step)(y)


@settings(max_examples=6, deadline=None)
@given(key=st.integers(0, 2**16), scale=st.floats(0.1, 2.0), reversible=st.booleans())
def test_step_commutes_with_every_symmetry_whatever_the_weights(key, scale, reversible):
    lpnet = equivariant(RB, key)
    net = learn.Reversible(lpnet) if reversible else lpnet
    group = lpnet.network.group
    assert len(group) == 4  # the identity and the three half-turns
    y = jnp.asarray(scale * Y)
    y1 = np.asarray(steps(net, y))
    assert np.all(np.isfinite(y1))
    size = max(1.0, float(jnp.abs(y).max()))
    # a real step: alpha = 0 (averaging S net(y) without flipping y) would not move y at all
    assert np.abs(y1 - np.asarray(y)).max() > 1e-6 * size
    for s in np.asarray(group):
        # the same arithmetic on sign-flipped numbers (the fixed-point iteration included: its
        # start and its map are equivariant), except the order of the group average's sum
        np.testing.assert_allclose(np.asarray(steps(net, jnp.asarray(s) * y)), s * y1, rtol=0, atol=16 * EPS * size)


@pytest.mark.slow
def test_alpha_is_the_group_average_of_the_network():
    net = equivariant(SO4, key=2)
    group = net.network.group
    assert len(group) == 8  # so(4): seven sign symmetries and the identity
    y = np.random.default_rng(3).uniform(-1.0, 1.0, size=6)
    expected = np.mean([np.asarray(s) * np.asarray(net.network.network(jnp.asarray(np.asarray(s) * y)))
                        for s in group], axis=0)
    np.testing.assert_allclose(np.asarray(net.alpha(jnp.asarray(y))), expected, rtol=0, atol=16 * EPS)
    # the group is closed under products: two of the rigid body's half-turns give the third
    closed = averaged(RB, group=sign_symmetries(RB)[:2]).group
    assert closed == ((-1.0, -1.0, 1.0), (-1.0, 1.0, -1.0), (1.0, -1.0, -1.0), (1.0, 1.0, 1.0))
    assert averaged(RB, group=[[1, 1, 1], [-1, -1, 1], [-1, -1, 1]]).group == ((-1.0, -1.0, 1.0), (1.0, 1.0, 1.0))


def test_without_equivariance_the_step_does_not_commute():
    # the property above is the symmetrisation's, not an accident of the architecture
    net = learn.LPNet(RB, hidden=(8, 8), key=0, h=0.1)
    s = sign_symmetries(RB)[0]
    gap = np.abs(np.asarray(steps(net, jnp.asarray(s * Y))) - s * np.asarray(steps(net, jnp.asarray(Y)))).max()
    assert gap > 1e-4


# with -m slow (so(4)'s and the rigid body's; the property is algebra-independent): a reversible
# equivariant step commutes with the symmetries by default in test_step_commutes_with_every_symmetry_whatever_the_weights
@pytest.mark.parametrize("system", [pytest.param(RB, marks=pytest.mark.slow), pytest.param(SO4, marks=pytest.mark.slow)],
                         ids=["RigidBody", "so4"])
def test_reversible_equivariant_step_is_reversible_under_every_reversing_symmetry(system):
    net = learn.Reversible(equivariant(system, key=3))
    assert net.symmetry == tuple(float(r) for r in reversing_symmetries(system)[0])
    y = jnp.asarray(np.random.default_rng(4).uniform(-1.0, 1.0, size=(5, system.dim)))
    y1 = steps(net, y)
    for r in reversing_symmetries(system):
        back = r * np.asarray(steps(net, jnp.asarray(r) * y1))
        # R Phi R Phi = id for every R = R_0 S: two converged iterations (2^10 eps each)
        np.testing.assert_allclose(back, np.asarray(y), rtol=0, atol=2**12 * EPS * max(1.0, float(jnp.abs(y).max())))
    # without the symmetrisation only the chosen R reverses the step (the same MLP weights)
    plain = learn.Reversible(learn.LPNet(system, hidden=(8, 8), key=3, h=0.1))
    y1 = steps(plain, y)
    other = reversing_symmetries(system)[1]
    assert np.abs(other * np.asarray(steps(plain, jnp.asarray(other) * y1)) - np.asarray(y)).max() > 1e-6


def test_casimirs_exact_and_save_load_roundtrip(tmp_path):
    net = equivariant(SO4, key=5)
    y = np.random.default_rng(6).uniform(-1.0, 1.0, size=(4, 6))
    traj = np.asarray(net.rollout(y, 500))
    C = np.asarray(SO4.casimirs(traj))
    # round-off random walk: 500 steps of a few roundings each, quadratic Casimirs of |y| ~ 1
    assert np.abs(C - C[:, :1]).max() < 500 * 64 * EPS
    # the file keeps the group (without the identity), not how it was asked for: the weights'
    # function cannot change on reload
    spec = net.hyperparameters()["network"]
    assert spec["kind"] == "GroupAveraged" and spec["network"]["kind"] == "AffineMLP"
    assert spec["group"] == [[int(v) for v in s] for s in net.network.group if min(s) < 0]
    assert len(spec["group"]) == 7
    net.save(tmp_path / "eq.h5")
    back = learn.LPNet.load(tmp_path / "eq.h5")
    assert isinstance(back.network, learn.GroupAveraged) and back.network.group == net.network.group
    assert net.reinitialised(9).network.group == net.network.group
    assert np.array_equal(np.asarray(back.rollout(y, 500)), traj)  # the program of the rollout above
    # the paper's LPNet has the plain network
    assert learn.LPNet(SO4, hidden=(8, 8), key=5).hyperparameters()["network"]["kind"] == "AffineMLP"


@pytest.mark.slow  # 1000 epochs (~4 s); the symmetry for any weights is tested by default above
def test_training_keeps_the_symmetry_and_fits():
    data = it.ground_truth(RB, Y, h=0.1, n_steps=20, progress=False)
    net = equivariant(RB, key=0, h=None)
    # 1000 epochs: one compiled chunk (a second chunk compiles again; measured loss ratio 3e-4)
    fitted, record = learn.fit(net, data, epochs=1000, progress=False, validation_fraction=0.0)
    y0 = jnp.asarray(data.states[:, :-1].reshape(-1, 3))
    y1 = jnp.asarray(data.states[:, 1:].reshape(-1, 3))
    assert record.train_loss < 1e-2 * float(learn.state_mse(net.with_h(0.1), y0, y1))
    assert isinstance(fitted.network, learn.GroupAveraged) and fitted.network.group == net.network.group
    s = np.asarray(net.network.group[0])
    np.testing.assert_allclose(np.asarray(steps(fitted, jnp.asarray(s) * y0)), s * np.asarray(steps(fitted, y0)),
                               rtol=0, atol=64 * EPS)


class PermutedFlows(learn.TestFlowParametrisation):
    """The rigid body's test flows with the parameters reversed, T(P alpha): a parametrisation
    whose parameters do not transform like the state under the half-turns that do not commute
    with P (exploration of the check only)."""

    def step(self, params, y, h):
        return super().step(params[::-1], y, h)


def test_a_parametrisation_that_breaks_the_law_is_refused():
    p = PermutedFlows(RB)
    # P swaps components 0 and 2: only S = (-1, 1, -1) commutes with it
    with pytest.raises(ValueError,
                       match=r"under S in \[\[-1, -1, 1\], \[1, -1, -1\]\]; leave those out of GroupAveraged"):
        learn.LPNet(RB, parametrisation=p, network=averaged(RB))
    net = learn.LPNet(RB, parametrisation=p, h=0.1, network=averaged(RB, hidden=(8,), group=[[-1, 1, -1]]))
    assert net.network.group == ((-1.0, 1.0, -1.0), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match=r"under S in \[\[-1, -1, 1\]\]; leave those out"):
        learn.LPNet(RB, parametrisation=p, network=averaged(RB, group=[[-1, -1, 1]]))
    with pytest.raises(ValueError,
                       match=r"GroupAveraged.group element = \[1, 1, -1\] is not a symmetry.*not Poisson"):
        learn.LPNet(RB, network=averaged(RB, group=[[1, 1, -1]]))
