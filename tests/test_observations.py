"""Observations: trajectories at their own uneven times (possibly noisy), their files (HDF5,
long-format .npz and .csv), `observe` (heyoka ground truth with seeded noise and drops) and
`uneven_times`."""

import os
import re

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import integrators as it
import liepoisson as lp
from liepoisson.systems import LiePoissonSystem

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))


def diamond() -> LiePoissonSystem:
    """A system of a non-catalogue algebra: the 4-dim solvable diamond algebra [e1, e2] = e3,
    [e4, e1] = e1, [e4, e2] = -e2, from its structure constants."""
    C = np.zeros((4, 4, 4))
    for a, b, d, v in ((0, 1, 2, 1.0), (3, 0, 0, 1.0), (3, 1, 1, -1.0)):
        C[a, b, d], C[b, a, d] = v, -v
    algebra = lp.LieAlgebra(C, "diamond", ("p", "q", "z", "n"))
    return LiePoissonSystem(algebra, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2) + m[3], name="diamond oscillator")


# Two trajectories of different lengths, at uneven times of their own.
T0 = np.array([0.0, 0.1, 0.35])
T1 = np.array([1.0, 1.2, 1.25, 1.9, 2.0])
Y0 = np.random.default_rng(0).normal(size=(3, 3))
Y1 = np.random.default_rng(1).normal(size=(5, 3))


@pytest.fixture
def obs():
    return it.Observations(BODY, [T0, T1], [Y0, Y1], metadata={"instrument": "gyro", "run": [1, 2]})


def _as_set(o: it.Observations) -> list[tuple[bytes, bytes]]:
    """The trajectories of `o`, bit for bit, in no particular order."""
    return sorted((t.tobytes(), y.tobytes()) for t, y in zip(o.times, o.states))


# -- 1. construction ----------------------------------------------------------------------------
def test_from_a_list_of_trajectories_of_different_lengths(obs):
    assert (obs.n_trajectories, len(obs), obs.dim, obs.n_observations) == (2, 2, 3, 8)
    assert obs.system is BODY
    for got, want in zip(obs.times, [T0, T1]):
        assert got.dtype == np.float64 and got.tobytes() == want.tobytes()
    for got, want in zip(obs.states, [Y0, Y1]):
        assert got.dtype == np.float64 and got.tobytes() == want.tobytes()
    assert obs.metadata == {"instrument": "gyro", "run": [1, 2]}
    # The data are copies: changing the caller's arrays afterwards changes nothing.
    t, y, meta = T0.copy(), Y0.copy(), {"a": [1]}
    o = it.Observations(BODY, [t, T1], [y, Y1], metadata=meta)
    t[1], y[0, 0] = 0.05, 99.0
    meta["a"].append(2)
    assert o.times[0][1] == 0.1 and o.states[0][0, 0] == Y0[0, 0] and o.metadata == {"a": [1]}
    # Integer input is converted to float64.
    o = it.Observations(BODY, [[0, 1, 3]], [np.arange(9).reshape(3, 3)])
    assert o.times[0].dtype == o.states[0].dtype == np.float64


def test_from_an_array_with_shared_times():
    states = np.random.default_rng(2).normal(size=(4, 6, 3))
    times = np.array([0.0, 0.1, 0.3, 0.35, 0.8, 1.0])
    for t in (times, list(times)):  # one 1-D array (or list) shared by every trajectory
        o = it.Observations(BODY, t, states)
        assert (o.n_trajectories, o.n_observations) == (4, 24)
        for j in range(4):
            np.testing.assert_array_equal(o.times[j], times)
            np.testing.assert_array_equal(o.states[j], states[j])
    # ... or an (n_traj, n) array, one row per trajectory.
    per = times + np.arange(4)[:, None]
    o = it.Observations(BODY, per, states)
    for j in range(4):
        np.testing.assert_array_equal(o.times[j], per[j])


def test_from_a_single_trajectory():
    y = np.random.default_rng(3).normal(size=(5, 3))
    t = np.array([0.0, 0.2, 0.3, 0.7, 0.75])
    o = it.Observations(BODY, t, y)
    assert o.n_trajectories == 1 and o.n_observations == 5
    np.testing.assert_array_equal(o.times[0], t)
    np.testing.assert_array_equal(o.states[0], y)
    # (n, dim) with n == dim is still one trajectory of n observations.
    o = it.Observations(BODY, t[:3], y[:3])
    assert o.n_trajectories == 1 and o.states[0].shape == (3, 3)


