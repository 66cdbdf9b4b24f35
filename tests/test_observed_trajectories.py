"""The base both kinds of observed trajectories share: the same intervals, selection and split."""

from __future__ import annotations

import numpy as np
import pytest

import integrators as it
import liepoisson as lp

BODY = lp.systems.RigidBody()


def _both():
    """Observations and BodyObservations of three trajectories at the same uneven times."""
    rng = np.random.default_rng(0)
    times = [np.cumsum(rng.uniform(0.05, 0.3, size=n)) for n in (4, 6, 5)]
    states = [rng.normal(size=(t.size, 3)) for t in times]
    obs = it.Observations(BODY, times, states, metadata={"made": "test"})
    body = it.BodyObservations(BODY, times, velocities=states, metadata={"made": "test"})
    return times, states, obs, body


def test_one_base_one_meaning_of_intervals():
    times, states, obs, body = _both()
    for data in (obs, body):
        assert isinstance(data, it.AbstractObservedTrajectories)
        np.testing.assert_array_equal(data.intervals(), np.concatenate([np.diff(t) for t in times]))
        assert data.n_observations == 15 and len(data) == 3 and data.dim == 3
        assert not data.is_regular()
    y0, y1, dt = obs.pairs()
    np.testing.assert_array_equal(dt, obs.intervals())
    np.testing.assert_array_equal(y0[:3], states[0][:-1])
    np.testing.assert_array_equal(y1[3:8], states[1][1:])


@pytest.mark.parametrize("which", [2, 3])
def test_select_and_split_keep_the_kind_and_the_trajectories(which):
    times, states, obs, body = _both()
    data = obs if which == 2 else body
    picked = data.select([2, 0])
    assert type(picked) is type(data) and picked.metadata == {"made": "test"}
    np.testing.assert_array_equal(picked.times[0], times[2])
    measured = picked.states if which == 2 else picked.velocities
    np.testing.assert_array_equal(measured[1], states[0])
    train, val = data.split(1 / 3, seed=4)
    assert type(train) is type(data) and type(val) is type(data)
    got = sorted(t[0] for t in train.times + val.times)
    assert got == sorted(t[0] for t in times)  # every trajectory in exactly one part
    assert data.split(0.0)[1] is None


@pytest.mark.parametrize("bad, error", [([], TypeError), ([0.5], TypeError), ([3], IndexError), (-4, IndexError)])
def test_select_names_a_bad_index(bad, error):
    _, _, obs, body = _both()
    for data in (obs, body):
        with pytest.raises(error, match="indices"):
            data.select(bad)
