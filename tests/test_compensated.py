"""Compensated composition (integrators.Compensated of a G-LPNet): TwoSum is error-free, a
compensated step is the plain step up to round-off, long runs keep the Casimirs closer than
the plain map, and the plain map is untouched."""

from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS, slow_except, system
from hypothesis import given
from hypothesis import strategies as st

import integrators as it
import learn
from integrators.splitting import (
    Compensated,
    LieTrotter,
    Splitting,
    Strang,
    TripleJump,
    compensated_flow,
    two_sum,
)

finite = st.floats(-1e300, 1e300, allow_nan=False, allow_infinity=False)


@given(a=finite, b=finite)
def test_two_sum_is_error_free(a, b):
    s, e = (float(x) for x in two_sum(np.float64(a), np.float64(b)))
    assert s == a + b  # the rounded sum
    assert Fraction(s) + Fraction(e) == Fraction(a) + Fraction(b)  # and exactly its error


def test_two_sum_inside_jit_is_not_simplified_away():
    # XLA may not reassociate (s - a) - b: the error term must survive compilation.
    s, e = jax.jit(two_sum)(np.array([1.0, 1e16]), np.array([1e-17, 1.0]))
    assert np.array_equal(np.asarray(s), [1.0, 1e16]) and np.array_equal(np.asarray(e), [1e-17, 1.0])


@pytest.mark.parametrize("name", ["RigidBody", "Kirchhoff", "ChargedParticle"])
def test_compensated_test_flow_is_the_test_flow(name):
    sys_ = system(name)
    rng = np.random.default_rng(0)
    alpha, y = rng.normal(size=sys_.dim), rng.normal(size=sys_.dim)
    if name == "ChargedParticle":
        y[2:] += 1.0  # away from the singular |x| = 0
    plain = np.asarray(jax.jit(lambda y: sys_.test_flow(alpha, 0.3, y))(y))
    hi, lo = jax.jit(lambda y: compensated_flow(lambda z: sys_.test_flow_increment(alpha, 0.3, z),
                                                (y, jnp.zeros_like(y))))(y)
    # One rounding of the plain sum (half an ulp a component) and a few of the increment:
    # 4 eps |y| holds both.
    assert np.max(np.abs(np.asarray(hi) + np.asarray(lo) - plain)) <= 4 * EPS * np.linalg.norm(y)


def _net(name, method=None, key=3):
    return learn.GLPNet(system(name), key=key, method=TripleJump() if method is None else method, h=0.1)


@pytest.mark.parametrize("method", [LieTrotter(), Strang(ordering=(5, 0, 4, 1, 3, 2)), TripleJump()])
def test_compensated_step_is_the_plain_step_up_to_round_off(method):
    net = _net("RigidBody", method)
    y = np.random.default_rng(2).normal(size=3)
    plain, compensated = np.asarray(net.step(y)), np.asarray(Compensated(net).step(y))
    # each of the step's flows rounds differently in the two: a few eps |y| per flow
    assert np.max(np.abs(plain - compensated)) <= 4 * EPS * np.linalg.norm(y) * net.exact_flows_per_step
    assert not np.array_equal(plain, compensated) or method == LieTrotter()  # (a different computation)


def test_plain_step_is_still_the_composition_of_the_test_flows():
    """The default path does not go through the increments: a G-LPNet's Lie-Trotter step is,
    bit for bit, its modules' test flows applied in turn (a Python loop, compiled)."""
    net = _net("RigidBody", LieTrotter())
    y = np.random.default_rng(3).normal(size=3)

    def chain(y):
        for s in range(net.n_modules):
            y = net.system.test_flow(net.terms.velocity(s, y), 0.1 / net.n_modules, y)
        return y

    assert np.array_equal(np.asarray(jax.jit(lambda y: net.step(y))(y)), np.asarray(jax.jit(chain)(y)))