def test_intervals_are_exactly_the_consecutive_pairs(obs):
    y0, y1, dt = obs.pairs()
    # By hand: (0,1), (1,2) of trajectory 0, then (0,1), (1,2), (2,3), (3,4) of trajectory 1;
    # never the pair (last of trajectory 0, first of trajectory 1).
    want0 = np.stack([Y0[0], Y0[1], Y1[0], Y1[1], Y1[2], Y1[3]])
    want1 = np.stack([Y0[1], Y0[2], Y1[1], Y1[2], Y1[3], Y1[4]])
    want_dt = np.array([T0[1] - T0[0], T0[2] - T0[1], T1[1] - T1[0], T1[2] - T1[1], T1[3] - T1[2], T1[4] - T1[3]])
    np.testing.assert_array_equal(y0, want0)
    np.testing.assert_array_equal(y1, want1)
    np.testing.assert_array_equal(dt, want_dt)
    np.testing.assert_allclose(dt, [0.1, 0.25, 0.2, 0.05, 0.65, 0.1], rtol=1e-13)
    assert y0.shape == y1.shape == (6, 3) and dt.shape == (6,)


def test_is_regular():
    states = np.random.default_rng(4).normal(size=(3, 11, 3))
    assert it.Observations(BODY, 0.1 * np.arange(11), states).is_regular()  # rounding within rtol
    assert it.Observations(BODY, 0.1 * np.arange(11) + np.arange(3)[:, None], states).is_regular()  # shifted starts
    uneven = 0.1 * np.arange(11)
    uneven[5] += 0.01
    assert not it.Observations(BODY, uneven, states).is_regular()
    # Each trajectory regular, but not with the same step: not regular.
    steps = np.array([0.1, 0.1, 0.2])[:, None] * np.arange(11)
    assert not it.Observations(BODY, steps, states).is_regular()
    assert not it.Observations(BODY, [T0, T1], [Y0, Y1]).is_regular()


def test_rms_size_weighs_every_observation():
    # Norms 5 and 1, then three of norm 1: sqrt((25 + 1 + 3) / 5). (Averaging per trajectory
    # first would give sqrt((13 + 1) / 2) = sqrt(7) instead.)
    o = it.Observations(BODY, [[0.0, 1.0], [0.0, 1.0, 2.0]],
                        [[[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]], [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]])
    assert o.rms_size() == pytest.approx(np.sqrt(29 / 5), rel=1e-15)


def test_select(obs):
    both = obs.select([1, 0])
    assert both.times[0].tobytes() == T1.tobytes() and both.states[1].tobytes() == Y0.tobytes()
    last = obs.select(-1)
    assert last.n_trajectories == 1 and last.states[0].tobytes() == Y1.tobytes()
    assert last.metadata == obs.metadata and last.system is BODY
    with pytest.raises(IndexError, match=r"out of range for 2 trajectories"):
        obs.select([0, 2])
    with pytest.raises(TypeError, match="indices must be an int or a non-empty sequence of ints"):
        obs.select([])
    with pytest.raises(TypeError, match="indices must be an int"):
        obs.select([0.5])


# -- 2. bad input ---------------------------------------------------------------------------------
def _with(a: np.ndarray, index, value) -> np.ndarray:
    a = a.copy()
    a[index] = value
    return a


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        pytest.param(lambda: it.Observations(BODY, [T0, np.array([1.0, 1.2, 1.1, 1.9, 2.0])], [Y0, Y1]),
                     ValueError, r"times\[1\] must be strictly increasing; times\[1\]\[2\] = 1.1 <.*unsorted time",
                     id="unsorted times"),
        pytest.param(lambda: it.Observations(BODY, [np.array([0.0, 0.1, 0.1]), T1], [Y0, Y1]),
                     ValueError, r"times\[0\] must be strictly increasing; times\[0\]\[2\] = 0.1 =.*repeated time",
                     id="repeated times"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1], [Y0, _with(Y1, (3, 2), np.nan)]),
                     ValueError, r"states\[1\] must be finite; observation 3 \(t = 1.9\), component 2 is nan\. "
                     r"Missing values are not masked", id="NaN in states"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1], [_with(Y0, (0, 1), -np.inf), Y1]),
                     ValueError, r"states\[0\] must be finite; observation 0.*component 1 is -inf\. "
                     r"Missing values are not masked", id="inf in states"),
        pytest.param(lambda: it.Observations(BODY, [T0, _with(T1, 2, np.nan)], [Y0, Y1]),
                     ValueError, r"times\[1\] must be finite; times\[1\]\[2\] = nan", id="NaN in times"),
        pytest.param(lambda: it.Observations(BODY, [T0, _with(T1, 4, np.inf)], [Y0, Y1]),
                     ValueError, r"times\[1\] must be finite; times\[1\]\[4\] = inf", id="inf in times"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1[:1]], [Y0, Y1[:1]]),
                     ValueError, r"trajectory 1 has 1 observation\(s\); a trajectory needs at least two",
                     id="one observation"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1[:4]], [Y0, Y1]),
                     ValueError, r"times\[1\] has 4 entries and states\[1\] 5 observations", id="fewer times"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1], [Y0, Y1[:4]]),
                     ValueError, r"times\[1\] has 5 entries and states\[1\] 4 observations", id="fewer states"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1], [Y0, np.ones((5, 4))]),
                     ValueError, r"states\[1\] must have shape \(n_observations, 3\).*got shape \(5, 4\)",
                     id="wrong dimension"),
        pytest.param(lambda: it.Observations(BODY, [T0, T1, T1], [Y0, Y1]),
                     ValueError, r"times has 3 trajectories and states 2", id="more time arrays"),
        pytest.param(lambda: it.Observations(BODY, [T0], [Y0, Y1]),
                     ValueError, r"times has 1 trajectories and states 2", id="fewer time arrays"),
        pytest.param(lambda: it.Observations("RigidBody", [T0, T1], [Y0, Y1]),
                     TypeError, r"system must be an AbstractPoissonSystem; got str", id="not a system"),
        pytest.param(lambda: it.Observations(lp.so3(), [T0, T1], [Y0, Y1]),
                     TypeError, r"system must be an AbstractPoissonSystem; got LieAlgebra", id="an algebra"),
        pytest.param(lambda: it.Observations(BODY, T0, np.zeros((0, 3, 3))),
                     ValueError, r"at least one trajectory", id="no trajectory"),
        pytest.param(lambda: it.Observations(BODY, "0 1 2", [Y0]),
                     TypeError, r"times must be a real array or a list of arrays; got str", id="times a string"),
        pytest.param(lambda: it.Observations(BODY, [T0], [Y0], metadata={"f": print}),
                     TypeError, r"metadata must be a dict of JSON values", id="metadata not JSON"),
    ],
)
def test_bad_input_names_the_problem(make, error, match):
    with pytest.raises(error, match=match):
        make()


