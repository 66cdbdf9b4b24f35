"""W8's DMD peers (paper._dmd): on an exactly linear system, exact DMD (even clock) and optimised
DMD (uneven clock) recover its eigenvalues, and the rank rule, which sees only the training
trajectories, picks a rank that holds them."""

import numpy as np
import pytest
import scipy.linalg as sl

pytest.importorskip("pydmd")

from paper import _dmd

#: A damped linear system of dimension 6: two rotations and two decays.
EIGENVALUES = np.array([-0.05 + 1.0j, -0.05 - 1.0j, -0.2 + 2.5j, -0.2 - 2.5j, -0.1, -0.6])


def _trajectories(clock, n=10, trajectories=3, seed=0):
    """x' = A x in a random basis, embedded in `n` dimensions (rank 6), from random starts."""
    rng = np.random.default_rng(seed)
    B = sl.block_diag([[-0.05, 1.0], [-1.0, -0.05]], [[-0.2, 2.5], [-2.5, -0.2]], [[-0.1]], [[-0.6]])
    Q = rng.normal(size=(6, 6))
    A = Q @ B @ np.linalg.inv(Q)
    P = np.linalg.qr(rng.normal(size=(n, 6)))[0]
    states = [np.stack([P @ sl.expm(A * s) @ x0 for s in clock]) for x0 in rng.normal(size=(trajectories, 6))]
    return [clock] * trajectories, states


def _uneven(m=25, seed=1):
    rng = np.random.default_rng(seed)
    return np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.15, m - 1))])


def _largest_miss(found):
    """How far the farthest true eigenvalue is from the nearest found one."""
    return max(np.min(np.abs(np.asarray(found) - w)) for w in EIGENVALUES)


@pytest.mark.parametrize(("kind", "clock", "tol"), [
    ("exact", 0.1 * np.arange(25), 1e-10),  # exact data at one step: DMD is exact
    ("optimised", _uneven(), 1e-8),  # uneven times: variable projection to VARPRO_OPTIONS' tolerance
])
def test_dmd_recovers_a_linear_systems_eigenvalues_at_the_rank_the_rule_chooses(kind, clock, tol):
    times, states = _trajectories(clock)
    rank, scores = _dmd.chosen_rank(kind, times, states, (2, 4, 6, 8))
    assert rank >= 6, scores  # too few modes cannot hold the six
    assert scores[2] > 1e3 * scores[rank] and scores[4] > 1e3 * scores[rank], scores
    fitted = _dmd.FITS[kind](times, states, rank)
    assert _largest_miss(fitted.eigenvalues) <= tol, fitted.eigenvalues
    # the forecast from a start the fit never saw follows the system
    fresh = _trajectories(clock, trajectories=4, seed=0)[1][-1]  # a fourth start of the same system (same A)
    predicted = fitted.predict(fresh[:1], clock)[0]
    assert np.max(np.linalg.norm(predicted - fresh, axis=-1)) <= 1e3 * tol * np.linalg.norm(fresh[0])


def test_exact_dmd_on_uneven_snapshots_is_as_good_as_its_resampling():
    """Exact DMD resamples uneven snapshots by a cubic spline: the eigenvalues are then found to
    the spline's accuracy, not to round-off."""
    times, states = _trajectories(_uneven())
    fitted = _dmd.fit_exact_dmd(times, states, 6)
    assert 1e-8 < _largest_miss(fitted.eigenvalues) <= 1e-3


def test_rank_rule_refuses_what_it_cannot_fit():
    times, states = _trajectories(_uneven())
    with pytest.raises(ValueError, match="kind must be one of"):
        _dmd.chosen_rank("sparse", times, states, (2,))
    with pytest.raises(ValueError, match="none of"):
        _dmd.chosen_rank("optimised", times, states, (40,))  # more modes than the held-out fit's snapshots
    with pytest.raises(ValueError, match="one clock"):
        _dmd.fit_optimised_dmd([times[0], times[0] * 1.1, times[0]], states, 6)


def test_an_overflow_in_the_optimised_fit_is_a_rank_it_cannot_fit_not_a_hang(monkeypatch):
    """pydmd's variable projection let a trial eigenvalue grow until $e^{\\omega t}$ overflowed
    (W8, QG F = 100), and LAPACK's least squares on the NaN never returned: the fit now runs
    with overflows raising, and the rank rule scores such a rank inf."""
    import pydmd

    def overflowing(self, X, t):
        return np.exp(np.outer(t, [1e3]))  # what a runaway trial eigenvalue does

    monkeypatch.setattr(pydmd.BOPDMD, "fit", overflowing)
    times, states = _trajectories(_uneven())
    assert _dmd.chosen_rank("optimised", times, states, (2, 4)) == (2, {2: np.inf, 4: np.inf})
    with pytest.raises(FloatingPointError):
        _dmd.fit_optimised_dmd(times, states, 4)
