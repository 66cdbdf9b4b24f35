r"""Dynamic mode decomposition peers (W8): exact DMD (Schmid 2010; Tu et al. 2014) and optimised
DMD (Askham & Kutz 2018, bagging-free: `pydmd.BOPDMD` with `num_trials=0`) from the `pydmd`
package (the `peers` optional extra), fitted to several trajectories, their rank chosen on the
training data only.

Both give a linear model $x(t) = \mathrm{Re}\,\Phi\,e^{\Omega t}\,b$ with continuous-time
eigenvalues $\omega_k$ and modes $\Phi$ `(n, r)`; a forecast from a field $x_0$ takes
$b = \Phi^+ x_0$ (least squares).

- **Exact DMD** needs snapshots at one step: every training trajectory is resampled onto an
  even grid of the data's median interval by a cubic spline in time (scipy's
  `CubicSpline`, per component), the pairs of consecutive resampled snapshots of every
  trajectory are stacked (`pydmd.DMD.fit(X, Y)`), and $\omega = \log\lambda/\Delta t$.
- **Optimised DMD** fits the uneven times themselves (eigenvalues stable:
  `EIG_CONSTRAINTS`), but one trajectory at a time: the
  trajectories must share their clock, and are stacked as one state `(J n, m)`, so that
  every trajectory $x_j(t) = \Phi\,e^{\Omega t}b_j$ shares $\Omega$ and the stacked modes are
  $\Phi\,\mathrm{diag}(b_j)$ per block; $\Phi$'s column $k$ is the leading left singular
  vector of the $J$ blocks' columns $k$ `(n, J)`.

The rank rule (`chosen_rank`): for each candidate rank, fit on every training trajectory but
its last `HELD_OUT_FRACTION` of snapshots, forecast those from the trajectory's first snapshot,
and keep the rank of the smallest mean relative error (ties: the smaller rank); then refit on
every snapshot. The test data are never seen.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence

import numpy as np

#: Variable projection's settings of the optimised DMD: pydmd's default tolerance (1e-6) stops
#: it 4e-3 off the eigenvalues of an exactly linear system (tests/test_dmd_peers.py); at these
#: it finds them to 2e-9.
VARPRO_OPTIONS = {"tol": 1e-12, "maxiter": 200}
#: The optimised DMD's eigenvalues: stable (real parts <= 0; pydmd's constraint for data that do
#: not grow: W8's flows keep their enstrophy). Unconstrained, on W8's slow QG F = 100 fields (which
#: move little over the data) a trial step's eigenvalue grew until $e^{\omega t}$
#: overflowed, and LAPACK's least squares on the NaN that followed never returned. (Conjugate
#: pairs as well would lose a real system's single real eigenvalues: tests/test_dmd_peers.py.)
EIG_CONSTRAINTS = frozenset({"stable"})
#: The share of every training trajectory's snapshots (its last ones) the rank rule holds out.
HELD_OUT_FRACTION = 1 / 3


def pydmd_missing() -> str | None:
    """Why the DMD peers cannot run (`None`: `pydmd` is installed)."""
    try:
        import pydmd  # noqa: F401
    except ImportError:
        return "pydmd is not installed (pip install 'liepoisson[peers]')"
    return None


@dataclasses.dataclass(frozen=True)
class LinearModes:
    r"""$x(t) = \mathrm{Re}\,\Phi\,e^{\Omega t}\,b$: continuous-time `eigenvalues` $\omega$ `(r,)`,
    `modes` $\Phi$ `(n, r)`; `rank` the SVD rank it was fitted at; `warnings` how many
    warnings pydmd raised while fitting it (convergence notes), recorded, not raised."""

    eigenvalues: np.ndarray
    modes: np.ndarray
    rank: int
    warnings: int = 0

    def predict(self, x0: np.ndarray, times: np.ndarray) -> np.ndarray:
        """The states at `times` `(m,)` (from 0) of the fields `x0` `(k, n)`: `(k, m, n)`."""
        x0 = np.atleast_2d(np.asarray(x0, dtype=np.float64))
        b, *_ = np.linalg.lstsq(self.modes, x0.T.astype(np.complex128), rcond=None)  # (r, k)
        growth = np.exp(np.outer(np.asarray(times, dtype=np.float64), self.eigenvalues))  # (m, r)
        with np.errstate(over="ignore", invalid="ignore"):
            out = np.einsum("nr,mr,rk->kmn", self.modes, growth, b)
        return np.real(out)


def _check(times: Sequence[np.ndarray], states: Sequence[np.ndarray]) -> None:
    if len(times) != len(states) or not times:
        raise ValueError(f"times and states must give the same number (>= 1) of trajectories; got {len(times)} and "
                         f"{len(states)}")
    for j, (t, y) in enumerate(zip(times, states)):
        if np.ndim(t) != 1 or np.ndim(y) != 2 or len(t) != len(y) or len(t) < 3:
            raise ValueError(f"trajectory {j}: times (m,) and states (m, n) with m >= 3 expected; got shapes "
                             f"{np.shape(t)} and {np.shape(y)}")


def fit_exact_dmd(times: Sequence[np.ndarray], states: Sequence[np.ndarray], rank: int) -> LinearModes:
    """Exact DMD (`pydmd.DMD(svd_rank=rank, exact=True)`) of the trajectories resampled onto an
    even grid of their median interval (module docstring)."""
    from pydmd import DMD
    from scipy.interpolate import CubicSpline

    _check(times, states)
    dt = float(np.median(np.concatenate([np.diff(t) for t in times])))
    X, Y = [], []
    for t, y in zip(times, states):
        t = np.asarray(t, dtype=np.float64)
        grid = t[0] + dt * np.arange(math.floor((t[-1] - t[0]) / dt + 1e-9) + 1)
        even = CubicSpline(t, np.asarray(y), axis=0)(grid)
        X.append(even[:-1])
        Y.append(even[1:])
    X, Y = np.concatenate(X).T, np.concatenate(Y).T
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dmd = DMD(svd_rank=rank, exact=True).fit(X, Y)
    eigs = np.asarray(dmd.eigs, dtype=np.complex128)
    with np.errstate(divide="ignore"):
        omega = np.log(eigs) / dt
    return LinearModes(omega, np.asarray(dmd.modes, dtype=np.complex128), rank, len(caught))


def fit_optimised_dmd(times: Sequence[np.ndarray], states: Sequence[np.ndarray], rank: int) -> LinearModes:
    """Optimised DMD (`pydmd.BOPDMD(svd_rank=rank)`, variable projection, no bagging) of the
    trajectories stacked on their shared clock (module docstring)."""
    from pydmd import BOPDMD

    _check(times, states)
    t = np.asarray(times[0], dtype=np.float64)
    if any(len(s) != len(t) or not np.allclose(s, t, rtol=0, atol=1e-12 * max(1.0, abs(t[-1]))) for s in times):
        raise ValueError("optimised DMD fits trajectories sampled on one clock: every trajectory's times must be the "
                         "same")
    n, J = states[0].shape[1], len(states)
    stacked = np.concatenate([np.asarray(y).T for y in states])  # (J n, m)
    # an overflow or a NaN in pydmd's arithmetic raises (FloatingPointError: a rank the solver
    # cannot fit) instead of reaching LAPACK, whose least squares on a NaN can hang
    with warnings.catch_warnings(record=True) as caught, np.errstate(over="raise", invalid="raise",
                                                                     divide="raise"):
        warnings.simplefilter("always")
        dmd = BOPDMD(svd_rank=rank, varpro_opts_dict=dict(VARPRO_OPTIONS),
                     eig_constraints=set(EIG_CONSTRAINTS)).fit(stacked, t - t[0])
    blocks = np.asarray(dmd.modes, dtype=np.complex128).reshape(J, n, -1)
    modes = np.empty((n, blocks.shape[-1]), dtype=np.complex128)
    for k in range(blocks.shape[-1]):
        u, _, _ = np.linalg.svd(blocks[:, :, k].T, full_matrices=False)
        modes[:, k] = u[:, 0]
    return LinearModes(np.asarray(dmd.eigs, dtype=np.complex128), modes, rank, len(caught))


FITS = {"exact": fit_exact_dmd, "optimised": fit_optimised_dmd}


def forecast_error(fitted: LinearModes, times: Sequence[np.ndarray], states: Sequence[np.ndarray],
                   first: Sequence[int] | None = None) -> float:
    """The mean over trajectories and their snapshots from index `first[j]` on (default 1) of
    the relative error $|x - \\hat x|/|x_0|$ of `fitted` forecast from each trajectory's first
    snapshot (inf if not finite)."""
    errors = []
    for j, (t, y) in enumerate(zip(times, states)):
        y = np.asarray(y)
        k = 1 if first is None else first[j]
        pred = fitted.predict(y[:1], np.asarray(t) - t[0])[0]
        errors.append(np.linalg.norm(pred[k:] - y[k:], axis=-1) / np.linalg.norm(y[0]))
    value = float(np.mean(np.concatenate(errors)))
    return value if np.isfinite(value) else math.inf


def chosen_rank(kind: str, times: Sequence[np.ndarray], states: Sequence[np.ndarray],
                ranks: Sequence[int]) -> tuple[int, dict[int, float]]:
    """The rank of `ranks` whose `kind` ("exact", "optimised") DMD, fitted to every trajectory
    but its last `HELD_OUT_FRACTION` of snapshots, forecasts those best from the trajectory's
    first snapshot; and every candidate's score (module docstring). Ranks beyond what the
    shortened data hold are skipped."""
    if kind not in FITS:
        raise ValueError(f"kind must be one of {sorted(FITS)}; got {kind!r}")
    _check(times, states)
    keep = [max(3, len(t) - max(1, round(HELD_OUT_FRACTION * len(t)))) for t in times]
    early_t = [np.asarray(t)[:k] for t, k in zip(times, keep)]
    early_y = [np.asarray(y)[:k] for y, k in zip(states, keep)]
    limit = min(min(keep), states[0].shape[1]) if kind == "optimised" else states[0].shape[1]
    scores = {}
    for r in sorted({int(r) for r in ranks}):
        if not 1 <= r <= limit:
            continue
        try:
            fitted = FITS[kind](early_t, early_y, r)
            scores[r] = forecast_error(fitted, times, states, keep)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):  # a rank the solver cannot fit: not chosen
            scores[r] = math.inf
    if not scores:
        raise ValueError(f"ranks: none of {list(ranks)} is between 1 and {limit} (what the held-out fits allow)")
    return min(scores, key=lambda r: (scores[r], r)), scores