# -- 3. files -------------------------------------------------------------------------------------
def test_hdf5_round_trip_is_bit_identical(obs, tmp_path):
    path = tmp_path / "o.h5"
    obs.save(path)
    assert os.listdir(tmp_path) == ["o.h5"]  # atomic write: no temporary left behind
    back = it.Observations.load(path)
    assert back.n_trajectories == obs.n_trajectories
    for a, b in zip(back.times, obs.times):
        assert a.dtype == np.float64 and a.tobytes() == b.tobytes()
    for a, b in zip(back.states, obs.states):
        assert a.dtype == np.float64 and a.tobytes() == b.tobytes()
    assert back.metadata == obs.metadata
    # The system is rebuilt from the file: a new RigidBody with the same inertia.
    assert type(back.system) is lp.systems.RigidBody and back.system is not BODY
    assert back.system.params == BODY.params
    # Given the matching system, it is used as is; a different one is refused.
    assert it.Observations.load(path, system=BODY).system is BODY
    with pytest.raises(ValueError, match=r"does not match the file .*o\.h5"):
        it.Observations.load(path, system=lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)))
    with h5py.File(path) as f:
        assert set(f) == {"trajectory", "t", "states"} and f["states"].shape == (8, 3)


def test_hdf5_round_trip_rebuilds_a_user_system(tmp_path):
    system = diamond()
    data = it.observe(system, np.random.default_rng(5).normal(size=(3, 4)), it.uneven_times(3, 6, seed=2),
                      noise=0.01, drop=0.2, seed=1)
    data.save(tmp_path / "d.h5")
    back = it.Observations.load(tmp_path / "d.h5")
    assert isinstance(back.system, LiePoissonSystem) and back.system is not system
    assert back.system.name == "diamond oscillator"
    np.testing.assert_array_equal(back.system.algebra.structure_constants, system.algebra.structure_constants)
    assert _as_set(back) == _as_set(data) and back.metadata == data.metadata


def _long_rows(trajectories: dict[int, tuple[np.ndarray, np.ndarray]], seed: int):
    """The long format of `{label: (t, states)}`, rows shuffled."""
    label = np.concatenate([np.full(len(t), k) for k, (t, _) in trajectories.items()])
    t = np.concatenate([t for t, _ in trajectories.values()])
    y = np.concatenate([y for _, y in trajectories.values()])
    perm = np.random.default_rng(seed).permutation(len(t))
    return label[perm], t[perm], y[perm]


LONG = {7: (T0, Y0), 3: (T1, Y1)}


def test_npz_in_long_format(tmp_path):
    label, t, y = _long_rows(LONG, seed=0)
    assert not np.all(np.diff(t) > 0)  # really shuffled
    np.savez(tmp_path / "o.npz", trajectory=label, t=t, states=y)
    back = it.Observations.load(tmp_path / "o.npz", system=BODY)
    assert back.system is BODY and back.n_trajectories == 2
    assert _as_set(back) == _as_set(it.Observations(BODY, [T0, T1], [Y0, Y1]))


