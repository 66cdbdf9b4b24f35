"""Trajectories: learning views, subsets, HDF5 round trip, refusal of bad files, atomic write."""

import json
import os

import h5py
import numpy as np
import pytest

import integrators as it
import liepoisson as lp


@pytest.fixture
def data():
    states = np.random.default_rng(1).normal(size=(4, 6, 6))
    return it.Trajectories(
        states, 0.1, lp.systems.Kirchhoff(inertia=(1, 2, 1), mass=(1, 2, 1)), tolerance=1e-16, seed=7
    )


def test_attributes(data):
    assert (data.n_traj, data.n_steps, data.dim) == (4, 5, 6)
    np.testing.assert_array_equal(data.times, 0.1 * np.arange(6))
    assert data.metadata["system"] == "Kirchhoff" and data.metadata["seed"] == 7
    one = it.Trajectories(np.zeros((3, 3)), 0.5, lp.systems.RigidBody())
    assert one.states.shape == (1, 3, 3)


def test_pairs_and_split(data):
    y0, y1 = data.pairs()
    assert y0.shape == y1.shape == (4 * 5, 6)
    np.testing.assert_array_equal(y0[5], data.states[1, 0])
    np.testing.assert_array_equal(y1[5], data.states[1, 1])
    (a0, _a1), (v0, v1) = data.split(0.2, seed=3)
    assert a0.shape == (16, 6) and v0.shape == (4, 6)
    both = np.concatenate([a0, v0])
    assert sorted(map(tuple, both)) == sorted(map(tuple, y0))  # a partition of the pairs
    # each validation pair is still a consecutive pair
    idx = [int(np.flatnonzero((y0 == v).all(1))[0]) for v in v0]
    np.testing.assert_array_equal(v1, y1[idx])
    (b0, _), _ = data.split(0.2, seed=3)
    np.testing.assert_array_equal(a0, b0)
    (c0, _), _ = data.split(0.2, seed=4)
    assert not np.array_equal(a0, c0)
    with pytest.raises(ValueError, match="validation_fraction"):
        data.split(1.0)


def test_select_and_concatenate(data):
    assert data[1].states.shape == (1, 6, 6)
    np.testing.assert_array_equal(data[1:3].states, data.states[1:3])
    np.testing.assert_array_equal(data.select([3, 0]).states, data.states[[3, 0]])
    both = it.Trajectories.concatenate([data[:2], data[2:]])
    np.testing.assert_array_equal(both.states, data.states)
    other = it.Trajectories(data.states, 0.2, data.system)
    with pytest.raises(ValueError, match="h="):
        it.Trajectories.concatenate([data, other])
    with pytest.raises(IndexError):
        data[10]


def test_round_trip_bit_identical(data, tmp_path):
    path = tmp_path / "k.h5"
    data.save(path)
    back = it.Trajectories.load(path)
    assert back.states.tobytes() == data.states.tobytes()
    assert back.times.tobytes() == data.times.tobytes()
    assert back.metadata == data.metadata
    assert type(back.system) is lp.systems.Kirchhoff and back.system.params == data.system.params
    assert os.listdir(tmp_path) == ["k.h5"]  # no temporary file left behind
    with h5py.File(path) as f:
        assert json.loads(f.attrs["system_params"]) == data.system.params
        assert f["trajectories"].dtype == np.float64


def test_round_trip_ground_truth(tmp_path):
    gt = it.ground_truth(lp.systems.ChargedParticle(), [1.0, 0.5, 0.5, 1.0], 0.1, 10)
    gt.save(tmp_path / "cp.h5")
    back = it.Trajectories.load(tmp_path / "cp.h5")
    assert back.states.tobytes() == gt.states.tobytes() and back.metadata == gt.metadata
    assert back.seed is None and back.tolerance == gt.tolerance


def test_foreign_file_refused(tmp_path):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("weights", data=np.zeros(3))
    with pytest.raises(ValueError, match=r"foreign\.h5.*missing.*trajectories"):
        it.Trajectories.load(path)


def test_not_hdf5_refused(tmp_path):
    path = tmp_path / "text.h5"
    path.write_text("hello")
    with pytest.raises(ValueError, match=r"text\.h5.*not a readable HDF5"):
        it.Trajectories.load(path)


def test_truncated_file_refused(data, tmp_path):
    path = tmp_path / "cut.h5"
    data.save(path)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match=r"cut\.h5"):
        it.Trajectories.load(path)


def test_corrupt_attributes_refused(data, tmp_path):
    path = tmp_path / "bad.h5"
    data.save(path)
    with h5py.File(path, "a") as f:
        f.attrs["system_params"] = "{not json"
    with pytest.raises(ValueError, match=r"bad\.h5.*system"):
        it.Trajectories.load(path)


def test_wrong_version_refused(data, tmp_path):
    path = tmp_path / "v2.h5"
    data.save(path)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 2
    with pytest.raises(ValueError, match=r"v2\.h5.*format_version 2"):
        it.Trajectories.load(path)


def test_failed_write_does_not_clobber(data, tmp_path, monkeypatch):
    path = tmp_path / "keep.h5"
    data.save(path)
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError, match="disk full"):
        it.Trajectories(np.ones((1, 2, 6)), 0.1, data.system).save(path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["keep.h5"]


@pytest.mark.parametrize(
    "args, error, words",
    [
        ((np.zeros((2, 3, 4)), 0.1), ValueError, ["states", "3)", "(2, 3, 4)"]),
        ((np.full((1, 3, 3), np.nan), 0.1), ValueError, ["states", "finite"]),
        ((np.zeros((1, 3, 3)), -1.0), ValueError, ["h", "-1.0"]),
    ],
)
def test_validation(args, error, words):
    with pytest.raises(error) as info:
        it.Trajectories(*args, lp.systems.RigidBody())
    for w in words:
        assert w in str(info.value)


def test_validation_split_is_the_rule_of_pairs_and_observations(data):
    """`validation_split` is the one split: sorted, disjoint indices covering every item, the
    validation part a seeded draw of round(fraction * n), the same as `Trajectories.split`."""
    from integrators.internals import validation_split

    train, val = validation_split(20, 0.2, 3)
    assert len(val) == 4 and np.array_equal(np.sort(np.concatenate([train, val])), np.arange(20))
    assert np.all(np.diff(train) > 0) and np.all(np.diff(val) > 0)
    perm = np.random.default_rng(3).permutation(20)  # the rule, written out
    np.testing.assert_array_equal(val, np.sort(perm[:4]))
    y0, _ = data.pairs()
    (a0, _), (v0, _) = data.split(0.2, seed=3)
    np.testing.assert_array_equal(a0, y0[train])
    np.testing.assert_array_equal(v0, y0[val])
    train, val = validation_split(5, 0.0, None)
    assert np.array_equal(train, np.arange(5)) and val.size == 0
    with pytest.raises(ValueError, match="leaves no training trajectory out of 3"):
        validation_split(3, 0.9, 0, "trajectory")