def _largest_drifts(step_map, Y0, n_steps):
    """The largest change of each Casimir over the run and the trajectories, relative to its
    scale |grad C(y0)| |y0|, in eps."""
    sys_ = step_map.system
    ys = np.asarray(step_map.rollout(Y0, n_steps, save_every=n_steps // 10))
    C = np.asarray(sys_.casimirs(ys))
    scale = (np.linalg.norm(np.asarray(sys_.casimir_gradients(Y0)), axis=-1)
             * np.linalg.norm(Y0, axis=-1)[:, None])
    return np.max(np.abs(C - C[:, :1]) / scale[:, None, :], axis=(0, 1)) / EPS


# The rigid body by default (Kirchhoff's, the se(3) increments, compiles for 7 s more; its
# increments are tested against expm in test_coadjoint.py)
@pytest.mark.parametrize("name", slow_except(["RigidBody", "Kirchhoff"], {"RigidBody"}))
def test_compensated_long_run_keeps_the_casimirs_closer(name):
    net = _net(name)
    Y0 = np.random.default_rng(1).normal(size=(8, net.system.dim))
    plain = _largest_drifts(net, Y0, 1000)
    compensated = _largest_drifts(Compensated(net), Y0, 1000)
    # 3-7 x 10^4 flows: the plain Casimirs random-walk by eps|y| a flow, to tens of eps (measured
    # 2-82 eps per trajectory); the compensated ones by eps |t alpha| |y|, the largest over 8
    # trajectories 29-250 times less than the plain largest (measured, two nets, 1000 and 3000
    # steps): a factor 4 is a robust margin.
    assert np.all(4 * compensated < plain), (plain, compensated)


def test_compensated_wraps_only_maps_of_compensable_flows():
    expected = r"step_map must be a step map that can run compensated \(an integrators.AbstractCompensable"
    with pytest.raises(TypeError, match=expected + r".*; got Splitting\("):
        Compensated(Splitting(system("RigidBody"), 0.1, Strang()))
    with pytest.raises(TypeError, match=expected + ".*; got a Strang"):
        Compensated(Strang())


def test_one_wrapper_for_every_compensable_map():
    # integrators.splitting's names are integrators', not copies
    assert Compensated is it.Compensated and two_sum is it.two_sum
    assert issubclass(learn.GLPNet, it.AbstractCompensable)
    assert issubclass(it.IsospectralMidpoint, it.AbstractCompensable)
    assert issubclass(learn.IsospectralPolynomial, it.AbstractCompensable)  # a learned isospectral map too


def test_compensated_is_a_step_map_of_the_wrapped_one():
    net = _net("RigidBody")
    m = Compensated(net)
    assert isinstance(m, it.AbstractStepMap)
    assert m.system is net.system and m.h == net.h and m.label == "Compensated(GLPNet)"
    assert m.exact_flows_per_step == net.exact_flows_per_step
    shorter = m.with_h(0.05)
    assert isinstance(shorter, Compensated) and shorter.h == 0.05 and shorter.step_map.h == 0.05
    y0 = np.random.default_rng(4).normal(size=(2, 3))
    ys = np.asarray(m.rollout(y0, 6, save_every=2))
    one, step = y0, jax.jit(jax.vmap(lambda y: m.step(y)))
    for k in range(1, 7):
        one = np.asarray(step(one))  # from a fresh (y, 0) each step
        if k % 2 == 0:
            # the rollout carries y_lo between steps, the steps here restart at lo = 0: a few
            # eps per flow apart
            assert np.max(np.abs(ys[:, k // 2] - one)) <= 4 * EPS * 3 * k * net.exact_flows_per_step
    # a Poisson map (forward mode through the pair and TwoSum): the defect is round-off
    assert float(np.max(np.asarray(m.poisson_defect(y0)))) <= 1e3 * EPS
    with pytest.raises(ValueError, match="no step size"):
        Compensated(learn.GLPNet(system("RigidBody"), key=0)).rollout(y0, 1)