def test_csv_in_long_format(tmp_path):
    label, t, y = _long_rows(LONG, seed=1)
    lines = ["trajectory,t,y0,y1,y2"]
    lines += [",".join([str(int(k)), repr(float(s)), *(repr(float(v)) for v in row)]) for k, s, row in zip(label, t, y)]
    (tmp_path / "o.csv").write_text("\n".join(lines) + "\n")
    back = it.Observations.load(tmp_path / "o.csv", system=BODY)
    assert back.system is BODY and back.n_trajectories == 2
    # repr round-trips a float exactly, so the loaded data are bit-identical.
    assert _as_set(back) == _as_set(it.Observations(BODY, [T0, T1], [Y0, Y1]))


@given(data=st.data())
def test_from_columns_any_labels_any_row_order(data):
    n_traj = data.draw(st.integers(1, 4))
    labels = data.draw(st.lists(st.integers(-1000, 1000), min_size=n_traj, max_size=n_traj, unique=True))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**16)))
    trajectories = {}
    for k in labels:
        n = data.draw(st.integers(2, 6))
        trajectories[k] = (np.cumsum(rng.uniform(0.01, 1.0, n)) - 0.5, rng.normal(size=(n, 3)))
    label, t, y = _long_rows(trajectories, seed=data.draw(st.integers(0, 2**16)))
    back = it.Observations.from_columns(BODY, label, t, y)
    expected = it.Observations(BODY, [t for t, _ in trajectories.values()], [y for _, y in trajectories.values()])
    assert _as_set(back) == _as_set(expected)


def test_text_files_need_the_system(tmp_path):
    label, t, y = _long_rows(LONG, seed=0)
    np.savez(tmp_path / "o.npz", trajectory=label, t=t, states=y)
    (tmp_path / "o.csv").write_text("trajectory,t,y0,y1,y2\n" + "\n".join(
        ",".join(map(repr, [float(k), float(s), *map(float, row)])) for k, s, row in zip(label, t, y)))
    for name in ("o.npz", "o.csv"):
        path = tmp_path / name
        with pytest.raises(ValueError, match=re.escape(str(path)) + r".* holds no system: pass system="):
            it.Observations.load(path)
        with pytest.raises(TypeError, match="system must be an AbstractPoissonSystem; got str"):
            it.Observations.load(path, system="RigidBody")
        assert it.Observations.load(path, system=BODY).n_observations == 8


def _csv(path, text):
    path.write_text(text)


def _h5_foreign(path):
    with h5py.File(path, "w") as f:
        f.create_dataset("temperature", data=np.arange(5.0))


def _h5_trajectories(path):  # another liepoisson file: a regular data set, not observations
    it.ground_truth(BODY, [1.0, 0.5, 0.2], 0.1, 3).save(path)


def _h5_truncated(path):
    it.Observations(BODY, [T0, T1], [Y0, Y1]).save(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _h5_without(field):
    def make(path):
        it.Observations(BODY, [T0, T1], [Y0, Y1]).save(path)
        with h5py.File(path, "a") as f:
            del f[field]
    return make


def _h5_version(path):
    it.Observations(BODY, [T0, T1], [Y0, Y1]).save(path)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 2


@pytest.mark.parametrize(
    ("name", "make", "match"),
    [
        ("wrong_header.csv", lambda p: _csv(p, "traj,time,a,b,c\n0,0.0,1,2,3\n0,1.0,1,2,3\n"),
         r"has the header 'traj,time,a,b,c'; expected 'trajectory,t,y0,y1,y2'"),
        ("wrong_dim.csv", lambda p: _csv(p, "trajectory,t,y0,y1\n0,0.0,1,2\n0,1.0,1,2\n"),
         r"expected 'trajectory,t,y0,y1,y2'"),
        ("text.csv", lambda p: _csv(p, "trajectory,t,y0,y1,y2\n0,0.0,1,2,3\n0,one,1,2,3\n"), r"a row is not 5 numbers"),
        ("cut.csv", lambda p: _csv(p, "trajectory,t,y0,y1,y2\n0,0.0,1,2,3\n0,1.0,1,"), r"a row is not 5 numbers"),
        ("binary.csv", lambda p: p.write_bytes(bytes(range(256)) * 4), r"not a readable CSV file"),
        ("labels.csv", lambda p: _csv(p, "trajectory,t,y0,y1,y2\n0.5,0.0,1,2,3\n0.5,1.0,1,2,3\n"),
         r"trajectory labels must be integers"),
        ("repeated.csv", lambda p: _csv(p, "trajectory,t,y0,y1,y2\n4,0.0,1,2,3\n4,1.0,1,2,3\n4,1.0,1,2,3\n"),
         r"repeated time"),
        ("foreign.h5", _h5_foreign, r"is not a liepoisson observations file"),
        ("trajectories.h5", _h5_trajectories, r"is not a liepoisson observations file"),
        ("garbage.h5", lambda p: p.write_bytes(b"not hdf5 at all " * 64), r"not a readable HDF5 file"),
        ("truncated.h5", _h5_truncated, r"not a readable HDF5 file"),
        ("no_states.h5", _h5_without("states"), r"damaged or lacks a field"),
        ("version.h5", _h5_version, r"format_version 2"),
        ("no_states.npz", lambda p: np.savez(p, trajectory=np.zeros(2), t=np.arange(2.0)),
         r"lacks the array\(s\) \['states'\]"),
    ],
)
def test_bad_files_are_refused_naming_the_file(tmp_path, name, make, match):
    path = tmp_path / name
    make(path)
    system = None if name.endswith(".h5") else BODY
    with pytest.raises(ValueError, match=re.escape(repr(str(path))) + ".*" + match):
        it.Observations.load(path, system=system)


def test_garbage_npz_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "garbage.npz"
    path.write_bytes(b"not a zip file " * 64)
    with pytest.raises(ValueError, match=re.escape(str(path))):
        it.Observations.load(path, system=BODY)


def test_truncated_npz_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "cut.npz"
    label, t, y = _long_rows(LONG, seed=0)
    np.savez(path, trajectory=label, t=t, states=y)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=re.escape(str(path))):
        it.Observations.load(path, system=BODY)


