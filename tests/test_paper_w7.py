"""W7, bodies in air (`paper/w7_air.py`): its protocol (drag takes angular momentum, the
gyroscope's bias is one per session), its flip period on a closed form, and the study end to
end at the smoke profile."""

import json

import numpy as np
import pytest

from paper import w7_air


def test_flip_times_are_the_zeros_of_a_sine_to_the_interpolation_error():
    # sin(pi t / T) changes sign at t = T, 2T, ...; linear interpolation between samples 0.01
    # apart errs by at most h^2/8 |f''| / |f'| = (pi/T) h^2 / 8 at a zero
    T, times = 0.23, 0.01 * np.arange(101)
    flips = w7_air.flip_times(times, np.sin(np.pi * times / T))
    np.testing.assert_allclose(flips, T * np.arange(1, 5), rtol=0, atol=np.pi / T * 0.01**2 / 8)
    assert w7_air.flip_period(times, np.sin(np.pi * times / T)) == pytest.approx(T, abs=1e-4)
    assert np.isnan(w7_air.flip_period(times, np.cos(np.pi * times / 3.0)))  # one flip: no period


def test_sessions_lose_angular_momentum_to_the_air_and_share_one_bias():
    train = w7_air.session(12, w7_air.TRAIN_SPINS, 0.02, w7_air.DATA_SEED)
    L = np.linalg.norm(train.rates * np.asarray(w7_air.INERTIA), axis=-1)
    lost = 1.0 - L[:, -1] / L[:, 0]
    # the real flights: ~15% of |L| per 1-s flight at the training spins
    assert 0.1 < np.mean(lost) < 0.2 and np.all(np.diff(L, axis=1) < 0)
    # the gyroscope: the truth plus noise of the given size plus one constant bias per session
    error = train.measured - train.rates
    np.testing.assert_allclose(error.mean(axis=(0, 1)), train.bias, atol=5 * 0.02 / np.sqrt(error[..., 0].size))
    assert np.std(error - train.bias) == pytest.approx(0.02, rel=0.05)
    test = w7_air.session(12, w7_air.TEST_SPINS, 0.02, w7_air.TEST_SEED)
    assert not np.allclose(test.bias, train.bias)
    # twice as fast: the spins about the intermediate axis
    assert np.median(np.abs(test.rates[:, 0, 1])) > 1.5 * np.median(np.abs(train.rates[:, 0, 1]))


@pytest.mark.slow  # every model of W7 fitted on 3 short flights: ~2-3 min on 2 busy cores
def test_w7_smoke_fits_every_model_and_resumes(tmp_path):
    from paper.__main__ import main

    args = ["run", "W7", "--profile", "smoke", "--no-progress", "--out", str(tmp_path)]
    assert main(args) == 0
    metrics = json.loads((tmp_path / "W7" / "metrics.json").read_text())
    rows = {r["model"]: r for r in metrics["rows"]}
    assert {"dissipative G-LPNet", "conservative G-LPNet", "LPNet", "limit", "Euler, no drag"} <= set(rows)
    for r in rows.values():
        assert np.isfinite(r["fit_seconds"]) and len(r["rate_errors"]) == 2
    # Euler's row is the truth's inertia; the limit, started 10% off, finds the ratios again
    true = np.array(w7_air.INERTIA) / w7_air.INERTIA[1]
    np.testing.assert_allclose(rows["Euler, no drag"]["inertia_ratios"], true, rtol=1e-12)
    np.testing.assert_allclose(rows["limit"]["inertia_ratios"], true, rtol=0.05)
    # the learned dissipative map found a drag (positive semidefinite: its diagonal >= 0)
    assert np.all(np.diag(rows["dissipative G-LPNet"]["drag_rate"]) >= 0.0)
    assert any("dissipative G-LPNet rate error" in v for v in metrics["verdict"])
    assert any(v.startswith("every fit") for v in metrics["verdict"])
    table = (tmp_path / "W7" / "table.md").read_text()
    assert table.startswith("# W7") and "| LPNet |" in table
    assert (tmp_path / "W7" / "test_flight_noise_0.02.png").stat().st_size > 0
    # rows are saved as they are measured: a second run reads them all back
    assert main(args) == 0
    again = json.loads((tmp_path / "W7" / "metrics.json").read_text())
    assert again["resumed_rows"] == len(metrics["rows"])
