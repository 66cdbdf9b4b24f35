"""Blow-up is an error, not a NaN: rollouts that leave the finite range raise naming the
trajectory, the step and the last finite state; coadjoint flows that overflow raise."""

from __future__ import annotations

import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from liepoisson.systems import LiePoissonSystem

BODY = lp.systems.RigidBody()


@pytest.mark.parametrize("save_every", [1, 2, 5])
def test_a_diverging_rollout_names_trajectory_step_and_last_state(save_every):
    m = it.RK4(BODY, h=20.0)  # far beyond RK4's stability region: grows until overflow
    y0 = np.array([[1e-3, 2e-3, 1e-3], [1.0, 0.5, 0.2]])  # the second one blows up first
    raw = np.asarray(m.rollout(y0, 60, save_every=save_every, nonfinite="return"))
    finite = np.isfinite(raw).all(axis=-1)
    assert not finite.all()
    first = [int(np.argmin(f)) if not f.all() else raw.shape[1] for f in finite]
    i = int(np.argmin(first))
    with pytest.raises(it.RolloutDivergedError, match=rf"RK4 \(h=20\) diverged: trajectory {i} became non-finite") as info:
        m.rollout(y0, 60, save_every=save_every)
    err = info.value
    assert err.trajectory == i and err.step == first[i] * save_every
    assert err.last_finite_step == (first[i] - 1) * save_every
    np.testing.assert_array_equal(err.state, raw[i, first[i] - 1])
    assert np.isfinite(err.state).all()
    np.testing.assert_array_equal(err.states, raw)


def test_a_single_state_and_a_finite_rollout():
    m = it.RK4(BODY, h=20.0)
    with pytest.raises(it.RolloutDivergedError, match="trajectory 0"):
        m.rollout(np.array([1.0, 0.5, 0.2]), 60)
    y = it.RK4(BODY, h=0.1).rollout(np.array([1.0, 0.5, 0.2]), 60)  # no error, all finite
    assert np.isfinite(np.asarray(y)).all()


def test_nonfinite_must_be_raise_or_return():
    with pytest.raises(ValueError, match=r"nonfinite must be one of \('raise', 'return'\) or an integrators.AbstractNonfinitePolicy; got 'ignore'"):
        it.RK4(BODY, h=0.1).rollout(np.ones(3), 2, nonfinite="ignore")


def test_nonfinite_policies_are_classes_and_their_names():
    """`RaiseIfNonfinite()` is `"raise"`, `ReturnNonfinite()` is `"return"`; a policy of your own
    sees the whole rollout."""
    m, y0 = it.RK4(BODY, h=20.0), np.array([[1.0, 0.5, 0.2], [0.1, 0.2, 0.3]])
    returned = np.asarray(m.rollout(y0, 60, nonfinite=it.ReturnNonfinite()))
    np.testing.assert_array_equal(returned, np.asarray(m.rollout(y0, 60, nonfinite="return")))
    assert not np.isfinite(returned).all()
    with pytest.raises(it.RolloutDivergedError, match="trajectory 0"):
        m.rollout(y0, 60, nonfinite=it.RaiseIfNonfinite())
    assert it.NONFINITE_POLICIES == {"raise": it.RaiseIfNonfinite(), "return": it.ReturnNonfinite()}

    seen = []

    class Record(it.AbstractNonfinitePolicy):
        name = "record"

        def check(self, step_map, out, save_every):
            seen.append((step_map, np.asarray(out), save_every))

    m.rollout(y0, 60, save_every=3, nonfinite=Record())
    assert seen[0][0] is m and seen[0][2] == 3
    np.testing.assert_array_equal(seen[0][1], returned[:, ::3])


@pytest.mark.slow
def test_splitting_on_a_non_compact_algebra_overflows_into_an_error():
    """sl(2) has non-compact orbits: exp(t M(alpha)) grows like exp(|t alpha|); a hyperbolic
    Hamiltonian at a large step overflows inside the compiled rollout: an error, not NaN."""
    system = LiePoissonSystem(lp.sl2(), lambda m, xp: 0.5 * (m[0] ** 2 - m[1] ** 2) + 0.5 * m[2] ** 2)
    m = it.splitting.Strang(system, h=40.0)
    with pytest.raises(it.RolloutDivergedError, match="Strang"):
        m.rollout(np.array([[3.0, 1.0, 0.5]]), 200)


@pytest.mark.slow  # the overflow's error by default in test_reliability.py and test_matrix_algebra.py
def test_coadjoint_flow_overflow_is_detected():
    g = lp.sl2()
    ok = np.asarray(g.coadjoint_flow([1.0, 0.0, 0.0], 1.0, [1.0, 1.0, 1.0]))
    assert np.isfinite(ok).all()
    with pytest.raises(FloatingPointError, match=r"overflowed at batch index \(1,\): \|t\| \|alpha\| = 800"):
        g.coadjoint_flow(np.array([[1.0, 0.0, 0.0], [800.0, 0.0, 0.0]]), 1.0, [1.0, 1.0, 1.0])
    # compact so(3): a rotation by any angle stays bounded, whatever |alpha|
    big = np.asarray(lp.so3().coadjoint_flow([1e6, 2e6, -3e6], 1.0, [1.0, 2.0, 3.0]))
    assert np.isfinite(big).all()