# -- 4. observe -----------------------------------------------------------------------------------
Y0S = np.random.default_rng(6).normal(size=(5, 3))


def test_noise_free_observations_are_heyoka_ground_truth():
    gt = it.ground_truth(BODY, Y0S, 0.1, 20)
    o = it.observe(BODY, Y0S, gt.times)
    assert o.n_trajectories == 5 and o.is_regular()
    # Both are heyoka at the same tolerance (machine epsilon) from the same states on the same
    # grid: at most a few roundings apart, so a small multiple of eps times the states' size.
    scale = np.max(np.abs(gt.states))
    for j in range(5):
        np.testing.assert_array_equal(o.times[j], gt.times)
        assert np.max(np.abs(o.states[j] - gt.states[j])) <= 8 * EPS * scale
    assert o.metadata == {"source": "integrators.observe", "noise": 0.0, "noise_std": 0.0, "law": "gaussian",
                          "drop": 0.0, "seed": 0, "tolerance": None}
    # One initial state (dim,) with a shared 1-D grid: one trajectory.
    one = it.observe(BODY, Y0S[2], gt.times)
    assert one.n_trajectories == 1
    assert np.max(np.abs(one.states[0] - gt.states[2])) <= 8 * EPS * scale


def test_each_trajectory_starts_from_y0_at_its_first_time():
    gt = it.ground_truth(BODY, Y0S[:2], 0.1, 10)
    times = np.stack([gt.times + 5.0, gt.times - 2.0])
    o = it.observe(BODY, Y0S[:2], times)
    np.testing.assert_array_equal(o.times[0], gt.times + 5.0)
    np.testing.assert_array_equal(o.states[0][0], Y0S[0])
    # The system is autonomous, so this is the same motion; shifting the grid rounds each time
    # by about eps * 5 and the states move at speed O(|y|^2): a few hundred eps at most.
    scale = np.max(np.abs(gt.states))
    for j in range(2):
        assert np.max(np.abs(o.states[j] - gt.states[j])) <= 100 * EPS * scale


def test_observe_a_user_system():
    system = diamond()
    y0 = np.random.default_rng(7).normal(size=(2, 4))
    gt = it.ground_truth(system, y0, 0.1, 8)
    o = it.observe(system, y0, gt.times)
    assert o.system is system
    scale = np.max(np.abs(gt.states))
    for j in range(2):  # same reason as for the rigid body: a few roundings apart
        assert np.max(np.abs(o.states[j] - gt.states[j])) <= 8 * EPS * scale


def test_the_same_seed_reproduces_exactly():
    T = it.uneven_times(6, 15, seed=3)
    a = it.observe(BODY, Y0S[:1].repeat(6, 0), T, noise=0.05, drop=0.3, seed=4)
    b = it.observe(BODY, Y0S[:1].repeat(6, 0), T, noise=0.05, drop=0.3, seed=4)
    assert _as_set(a) == _as_set(b) and [t.size for t in a.times] == [t.size for t in b.times]
    c = it.observe(BODY, Y0S[:1].repeat(6, 0), T, noise=0.05, drop=0.3, seed=5)
    assert [t.tobytes() for t in c.times] != [t.tobytes() for t in a.times]
    assert not np.array_equal(c.states[0][0], a.states[0][0])  # other noise on the first state


