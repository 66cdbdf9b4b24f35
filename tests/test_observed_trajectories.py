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


def test_groups_travel_with_their_trajectories_and_through_files(tmp_path):
    times, states, _, _ = _both()
    groups = ["monday", 7, "monday"]
    obs = it.Observations(BODY, times, states, groups=groups)
    body = it.BodyObservations(BODY, times, velocities=states, groups=np.array(groups, dtype=object))
    for data, kind in ((obs, it.Observations), (body, it.BodyObservations)):
        assert data.groups == ("monday", 7, "monday")
        np.testing.assert_array_equal(data.group_index(), [0, 1, 0])
        assert data.n_groups == 2
        assert data.select([1, 2]).groups == (7, "monday")
        train, val = data.split(1 / 3, seed=4)
        assert sorted(map(str, train.groups + val.groups)) == sorted(map(str, groups))
        path = tmp_path / f"{kind.__name__}.h5"
        data.save(path)
        back = kind.load(path)
        assert back.groups == data.groups
        data.select([0]).save(path)
        assert kind.load(path).groups == ("monday",)
    # without groups: each trajectory its own, and nothing written
    plain = it.Observations(BODY, times, states)
    assert plain.groups is None and plain.n_groups == 3
    np.testing.assert_array_equal(plain.group_index(), [0, 1, 2])
    plain.save(tmp_path / "plain.h5")
    assert it.Observations.load(tmp_path / "plain.h5").groups is None
    body_plain = it.BodyObservations(BODY, times, velocities=states).in_units(0.5)
    assert body_plain.groups is None


@pytest.mark.parametrize("groups, error, match", [
    ("abc", TypeError, "sequence of labels"),
    (["a", "b"], ValueError, r"one label per trajectory \(3\); got 2"),
    (["a", 1.5, "b"], TypeError, r"groups\[1\] must be a string or an integer .* 1\.5"),
    (["a", True, "b"], TypeError, r"groups\[1\] must be a string or an integer"),
])
def test_bad_groups_are_named(groups, error, match):
    times, states, _, _ = _both()
    with pytest.raises(error, match=match):
        it.Observations(BODY, times, states, groups=groups)
    with pytest.raises(error, match=match):
        it.BodyObservations(BODY, times, velocities=states, groups=groups)


def test_a_file_with_foreign_groups_is_refused(tmp_path):
    import h5py

    _, _, obs, body = _both()
    for data, kind in ((obs, it.Observations), (body, it.BodyObservations)):
        path = tmp_path / f"{kind.__name__}.h5"
        data.save(path)
        with h5py.File(path, "r+") as f:
            f.attrs["groups"] = '{"not": "a list"}'
        with pytest.raises(ValueError, match="attribute groups must be a JSON list of labels"):
            kind.load(path)


def test_sessions_read_one_file_each_are_concatenated_with_their_labels(tmp_path):
    times, states, obs, body = _both()
    for data, kind in ((obs, it.Observations), (body, it.BodyObservations)):
        joined = kind.concatenate([data, data.select([1])], groups=["day 1", "day 2"])
        assert type(joined) is kind and len(joined) == 4
        assert joined.groups == ("day 1",) * 3 + ("day 2",)
        np.testing.assert_array_equal(joined.times[3], times[1])
        assert joined.metadata == {"concatenated": [data.metadata, data.metadata]}
        # groups of their own are kept; a mixture is refused
        labelled = kind.concatenate([data, data], groups=["a", "b"])
        assert kind.concatenate([labelled, labelled.select([0])]).groups == ("a",) * 3 + ("b",) * 3 + ("a",)
        with pytest.raises(ValueError, match="some datasets have groups and some do not"):
            kind.concatenate([labelled, data])
        with pytest.raises(TypeError, match=f"non-empty sequence of {kind.__name__}"):
            kind.concatenate([])
    with pytest.raises(TypeError, match="non-empty sequence of Observations"):
        it.Observations.concatenate([obs, body])
    with pytest.raises(ValueError, match=r"datasets\[1\] is of"):
        it.Observations.concatenate([obs, it.Observations(lp.systems.RigidBody(inertia=(1.0, 2.0, 4.0)),
                                                           times, states)])
    rates = it.BodyObservations(BODY, times, velocities=states)
    with pytest.raises(ValueError, match="concatenate observations of the same measurements"):
        it.BodyObservations.concatenate([rates, it.BodyObservations(
            BODY, times, configurations=[np.tile([0.0, 0.0, 0.0, 1.0], (t.size, 1)) for t in times])])
    # a gyroscope file read as one session
    path = tmp_path / "session.csv"
    it.write_gyro_csv(path, rates.select([0]))
    read = it.read_gyro_csv(path, BODY, group="tuesday")
    assert read.groups == ("tuesday",)
    with pytest.raises(TypeError, match="group must be a label"):
        it.read_gyro_csv(path, BODY, group=1.5)
