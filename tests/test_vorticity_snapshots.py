"""integrators.read_vorticity_snapshots, write_vorticity_snapshots, add_field_noise."""

import tracemalloc

import h5py
import jax
import numpy as np
import pytest

from integrators import (
    Observations,
    add_field_noise,
    read_vorticity_snapshots,
    write_vorticity_snapshots,
)
from liepoisson.systems import Zeitlin

EPS = np.finfo(np.float64).eps


def _fields(N, n, seed):
    system = Zeitlin(N)
    rng = np.random.default_rng(seed)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.1, 0.5, n - 1))])  # uneven
    states = np.stack([system.random_state(seed * 100 + k) for k in range(n)])
    return system, times, states


def test_matrices_and_harmonics_round_trip(tmp_path):
    system, times, states = _fields(8, 5, 1)
    matrices = np.asarray(system.algebra.matrix(states))
    harmonics = np.stack([system.harmonics(y) for y in states])
    write_vorticity_snapshots(tmp_path / "a.h5", times, matrices)
    write_vorticity_snapshots(tmp_path / "b.h5", times[:4] + 1.0, harmonics[:4])
    data = read_vorticity_snapshots([tmp_path / "a.h5", tmp_path / "b.h5"])
    assert isinstance(data, Observations) and data.system == system
    assert data.n_trajectories == 2
    np.testing.assert_array_equal(data.times[0], times)
    np.testing.assert_array_equal(data.times[1], times[:4] + 1.0)
    # matrices: one gather of exact entries (u(N)'s dual coefficients, gain 1 to the last bit)
    assert np.max(np.abs(data.states[0] - states)) <= 4 * EPS * np.max(np.abs(states))
    # harmonics: two transforms by bases scaled by sqrt(N), a few eps each, times N
    assert np.max(np.abs(data.states[1] - states[:4])) <= 16 * 8 * EPS * np.max(np.abs(states))
    # |y| is the Frobenius norm of W (the basis is orthonormal for Re tr(A^dagger B))
    assert abs(np.linalg.norm(data.states[0][0]) - np.linalg.norm(matrices[0])) <= 8 * EPS * np.linalg.norm(
        matrices[0])


def test_bad_files(tmp_path):
    system, times, states = _fields(4, 3, 2)
    matrices = np.asarray(system.algebra.matrix(states))
    write_vorticity_snapshots(tmp_path / "n4.h5", times, matrices)
    _, t6, s6 = _fields(6, 3, 3)
    write_vorticity_snapshots(tmp_path / "n6.h5", t6, np.asarray(Zeitlin(6).algebra.matrix(s6)))
    with pytest.raises(ValueError, match=r"holds fields of N = 6; the system is Zeitlin\(N=4\)|holds fields of N = 6"):
        read_vorticity_snapshots([tmp_path / "n4.h5", tmp_path / "n6.h5"])
    with pytest.raises(ValueError, match="holds fields of N = 4"):
        read_vorticity_snapshots(tmp_path / "n4.h5", system=Zeitlin(5))
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.create_dataset("t", data=times)
    with pytest.raises(ValueError, match="is not a vorticity snapshot file"):
        read_vorticity_snapshots(tmp_path / "other.h5")
    bad = matrices.copy()
    bad[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match="fields must be finite"):
        write_vorticity_snapshots(tmp_path / "bad.h5", times, bad)
    with pytest.raises(ValueError, match="fields must be skew-Hermitian"):
        write_vorticity_snapshots(tmp_path / "bad.h5", times, np.abs(matrices))
    with pytest.raises(ValueError, match="times has 2 entries and fields 3 snapshots"):
        write_vorticity_snapshots(tmp_path / "bad.h5", times[:2], matrices)
    with pytest.raises(ValueError, match=r"times must be strictly increasing"):
        write_vorticity_snapshots(tmp_path / "bad.h5", times[::-1], matrices)
    with h5py.File(tmp_path / "nan.h5", "w") as f:  # a damaged file: a non-finite snapshot
        f.create_dataset("t", data=times)
        f.create_dataset("vorticity", data=np.where(np.arange(3)[:, None, None] == 2, np.nan, matrices))
        f.attrs["format"] = "liepoisson-vorticity-snapshots"
    with pytest.raises(ValueError, match=r"snapshot 2 .* is not finite"):
        read_vorticity_snapshots(tmp_path / "nan.h5")
    with pytest.raises(TypeError, match="system must be liepoisson.systems.Zeitlin"):
        read_vorticity_snapshots(tmp_path / "n4.h5", system="Zeitlin")


def test_field_noise_is_relative_to_the_rms_component():
    system, times, states = _fields(16, 11, 4)
    data = Observations(system, times, states)
    noisy = add_field_noise(data, 1e-3, seed=5)
    difference = noisy.states[0] - states
    rms = np.sqrt(np.mean(states**2))
    # 11 x 256 draws: the sample standard deviation is within 5 of its standard errors
    # (1/sqrt(2 x 2816) = 1.3%) of the asked 1e-3 of the rms component
    assert abs(np.std(difference) / (1e-3 * rms) - 1) <= 5 / np.sqrt(2 * difference.size)
    assert noisy.metadata["noise_std"] == pytest.approx(1e-3 * rms, rel=1e-14)
    # the noise's norm is about 1e-3 of the field's, whatever the dimension
    ratio = np.linalg.norm(difference) / np.linalg.norm(states)
    assert 0.9e-3 <= ratio <= 1.1e-3
    assert np.array_equal(add_field_noise(data, 0.0).states[0], states)
    with pytest.raises(ValueError, match="noise must be a finite number >= 0"):
        add_field_noise(data, -1.0)
    with pytest.raises(TypeError, match="data must be integrators.Observations"):
        add_field_noise(states, 1e-3)


def test_reading_n64_forms_nothing_of_dimension_squared(tmp_path):
    N = 64
    dim = N * N
    system, times, states = _fields(N, 4, 6)
    harmonics = np.stack([system.harmonics(y) for y in states])
    write_vorticity_snapshots(tmp_path / "h.h5", times, harmonics)
    write_vorticity_snapshots(tmp_path / "w.h5", times, np.asarray(system.algebra.matrix(states)))
    read_vorticity_snapshots([tmp_path / "h.h5", tmp_path / "w.h5"], system=system)  # compile and cache
    tracemalloc.start()
    try:
        data = read_vorticity_snapshots([tmp_path / "h.h5", tmp_path / "w.h5"], system=system)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert np.max(np.abs(data.states[1] - states)) <= 4 * EPS * np.max(np.abs(states))
    # one (dim, dim) float64 array would be 128 MiB; the data are 2 x 4 x 4096 floats (256 KiB)
    assert peak < 8 * dim * dim / 16, peak
    # the conversion to coordinates (JAX, not seen by tracemalloc) is a gather of N x N entries:
    # no intermediate of its program has dim^2 elements
    jaxpr = jax.make_jaxpr(system.algebra.coordinates)(np.asarray(system.algebra.matrix(states[0])))
    sizes = [int(np.prod(v.aval.shape)) for eqn in jaxpr.eqns for v in eqn.outvars]
    assert max(sizes) < dim * dim / 16, max(sizes)