def test_drops_and_noise_are_independent_streams():
    T = it.uneven_times(8, 30, seed=1)
    y0 = np.random.default_rng(8).normal(size=(8, 3))
    noisy = it.observe(BODY, y0, T, noise=0.1, drop=0.4, seed=2)
    clean = it.observe(BODY, y0, T, noise=0.0, drop=0.4, seed=2)
    other = it.observe(BODY, y0, T, noise=0.3, law="laplace", drop=0.4, seed=2)
    full = it.observe(BODY, y0, T)  # nothing dropped, no noise
    assert clean.n_observations < full.n_observations  # something was dropped
    for j in range(8):
        # The same kept times whatever the noise...
        assert noisy.times[j].tobytes() == clean.times[j].tobytes() == other.times[j].tobytes()
        # ... and the noise-free call gives the clean states there.
        kept = np.isin(T[j], clean.times[j])
        assert kept.sum() == clean.times[j].size
        scale = np.max(np.abs(full.states[j]))
        assert np.max(np.abs(clean.states[j] - full.states[j][kept])) <= 8 * EPS * scale
        assert not np.array_equal(noisy.states[j], clean.states[j])


# Sample kurtosis E[e^4]/E[e^2]^2 and P(|e| < std) of each law.
KURTOSIS = {"gaussian": 3.0, "uniform": 9 / 5, "laplace": 6.0}
WITHIN_ONE_STD = {"gaussian": 0.6826894921370859, "uniform": 1 / np.sqrt(3.0), "laplace": 1 - np.exp(-np.sqrt(2.0))}


@pytest.mark.parametrize("law", sorted(KURTOSIS))
def test_noise_has_the_asked_size_and_law(law):
    T = it.uneven_times(50, 101, seed=1)
    y0 = np.random.default_rng(9).normal(size=(50, 3))
    clean = it.observe(BODY, y0, T, seed=3)
    noisy = it.observe(BODY, y0, T, noise=0.05, law=law, seed=3)
    std = 0.05 * clean.rms_size()
    assert noisy.metadata["noise_std"] == pytest.approx(std, rel=1e-14)
    assert noisy.metadata["law"] == law and noisy.metadata["noise"] == 0.05
    e = np.concatenate([y - c for y, c in zip(noisy.states, clean.states)]) / std  # (N/3, 3), unit std
    n = e.size  # 50 * 101 * 3 = 15150 samples
    # Sample std: relative standard error sqrt((kurtosis - 1) / (4 n)) (0.4 % to 0.9 % here); a
    # 5-sigma band. A wrong scale (e.g. Laplace with scale 1, uniform on [-1, 1]) is off by
    # 40 % or more. Each component alone: n / 3 samples.
    sigma = np.sqrt((KURTOSIS[law] - 1) / (4 * n))
    assert abs(np.std(e) - 1) <= 5 * sigma
    assert np.all(np.abs(np.std(e, axis=0) - 1) <= 5 * np.sqrt(3) * sigma)
    assert abs(np.mean(e)) <= 5 / np.sqrt(n)  # the mean has standard error 1 / sqrt(n)
    # The shape of the law: P(|e| < 1) is 0.577 (uniform), 0.683 (gaussian), 0.757 (laplace),
    # estimated with standard error <= sqrt(0.25 / n) = 0.004; 5 sigma keeps them apart.
    assert abs(np.mean(np.abs(e) < 1) - WITHIN_ONE_STD[law]) <= 5 * np.sqrt(0.25 / n)
    if law == "uniform":
        assert np.max(np.abs(e)) <= np.sqrt(3.0) * (1 + 1e-9)


@pytest.mark.parametrize("law", [it.GaussianNoise(), it.UniformNoise(), it.LaplaceNoise()], ids=repr)
def test_a_noise_law_is_a_class_and_its_name(law):
    """Each law alone draws unit standard deviation with its own shape (the 5-sigma bands of
    `test_noise_has_the_asked_size_and_law`), and `observe` with the instance is `observe` with
    its name, to the bit."""
    e = law.sample(np.random.default_rng(0), (40_000,))
    n = e.size
    assert abs(np.std(e) - 1) <= 5 * np.sqrt((KURTOSIS[law.name] - 1) / (4 * n))
    assert abs(np.mean(np.abs(e) < 1) - WITHIN_ONE_STD[law.name]) <= 5 * np.sqrt(0.25 / n)
    assert it.NOISE_LAWS[law.name] == law
    T = it.uneven_times(3, 6, seed=1)
    y0 = np.random.default_rng(2).normal(size=(3, 3))
    by_class = it.observe(BODY, y0, T, noise=0.1, law=law, seed=4)
    by_name = it.observe(BODY, y0, T, noise=0.1, law=law.name, seed=4)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(by_class.states, by_name.states))
    assert by_class.metadata == by_name.metadata


def test_a_noise_law_of_your_own():
    class Rademacher(it.AbstractNoiseLaw):
        name = "rademacher"

        def sample(self, rng, shape):
            return rng.choice([-1.0, 1.0], size=shape)

    T = it.uneven_times(4, 8, seed=1)
    y0 = np.random.default_rng(3).normal(size=(4, 3))
    clean = it.observe(BODY, y0, T, seed=5)
    noisy = it.observe(BODY, y0, T, noise=0.1, law=Rademacher(), seed=5)
    std = noisy.metadata["noise_std"]
    e = np.concatenate([y - c for y, c in zip(noisy.states, clean.states)]) / std
    np.testing.assert_allclose(np.abs(e), 1.0, rtol=1e-9)  # round-off of y + std e - y, relative to |y| / std
    assert noisy.metadata["law"] == "rademacher"


def test_first_and_last_observations_are_never_dropped():
    T = it.uneven_times(20, 12, seed=2)
    y0 = np.random.default_rng(10).normal(size=(20, 3))
    for seed in range(3):
        o = it.observe(BODY, y0, T, drop=0.95, seed=seed)
        for j in range(20):
            assert o.times[j][0] == T[j, 0] and o.times[j][-1] == T[j, -1]
            assert np.all(np.isin(o.times[j], T[j]))
            np.testing.assert_array_equal(o.states[j][0], y0[j])
    # Nearly everything inside is dropped with drop=0.95: 20 * 10 interior times, 5 % kept.
    assert o.n_observations < 40 + 30


def test_drop_rate():
    T = it.uneven_times(50, 101, seed=4)
    y0 = np.random.default_rng(11).normal(size=(50, 3))
    o = it.observe(BODY, y0, T, drop=0.3, seed=6)
    interior = 50 * 99
    dropped = (50 * 101 - o.n_observations) / interior
    # Binomial: standard error sqrt(0.3 * 0.7 / 4950) = 0.0065; a 5-sigma band.
    assert abs(dropped - 0.3) <= 5 * np.sqrt(0.21 / interior)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"noise": -0.1}, ValueError, r"noise must be a finite number >= 0.*got -0.1"),
        ({"noise": np.nan}, ValueError, r"noise must be a finite number >= 0.*got nan"),
        ({"noise": np.inf}, ValueError, r"noise must be a finite number >= 0.*got inf"),
        ({"law": "normal"}, ValueError, r"law must be one of \('gaussian', 'uniform', 'laplace'\) or an integrators.AbstractNoiseLaw; got 'normal'"),
        ({"law": "Gaussian"}, ValueError, r"law must be one of .*got 'Gaussian'"),
        ({"drop": -0.1}, ValueError, r"drop must be in \[0, 1\); got -0.1"),
        ({"drop": 1.5}, ValueError, r"drop must be in \[0, 1\); got 1.5"),
        ({"drop": np.nan}, ValueError, r"drop must be in \[0, 1\); got nan"),
        ({"drop": "half"}, TypeError, r"drop must be a number"),
        ({"seed": -1}, ValueError, r"seed must be an integer >= 0"),
        ({"times": [[0.0, 1.0]] * 3}, ValueError, r"times has 3 trajectories and y0 2 initial states"),
        ({"times": [0.0]}, ValueError, r"times\[0\] has 1 time\(s\); a trajectory needs at least two"),
        ({"times": [0.0, 1.0, 0.5]}, ValueError, r"times\[0\] must be strictly increasing.*unsorted"),
        ({"times": [0.0, np.nan]}, ValueError, r"times\[0\] must be finite"),
        ({"system": "RigidBody"}, TypeError, r"system must be an AbstractPoissonSystem; got str"),
        ({"y0": np.ones((2, 4))}, ValueError, r"y0 must have shape \(\.\.\., 3\)"),
    ],
)
def test_bad_observe_arguments(kwargs, error, match):
    args = {"system": BODY, "y0": np.ones((2, 3)), "times": [0.0, 0.5, 1.0]}
    args.update(kwargs)
    system, y0, times = args.pop("system"), args.pop("y0"), args.pop("times")
    with pytest.raises(error, match=match):
        it.observe(system, y0, times, **args)


# -- 5. uneven_times --------------------------------------------------------------------------------
def _check_uneven(T, n_traj, n_obs, lo, hi):
    assert T.shape == (n_traj, n_obs) and T.dtype == np.float64
    np.testing.assert_array_equal(T[:, 0], 0.0)
    dt = np.diff(T, axis=1)
    assert np.all(dt > 0)
    # The steps are drawn in [lo, hi] then summed: differencing the sums rounds by eps * |t|.
    slack = 4 * EPS * np.max(T)
    assert np.all(dt >= lo - slack) and np.all(dt <= hi + slack)


def test_uneven_times():
    T = it.uneven_times(7, 30, steps=(0.05, 0.3), seed=11)
    _check_uneven(T, 7, 30, 0.05, 0.3)
    dt = np.diff(T, axis=1)
    assert np.ptp(dt) > 0.1  # really uneven, spread over the range
    assert not np.array_equal(T[0], T[1])  # each trajectory its own times
    np.testing.assert_array_equal(it.uneven_times(7, 30, steps=(0.05, 0.3), seed=11), T)
    assert not np.array_equal(it.uneven_times(7, 30, steps=(0.05, 0.3), seed=12), T)
    _check_uneven(it.uneven_times(3, 4), 3, 4, 0.05, 0.3)  # the defaults
    # low == high: a regular grid.
    R = it.uneven_times(4, 10, steps=(0.2, 0.2), seed=0)
    _check_uneven(R, 4, 10, 0.2, 0.2)
    assert it.Observations(BODY, R, np.zeros((4, 10, 3))).is_regular()


@given(n_traj=st.integers(1, 5), n_obs=st.integers(2, 20), lo=st.floats(1e-3, 10.0),
       ratio=st.floats(1.0, 100.0), seed=st.integers(0, 2**32))
def test_uneven_times_properties(n_traj, n_obs, lo, ratio, seed):
    T = it.uneven_times(n_traj, n_obs, steps=(lo, lo * ratio), seed=seed)
    _check_uneven(T, n_traj, n_obs, lo, lo * ratio)
    np.testing.assert_array_equal(T, it.uneven_times(n_traj, n_obs, steps=(lo, lo * ratio), seed=seed))


@pytest.mark.parametrize(
    ("args", "kwargs", "error", "match"),
    [
        ((0, 5), {}, ValueError, r"n_trajectories must be an integer >= 1; got 0"),
        ((1.5, 5), {}, TypeError, r"n_trajectories must be an integer"),
        ((2, 1), {}, ValueError, r"n_observations must be an integer >= 2; got 1"),
        ((2, 5), {"steps": (0.3, 0.1)}, ValueError, r"low <= high"),
        ((2, 5), {"steps": (0.0, 0.1)}, ValueError, r"steps\[0\] must be finite and > 0"),
        ((2, 5), {"steps": (0.1, np.inf)}, ValueError, r"steps\[1\] must be finite and > 0"),
        ((2, 5), {"steps": (-0.1, 0.1)}, ValueError, r"steps\[0\] must be finite and > 0"),
        ((2, 5), {"steps": (0.1,)}, TypeError, r"steps must be \(low, high\)"),
        ((2, 5), {"steps": 0.1}, TypeError, r"steps must be \(low, high\)"),
        ((2, 5), {"seed": -1}, ValueError, r"seed must be an integer >= 0"),
    ],
)
def test_bad_uneven_times_arguments(args, kwargs, error, match):
    with pytest.raises(error, match=match):
        it.uneven_times(*args, **kwargs)


# -- 6. split -------------------------------------------------------------------------------------
@pytest.fixture
def ten():
    """Ten trajectories of lengths 2..11, so each is known by its length."""
    rng = np.random.default_rng(12)
    return it.Observations(BODY, [np.cumsum(rng.uniform(0.1, 0.2, n)) for n in range(2, 12)],
                           [rng.normal(size=(n, 3)) for n in range(2, 12)], metadata={"k": 1})


def test_split_by_whole_trajectories(ten):
    train, val = ten.split(0.3, seed=1)
    assert (train.n_trajectories, val.n_trajectories) == (7, 3)
    assert train.metadata == val.metadata == ten.metadata and train.system is val.system is BODY
    originals = {t.size: (t, y) for t, y in zip(ten.times, ten.states)}
    lengths = []
    for part in (train, val):
        for t, y in zip(part.times, part.states):  # each piece is a whole original trajectory
            t0, y0 = originals[t.size]
            assert t.tobytes() == t0.tobytes() and y.tobytes() == y0.tobytes()
            lengths.append(t.size)
    # Disjoint, and together everything: each original exactly once.
    assert sorted(lengths) == list(range(2, 12))
    assert train.n_observations + val.n_observations == ten.n_observations
    # Seeded: the same seed gives the same split; the seeds do not all give the same one.
    again_train, again_val = ten.split(0.3, seed=1)
    assert _as_set(again_train) == _as_set(train) and _as_set(again_val) == _as_set(val)
    splits = {tuple(sorted(t.size for t in ten.split(0.3, seed=s)[1].times)) for s in range(6)}
    assert len(splits) > 1


def test_split_edge_cases(ten):
    train, val = ten.split(0.0)
    assert val is None and _as_set(train) == _as_set(ten)
    with pytest.raises(ValueError, match=r"validation_fraction=0.97 leaves no training trajectory out of 10"):
        ten.split(0.97)
    with pytest.raises(ValueError, match=r"validation_fraction must be in \[0, 1\)"):
        ten.split(1.0)
    with pytest.raises(ValueError, match=r"seed must be an integer >= 0"):
        ten.split(0.3, seed=-2)
