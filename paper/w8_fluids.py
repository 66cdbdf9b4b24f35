r"""W8 (beyond the paper): fluids from data. A vorticity field on the sphere (Zeitlin's model,
u(N), dimension $N^2$) whose stream operator is unknown, observed noisily at uneven times through
snapshot files; models learn it and forecast fields they never saw.

**Truths** (each `Truth`): Euler's equations (the Laplacian's spectrum $-l(l+1)$),
quasi-geostrophic flow $L = \Delta - F$ with $F = 10$ and $F = 100$, and Euler's equations on
a sphere turning at $\Omega = 1$ (absolute vorticity $q = W + \Omega f$,
`learn.StreamOperator`'s rotation). Each is `learn.StreamOperator` at its true parameters,
rolled out with `fine` equal steps per interval (stage tolerance 1e-13).

**Data**: `n_train` random fields (`Zeitlin.random_state`, every degree 1..N - 1, decay 0.5: about
the same enstrophy in each degree, so that the data say something of every eigenvalue; with
degrees <= 20 only, a probe at N = 64 left degrees 21..63 unidentified and the fit's trial steps
broke down there; unit $L^2$ norm of the harmonic coefficients: rms vorticity 1), each observed at `snapshots`
times of one uneven clock (intervals uniform in $[0.5, 1.5]\,\Delta$, $\Delta$ =
`interval` eddy turnovers), with Gaussian noise of `noise` times the field's rms component
(`integrators.add_field_noise`), written to snapshot files (`integrators.write_vorticity_snapshots`,
one per trajectory, under `<out>/W8/snapshots/`) and read back
(`integrators.read_vorticity_snapshots`): the models see only what was read.

**Eddy turnover time** $\tau = 1/\omega_{rms}$, $\omega_{rms}^2 = 2Z/|S^2|$ the mean of
$\omega^2$ over the sphere ($Z = \tfrac12\int\omega^2$ the enstrophy, a Casimir: the same at every
time) of the true test fields at $t = 0$; with unit harmonic norm $\omega_{rms} = 1$, $\tau = 1$.
At $\tau$ the fields have moved about a tenth of their norm, at $5\tau$ about a half.

**Models** (each an `AbstractFluidModel`):
- *learned stream operator*: `learn.StreamOperator` with a spectrum per degree
  (`learn.DegreeSpectrum`, started at the Laplacian's) and, on the rotating truth, a rotation
  (started at 0), fitted by `learn.fit_stream_operator` (trajectory least squares, one fitted
  start per trajectory, standard errors). The gauge (the spectrum is known up to a constant
  added to every $1/\lambda_l$: the enstrophy Casimir) is held at the highest degree $N - 1$,
  at the Laplacian's $-(N-1)N$: the truths' spectra then differ from the start's gauge by
  $F/((N-1)N)^2$-small shifts. Held at degree 1 (the library's default), the QG F = 10 truth
  needs a shift of $1/2 - 1/12$ of $1/\lambda$, a stream dominated by the Casimir term, which
  the midpoint breaks at $O(h^2)$: at N = 8 that fit stopped at a loss 4e4 times the noise's.
  On a rotating sphere the gauge is no symmetry: adding $\kappa$ to every $1/\lambda_l$ adds
  $\kappa\Omega[W, f]$, a turning of the field about the axis, to the flow, so the data fix
  every eigenvalue and $\Omega$; the rotating truth's Laplacian has the held value, and the fit
  is compared with the truth itself.
- *limit*: the true family fitted by the same trajectory least squares: the QG family
  (`learn.QuasiGeostrophicSpectrum`, one parameter $F$ from 0) for Euler (its $F = 0$ member)
  and the QG truths; for the rotating truth the Laplacian with only the rotation learned
  (`LaplacianSpectrum`, no spectral parameter; rotation from 0).
- *DMD* and *optimised DMD* (`paper._dmd`, pydmd; rows skipped, with the reason, without it):
  rank chosen among `dmd_ranks` by forecasting the training trajectories' last third from
  their first snapshot (fits on the rest), then refitted on everything.
- The LPNet of W5 is not a row: it learns a map at one step $H$ from pairs of consecutive
  samples at $H$; these snapshots are at uneven times (no two intervals equal), and its
  $\alpha$ affine in $W$ has $N^4 + N^2$ weights (16.8 million at N = 64, 268 million at 128).

**Test**: `n_test` other random fields, their first observation noisy (the same noise rule),
forecast by every model from that noisy field, in steps of $\Delta$ (the stream operators:
each in equal steps of the `composition` of midpoints (`learn.StreamOperator`'s) of at most
`Condition.max_step` (`fit_step` eddy turnovers; on the rotating sphere `fit_step` times
$1/(2\Omega)$ if shorter; above N = 32 shorter by $(N - 1)/31$), as in their fits, where every interval is run in the same number of
steps, the fewest that keep the longest one's at most that), against the truth from the clean field.
A fitted model carries its step's error into its parameters, the more visibly the smaller the
error bars (more data, larger N): hence a higher order and shorter steps in the full profile
than in quick (quick: Suzuki's, 0.15; full: Yoshida6, 0.075; the biases measured in
BENCHMARKS.md, "The step's order"), and in the full profile a fit whose step's estimated bias
is over `max_step_bias` (0.05) standard errors on any parameter is fitted again in half the
step from where it stopped (`_fit`; its standard errors' solves started from the last fit's:
`fit_stream_operator`'s `se_start`), so that no step moves a 3-SE comparison. DMD's modes span
what the training snapshots span (rank at most their number): the part of a test field
outside them is lost at $t = 0$ (its size is in the DMD rows' note).

**Columns**: the field error $\|\hat W - W\|_F/\|W_0\|_F$ at $\tau$ and at $5\tau$ (mean over
the test fields); the energy error $|E(\hat W) - E(W)|/E(W)$ (the truth's energy) and the
enstrophy error (the same with $\tfrac12\|W\|_F^2$) at $5\tau$; the identified parameters
against the truth's in units of their standard errors (the spectrum per degree in the same
gauge, `learn.in_gauge`; the largest over degrees 1..N-2 and the rotation; the row's
parameters say the step's estimated bias in the same units, `learn.StreamOperatorFit.step_bias`,
and the learned rows' the truth's Wald test, every parameter at once with their correlations,
`learn.StreamOperatorFit.wald_test`: with N - 2 degrees one beyond 3 SE is no rare event, and
the largest |error|/SE less the step's bias, what shorter steps would give to first order; each
in rows fitted since it was added); the Casimir drift
$\max_k|\sum_i e_i^k(t) - \sum_i e_i^k(0)|/\sum_i|e_i(0)|^k$, $e_i$ the eigenvalues of
$iq$, $q = W + \Omega f$ the absolute vorticity (on the rotating truth, $\Omega$ the model's own
fitted rotation, the truth's for DMD; $q = W$ otherwise), $k = 2..4$, over every forecast
step; the fit time and the process's peak memory by its end. A learned row keeps its spectrum
per degree (`W8Row.spectrum`), and `spectrum.png` draws it: each degree's error in standard
errors, with and without the step's bias.

**Fast checks** (a profile's `fast_checks`, with the settings `FAST`): a condition fitted on the
issue's time budget (N = 128, dimension 16,384: under 10 minutes on 2 cores, under 8 GB), with
a smaller protocol: fewer snapshots, one midpoint a step, no standard errors. Their verdict
says the budget, not the spectrum's standard errors; learned and limit share the step's error.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import time
from pathlib import Path
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, save_figure

from . import _dmd
from ._experiment import Column, Profile, fmt, optional, profiles
from ._runner import AbstractStudy
from ._study import AbstractStudyModel

TRUTH_TOL = 1e-13  # the truth's stage tolerance
MODEL_TOL = 1e-12  # the learned models' stage tolerance
FORECAST_ITERATIONS = 16  # stage iterations of a forecast step (a noisy start, steps of Delta)
TRAIN_SEED, TEST_SEED, CLOCK_SEED, NOISE_SEED = 100, 200, 0, 1
ROTATION = 1.0  # the rotating truth's angular velocity (the rms vorticity is 1)
HORIZONS = (1, 5)  # in eddy turnovers
RESOLUTION = 32  # the N at which fit_step was measured; steps shorten above it (Condition.max_step)

#: The settings of a profile's `fast_checks`: conditions fitted on a time budget (N = 128 in under
#: 10 minutes on 2 cores), near the protocol of `benchmarks/stream_operator_probe.py`: two
#: trajectories of six snapshots at a mean interval of 0.02 eddy turnovers (at N = 128 a field's
#: finest degrees move fast: a midpoint of W8's interval errs far above the noise and its stage
#: iteration stalls), in midpoints (`fit_step` 0.0625 eddy turnovers at N = 32, shortened by
#: `Condition.max_step` above it: the longest interval, 0.03 tau, is two steps at N = 128; one
#: step an interval is faster, but its step's error is many times the noise's), at most 10
#: iterations, no standard errors (their p conjugate gradient solves would take hours), two test
#: fields, the truth's forecasts in two of Suzuki's steps an interval. The step's error is still
#: the models' own, learned and limit alike: these rows measure size and time more than the
#: spectrum. The measured figures behind these choices: BENCHMARKS.md, "Fluids from data: the
#: stream operator at N = 64 and 128".
FAST = {"n_train": 2, "snapshots": 6, "prefix": 6, "n_test": 2, "interval": 0.02, "composition": None,
        "fit_step": 0.0625, "fine": 2, "lm_iterations": 10, "standard_errors": False}

PROFILES = profiles(
    # sizes: N; truths: names of TRUTHS; noises: relative to the field's rms component (the grid
    # sizes x truths x noises); spot_checks: (N, truth, noise) conditions run beside the grid;
    # n_train x snapshots: the training trajectories and their snapshots (one uneven clock);
    # interval: the mean snapshot interval in eddy turnovers; prefix: the snapshots of the
    # stream operators' first fit (continuation in time, `_fit`; smoke: all, no continuation,
    # as measured; quick, full: NOT yet measured, the N = 16 check was cut by the deadline); fit_step: the stream operators'
    # longest step in eddy turnovers (`Condition.max_step`: fit_stream_operator's max_step, forecasts too;
    # shorter on a rotating sphere and above N = 32); composition: their
    # step's (None: one midpoint; the module docstring); fine: the
    # truth's steps per interval; lm_iterations: fit_stream_operator's at most; dmd_ranks: the DMD candidates;
    # standard_errors: the stream operators' (fit_stream_operator's); max_step_bias: a stream
    # operator whose step's estimated bias is over this many standard errors on any parameter is
    # fitted again in half the step (`_fit`; None: never); fast_checks: (N, truth, noise)
    # conditions run with the settings fast_settings changes (`FAST`).
    # "smoke" exercises the whole pipeline (tests); numbers are meaningless at N = 8.
    smoke=Profile(sizes=(8,), truths=("Euler", "QG F = 10", "QG F = 100", "rotating"), noises=(1e-2,), n_train=3,
                  snapshots=9, n_test=2, interval=0.1, prefix=9, fit_step=0.05, composition=None, fine=4, lm_iterations=20, dmd_ranks=(4, 8, 16),
                  spot_checks=(), standard_errors=True, max_step_bias=None, fast_checks=(), fast_settings={}),
    quick=Profile(sizes=(16,), truths=("Euler", "QG F = 10", "QG F = 100", "rotating"), noises=(1e-3, 1e-2),
                  n_train=4, snapshots=11, n_test=4, interval=0.1, prefix=4, fit_step=0.15, composition="Suzuki", fine=8, lm_iterations=30,
                  dmd_ranks=(4, 8, 16, 32), spot_checks=(), standard_errors=True, max_step_bias=None, fast_checks=(),
                  fast_settings={}),
    # the whole grid at N = 32 and two conditions at N = 64, one of each noise (a learned fit at
    # N = 64 outlasts a session, its time the row's fit_seconds: the grid there is many times
    # that); N = 128 on the time budget (`FAST`). Yoshida's order 6 in two steps an interval (four on the rotating sphere:
    # `Condition.max_step`; Suzuki's in one biases the per-degree spectrum at N = 32 by many
    # standard errors: BENCHMARKS, "The step's order"); resumable row by row (--out)
    full=Profile(sizes=(32,), truths=("Euler", "QG F = 10", "QG F = 100", "rotating"), noises=(1e-3, 1e-2),
                 n_train=4, snapshots=11, n_test=4, interval=0.1, prefix=4, fit_step=0.075, composition="Yoshida6", fine=8, lm_iterations=30,
                 dmd_ranks=(4, 8, 16, 32, 64), spot_checks=((64, "Euler", 1e-3), (64, "QG F = 10", 1e-2)),
                 standard_errors=True, max_step_bias=0.05, fast_checks=((128, "Euler", 1e-3),), fast_settings=FAST),
)


class LaplacianSpectrum(learn.AbstractSpectrum):
    r"""The Hoppe-Yau Laplacian's spectrum $-l(l+1)$, nothing learned (no array leaves): the
    limit of the rotating truth, whose only unknown is the rotation."""

    kind: ClassVar[str] = "laplacian"

    def eigenvalues(self, N: int) -> jax.Array:
        l = np.floor(np.sqrt(np.arange(N * N) + 0.5))
        return jnp.asarray(-(l * (l + 1.0)))

    @classmethod
    def laplacian(cls, N: int) -> LaplacianSpectrum:
        return cls()

    def values(self) -> np.ndarray:
        return np.zeros(0)

    def standard_errors(self, leaf_errors: Any) -> np.ndarray:
        return np.zeros(0)

    def with_values(self, values: Any) -> LaplacianSpectrum:
        if np.size(values) != 0:
            raise ValueError(f"values must be empty (the Laplacian learns nothing); got {values!r}")
        return self


@dataclasses.dataclass(frozen=True)
class Truth:
    """A true fluid: quasi-geostrophic `F` (0: Euler's equations) on a sphere turning at
    `rotation` (`None`: not turning)."""

    name: str
    F: float = 0.0
    rotation: float | None = None

    def degree_values(self, N: int) -> np.ndarray:
        r"""The true eigenvalues per degree $-l(l+1) - F$, $l = 1..N-1$."""
        l = np.arange(1, N)
        return -(l * (l + 1.0)) - self.F

    def model(self, system: lp.systems.Zeitlin) -> learn.StreamOperator:
        """At its true parameters, Suzuki's composition, order 4 (`fine` steps an interval put
        its error far below the fitted models')."""
        return learn.StreamOperator(system, learn.QuasiGeostrophicSpectrum(self.F), rotation=self.rotation,
                                    composition="Suzuki", tol=TRUTH_TOL, iterations=FORECAST_ITERATIONS)


TRUTHS = {t.name: t for t in (Truth("Euler"), Truth("QG F = 10", F=10.0), Truth("QG F = 100", F=100.0),
                              Truth("rotating", rotation=ROTATION))}


@eqx.filter_jit
def _rollouts(model: learn.StreamOperator, starts: jax.Array, intervals: jax.Array, substeps: int) -> jax.Array:
    """`model` from each of `starts` `(k, n)` over `intervals` `(m,)`: `(k, m + 1, n)`."""
    return jax.vmap(lambda s: model.rollout_intervals(s, intervals, substeps))(starts)


class Condition:
    """One N x truth x noise of W8: the snapshot files (written when a row first needs them,
    under `folder`), the data read back, the test fields and the truth's forecasts."""

    def __init__(self, N: int, truth: Truth, noise: float, P: Profile, fast: bool = False):
        self.N, self.truth, self.noise, self.fast = N, truth, noise, fast
        #: the profile, with its `fast_settings` on a fast check (`FAST`)
        self.P = P.replace(**P.fast_settings) if fast else P
        self.system = lp.systems.Zeitlin(N)
        self.folder: Path | None = None  # set by the study before the rows
        self.checkpoints: Path | None = None  # the fits' checkpoints: likewise

    @property
    def key(self) -> str:
        return (f"N{self.N}-{self.truth.name.replace(' ', '').replace('=', '')}-{self.noise:g}"
                + ("-fast" if self.fast else ""))

    def _fields(self, seed: int, count: int) -> np.ndarray:
        return np.stack([self.system.random_state(seed + j, lmax=self.N - 1, decay=0.5)
                         for j in range(count)])

    @functools.cached_property
    def tau(self) -> float:
        r"""The eddy turnover time $1/\omega_{rms}$ of the true test fields (module docstring)."""
        harmonics = np.stack([self.system.harmonics(y) for y in self._fields(TEST_SEED, self.P.n_test)])
        return float(1.0 / np.sqrt(np.mean(np.sum(harmonics**2, axis=-1))))

    @property
    def max_step(self) -> float:
        r"""The stream operators' longest step (fits and forecasts): `fit_step` times the flow's
        shortest time scale, the eddy turnover $\tau$ or, on a rotating sphere, $1/(2\Omega)$
        (the inverse of the planetary vorticity's largest value $2\Omega$; the sphere's rotation
        rate is known to a physicist to its order of magnitude, its value is what a model learns),
        and above `RESOLUTION` shorter by $(N - 1)/($`RESOLUTION`$ - 1)$: the field's finest
        resolved degree $l = N - 1$ is advected, so a step's error, and the midpoint's stage
        iteration's contraction factor, grow with $l\,h$ (Courant's number). Without the
        rotation's scale the step biased the rotating truth's learned spectrum by many standard
        errors, without the resolution's the limit's $F$ at N = 64 (BENCHMARKS.md, "The step's
        order")."""
        scale = self.tau
        if self.truth.rotation is not None and self.truth.rotation != 0:
            scale = min(scale, 1.0 / (2.0 * abs(self.truth.rotation)))
        return self.P.fit_step * scale * min(1.0, (RESOLUTION - 1) / (self.N - 1))

    @functools.cached_property
    def clock(self) -> np.ndarray:
        """The training snapshots' times (one uneven clock)."""
        rng = np.random.default_rng(CLOCK_SEED)
        steps = self.P.interval * self.tau * rng.uniform(0.5, 1.5, self.P.snapshots - 1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    @functools.cached_property
    def data(self) -> it.Observations:
        """The noisy training snapshots, written to files and read back."""
        truth = self.truth.model(self.system)
        clean = np.asarray(_rollouts(truth, jnp.asarray(self._fields(TRAIN_SEED, self.P.n_train)),
                                     jnp.asarray(np.diff(self.clock)), self.P.fine))
        noisy = it.add_field_noise(it.Observations(self.system, [self.clock] * self.P.n_train, list(clean)),
                                   self.noise, seed=NOISE_SEED)
        folder = self.folder
        if folder is None:
            raise ValueError("Condition.folder: where the snapshot files go must be set before the data are read")
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for j, (t, y) in enumerate(zip(noisy.times, noisy.states)):
            path = folder / f"train{j}.h5"
            it.write_vorticity_snapshots(path, t, np.asarray(self.system.algebra.matrix(y)))
            paths.append(path)
        read = it.read_vorticity_snapshots(paths, self.system)
        return it.Observations(self.system, read.times, read.states,
                               metadata={**read.metadata, "noise": self.noise,
                                         "noise_std": noisy.metadata["noise_std"]})

    @functools.cached_property
    def steps(self) -> int:
        """Forecast steps of Delta per eddy turnover."""
        return max(1, round(1.0 / self.P.interval))

    @property
    def step(self) -> float:
        return self.tau / self.steps

    @functools.cached_property
    def test(self) -> tuple[np.ndarray, np.ndarray]:
        """`(starts, reference)`: the noisy test fields `(k, n)` and the truth from the clean
        ones, every step of Delta to 5 tau `(k, 5 steps + 1, n)`."""
        clean = self._fields(TEST_SEED, self.P.n_test)
        intervals = np.full(HORIZONS[-1] * self.steps, self.step)
        reference = np.asarray(_rollouts(self.truth.model(self.system), jnp.asarray(clean), jnp.asarray(intervals),
                                         self.P.fine))
        rms = float(np.sqrt(np.mean(clean**2)))  # add_field_noise's rule on the first observations
        rng = np.random.default_rng(NOISE_SEED + 1)
        starts = clean + self.noise * rms * rng.normal(size=clean.shape)
        return starts, reference


@dataclasses.dataclass(frozen=True)
class Forecaster:
    """What a model fitted: `predict(starts, step, n_steps)` -> `(k, n_steps + 1, n)`, and what it
    identified (`z`: its parameters' largest |error| / standard error; `parameters`: in words)."""

    predict: Any
    z: float | None = None
    parameters: str | None = None
    note: str | None = None
    #: The sphere's rotation the model's own Casimirs are of (those of q = W + rotation f);
    #: `None`: the truth's (a model without one, such as DMD).
    rotation: float | None = None
    #: The fit's wall time, if the model knows it better than the clock around `fit` (a fit
    #: resumed from a checkpoint: its time over every process that ran it).
    fit_seconds: float | None = None
    #: The identified spectrum per degree (`W8Row.spectrum`; `None`: a model without one).
    spectrum: dict[str, list[float]] | None = None


class AbstractFluidModel(AbstractStudyModel):
    """A model of W8: `fit(condition, data)` returns a `Forecaster`. `skip` says why the
    model cannot run here (`None`: it can)."""

    def skip(self) -> str | None:
        return None


def _fit(model: learn.StreamOperator, condition: Condition, data: it.Observations, iterations: int,
         progress: bool, tag: str) -> tuple[learn.StreamOperatorFit, Any, float]:
    """`learn.fit_stream_operator` with steps of at most `condition.max_step`, first on
    every trajectory's first `prefix` snapshots, then from there on all of them (continuation
    in time: the parameters that rotate the field, the degree-1 eigenvalue and the rotation,
    have a loss with other minima once the rotation angle over the data is large; fitted on all
    snapshots at once from the Laplacian's start at N = 16, the QG truths' learned operator
    stopped with field errors 0.67-0.80 at tau and the rotating truth's limit at rotation 0.51
    of 1), the forecasts of its fitted operator at steps as short, and the fits' wall time. Each
    fit is resumable (`learn.Checkpoint` in `condition.checkpoints`, `<tag>-first.h5` and `<tag>.h5`,
    written after every iteration and standard error's column: a learned fit at N = 64 outlasts
    a working session)."""
    max_step = condition.max_step
    starts = None
    k = condition.P.prefix
    if k < min(len(t) for t in data.times):  # continuation in time: the first k snapshots, then all
        short = it.Observations(data.system, [t[:k] for t in data.times], [y[:k] for y in data.states],
                                metadata=data.metadata)
        first = learn.fit_stream_operator(model, short, max_step=max_step, iterations=iterations,
                                          standard_errors=False, progress=progress,
                                          checkpoint=_checkpoint(condition, f"{tag}-first"))
        model, starts, seconds = first.model, first.starts, first.seconds
    else:
        seconds = 0.0
    fit = learn.fit_stream_operator(model, data, max_step=max_step, iterations=iterations, starts=starts,
                                    standard_errors=condition.P.standard_errors, progress=progress,
                                    checkpoint=_checkpoint(condition, tag))
    limit, halvings = condition.P.max_step_bias, 0
    while limit is not None and (worst := worst_step_bias(fit)) is not None and worst > limit:
        if halvings == MAX_HALVINGS:
            raise RuntimeError(f"W8 {condition.key} {tag}: the step's estimated bias is still {worst:.2g} standard "
                               f"errors after {MAX_HALVINGS} halvings of the step (max_step {max_step:g}): the "
                               "estimate does not fall as the step's order says; fit with max_step_bias=None to see it")
        # the same fit in half the step, from where it stopped (its parameters and starts)
        halvings, max_step = halvings + 1, max_step / 2
        if progress:
            print(f"W8 {condition.key} {tag}: the step's estimated bias {worst:.2g} standard errors (over "
                  f"{limit:g}): fitting again in steps of at most {max_step:.4g}", flush=True)
        seconds += fit.seconds
        # its standard errors' solves started from the last fit's (in its checkpoint, if kept)
        last = _checkpoint(condition, tag if halvings == 1 else f"{tag}-half{halvings - 1}")
        fit = learn.fit_stream_operator(fit.model, data, max_step=max_step, iterations=iterations, starts=fit.starts,
                                        standard_errors=True, progress=progress,
                                        se_start=None if last is None else last.path,
                                        checkpoint=_checkpoint(condition, f"{tag}-half{halvings}"))
    fitted = learn.StreamOperator(fit.model.system, fit.spectrum, rotation=fit.rotation, composition=fit.model.composition,
                                  tol=MODEL_TOL, iterations=FORECAST_ITERATIONS)

    def predict(starts, step, n_steps):
        substeps = max(1, math.ceil(step / max_step - 1e-12))
        return np.asarray(_rollouts(fitted, jnp.asarray(starts), jnp.full(n_steps, step), substeps))

    return fit, predict, seconds + fit.seconds


#: The most times `_fit` halves a step whose estimated bias is over the profile's `max_step_bias`.
MAX_HALVINGS = 3


def worst_step_bias(fit: learn.StreamOperatorFit) -> float | None:
    """The step's estimated bias (`StreamOperatorFit.step_bias`) at most, in standard errors of
    the parameters fitted (a held reference has none); `None` if not estimated (no standard
    errors)."""
    bias, se = np.asarray(fit.step_bias, dtype=float), np.asarray(fit.standard_errors, dtype=float)
    if fit.rotation is not None:
        bias, se = np.append(bias, fit.rotation_step_bias), np.append(se, fit.rotation_standard_error)
    fitted = se > 0
    if not np.any(fitted) or not np.all(np.isfinite(bias[fitted])):
        return None
    return float(np.max(np.abs(bias[fitted]) / se[fitted]))


def _checkpoint(condition: Condition, name: str) -> learn.Checkpoint | None:
    """A fit's checkpoint, in the condition's folder of them, resumed if there (`None`: a
    condition built outside the study, without such a folder, fits without one)."""
    if condition.checkpoints is None:
        return None
    return learn.Checkpoint(condition.checkpoints / f"{name}.h5", every=1, resume=True)


def _pm(value: float, se: float) -> str:
    return f"{value:.5g} ± {se:.2g}"


def _step_words(fit: learn.StreamOperatorFit) -> str:
    """The step's estimated bias at most (`worst_step_bias`) and the fit's steps an interval."""
    worst = worst_step_bias(fit)
    return "" if worst is None else f"; the step's estimated bias at most {worst:.2g} SE ({fit.substeps} steps an interval)"


def _unbiased_words(fit: learn.StreamOperatorFit, true: np.ndarray, rotation: float | None) -> str:
    r"""The largest |error|/SE of the learned spectrum (degrees 1..N-2, and the rotation) once
    the step's estimated bias is taken off, $|\hat\lambda_l - b_l - \lambda_l|/\sigma_l$: what
    a fit in shorter steps would give, to first order ("" where the bias is not known)."""
    bias = np.asarray(fit.step_bias, dtype=float)
    if not np.all(np.isfinite(bias)):
        return ""
    z = list(np.abs(fit.values - bias - true)[:-1] / fit.standard_errors[:-1])
    if rotation is not None and fit.rotation_step_bias is not None:
        z.append(abs(fit.rotation - fit.rotation_step_bias - rotation) / fit.rotation_standard_error)
    worst = int(np.argmax(z))
    where = "the rotation" if worst == len(fit.values) - 1 else f"degree {worst + 1}"
    return f"; less the step's bias, |error|/SE {max(z):.4g} at most ({where})"


def _listed(arrays: dict[str, Any]) -> dict[str, list[float]]:
    """A row's `spectrum`: the arrays as lists (JSON; NaN is saved as null)."""
    return {k: np.asarray(v, dtype=float).tolist() for k, v in arrays.items()}


@dataclasses.dataclass(frozen=True)
class LearnedStreamModel(AbstractFluidModel):
    """`learn.StreamOperator` with a spectrum per degree (gauge at degree N - 1) and, on a
    rotating truth, a rotation; `learn.fit_stream_operator` (module docstring)."""

    iterations: int
    label: str = "learned stream operator (spectrum per degree)"

    def fit(self, condition, data, *, progress=False):
        N, truth = condition.N, condition.truth
        l = np.arange(1, N)
        start = learn.DegreeSpectrum(-(l * (l + 1.0)), reference_degree=N - 1)
        model = learn.StreamOperator(condition.system, start, rotation=None if truth.rotation is None else 0.0,
                                     composition=condition.P.composition, tol=MODEL_TOL, iterations=6)
        fit, predict, seconds = _fit(model, condition, data, self.iterations, progress, "learned")
        true = learn.in_gauge(truth.degree_values(N), N - 2, float(fit.values[N - 2]))
        spectrum = {"values": fit.values, "true": true}
        if not condition.P.standard_errors:  # a fast check (`FAST`): the spectrum's relative error
            relative = np.abs(fit.values - true)[:-1] / np.abs(true[:-1])
            words = (f"no standard errors; spectrum: largest relative error {np.max(relative):.2g} at degree "
                     f"{int(np.argmax(relative)) + 1}, median {np.median(relative):.2g}")
            if truth.rotation is not None:
                words += f"; rotation {fit.rotation:.5g}"
            return Forecaster(predict, None, words, f"{fit.iterations} LM iterations ({fit.stopped})",
                              fit.rotation, seconds, _listed(spectrum))
        spectrum |= {"standard_errors": fit.standard_errors, "step_bias": fit.step_bias}
        z = list(np.abs(fit.values - true)[:-1] / fit.standard_errors[:-1])
        words = f"spectrum: largest |error|/SE at degree {int(np.argmax(z)) + 1}"
        if truth.rotation is not None:
            # no gauge on a rotating sphere (module docstring): the truth's own rotation
            z.append(abs(fit.rotation - truth.rotation) / fit.rotation_standard_error)
            words += f"; rotation {_pm(fit.rotation, fit.rotation_standard_error)}"
        wald = fit.wald_test(truth.degree_values(N), truth.rotation)
        words += f"; the truth's Wald d^2 {wald.statistic:.1f} on {wald.dof} parameters, p = {wald.p_value:.2g}"
        words += _step_words(fit) + _unbiased_words(fit, true, truth.rotation)
        return Forecaster(predict, float(np.max(z)), words, f"{fit.iterations} LM iterations ({fit.stopped})",
                          fit.rotation, seconds, _listed(spectrum))


@dataclasses.dataclass(frozen=True)
class LimitModel(AbstractFluidModel):
    """The true family by the same trajectory least squares: the QG family from F = 0, or on a
    rotating truth the Laplacian with the rotation learned from 0."""

    iterations: int
    label: str = "limit (the true family)"

    def fit(self, condition, data, *, progress=False):
        truth = condition.truth
        if truth.rotation is None:
            model = learn.StreamOperator(condition.system, learn.QuasiGeostrophicSpectrum(0.0),
                                         composition=condition.P.composition, tol=MODEL_TOL, iterations=6)
        else:
            model = learn.StreamOperator(condition.system, LaplacianSpectrum(), rotation=0.0,
                                         composition=condition.P.composition, tol=MODEL_TOL, iterations=6)
        fit, predict, seconds = _fit(model, condition, data, self.iterations, progress, "limit")
        if not condition.P.standard_errors:  # a fast check (`FAST`)
            words = "no standard errors; " + (f"F = {float(fit.values[0]):.5g}" if truth.rotation is None
                                              else f"rotation {fit.rotation:.5g}")
            return Forecaster(predict, None, words, f"{fit.iterations} LM iterations ({fit.stopped})",
                              fit.rotation, seconds)
        if truth.rotation is None:
            z = abs(float(fit.values[0]) - truth.F) / float(fit.standard_errors[0])
            words = f"F = {_pm(float(fit.values[0]), float(fit.standard_errors[0]))}"
        else:
            z = abs(fit.rotation - truth.rotation) / fit.rotation_standard_error
            words = f"rotation {_pm(fit.rotation, fit.rotation_standard_error)}"
        words += _step_words(fit)
        return Forecaster(predict, float(z), words, f"{fit.iterations} LM iterations ({fit.stopped})",
                          fit.rotation, seconds)


@dataclasses.dataclass(frozen=True)
class DMDModel(AbstractFluidModel):
    """DMD (`kind` "exact" or "optimised", `paper._dmd`), its rank chosen among `ranks` on the
    training data."""

    kind: str
    ranks: tuple[int, ...]

    @property
    def label(self) -> str:
        return "DMD (exact)" if self.kind == "exact" else "optimised DMD (BOPDMD)"

    def skip(self):
        return _dmd.pydmd_missing()

    def fit(self, condition, data, *, progress=False):
        times, states = list(data.times), list(data.states)
        rank, scores = _dmd.chosen_rank(self.kind, times, states, self.ranks)
        try:
            fitted = _dmd.FITS[self.kind](times, states, rank)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as err:  # pydmd failed on every snapshot
            return Forecaster(lambda starts, step, n_steps: np.full((len(starts), n_steps + 1, starts.shape[1]), np.inf),
                              None, None, f"rank {rank} of {sorted(scores)}: pydmd failed ({type(err).__name__})")

        def predict(starts, step, n_steps):
            return fitted.predict(starts, step * np.arange(n_steps + 1))

        starts = condition.test[0]
        lost = np.linalg.norm(fitted.predict(starts, np.zeros(1))[:, 0] - starts, axis=-1) / np.linalg.norm(starts, axis=-1)
        note = f"rank {rank} of {sorted(scores)}; the test starts' part outside the modes {np.mean(lost):.2g}"
        if fitted.warnings:
            note += f" ({fitted.warnings} pydmd warning(s))"
        return Forecaster(predict, None, None, note)


def models(P: Profile) -> list[AbstractFluidModel]:
    """W8's models, in the order of their rows."""
    return [LearnedStreamModel(P.lm_iterations), LimitModel(P.lm_iterations), DMDModel("exact", P.dmd_ranks),
            DMDModel("optimised", P.dmd_ranks)]


@dataclasses.dataclass(frozen=True)
class W8Row:
    N: int
    truth: str
    noise: float
    model: str
    error_1: float | None
    error_5: float | None
    energy_error: float | None
    enstrophy_error: float | None
    z: float | None
    casimir_drift: float | None
    fit_seconds: float | None
    parameters: str | None
    note: str | None
    #: The process's peak resident memory by the fit's end, in GB (an upper bound on the fit's;
    #: `None` in rows saved before it was recorded).
    peak_memory_gb: float | None
    #: The learned model's spectrum per degree $l = 1..N-1$ in the truth's gauge (`values`, the
    #: truth's `true`, and with standard errors `standard_errors` and the step's estimated bias
    #: `step_bias`; degree N - 1 is the gauge's, held); `None` for other models and in rows saved
    #: before it was kept.
    spectrum: dict[str, list[float]] | None = optional()

    @property
    def condition(self) -> tuple[int, str, float]:
        return (self.N, self.truth, self.noise)


def casimir_drift(system: lp.systems.Zeitlin, ys: np.ndarray, rotation: float | None = None) -> float:
    r"""The module docstring's Casimir drift of the forecasts `ys` `(k, m, n)` (inf if not
    finite), of the absolute vorticity $W + \Omega f$ on a sphere turning at `rotation`."""
    if not np.all(np.isfinite(ys)):
        return math.inf
    q = np.asarray(system.algebra.matrix(ys))
    if rotation is not None:
        q = q + rotation * learn.planetary_vorticity(system.N)
    e = np.linalg.eigvalsh(1j * q)  # (k, m, N)
    worst = 0.0
    for k in (2, 3, 4):
        p = np.sum(e**k, axis=-1)
        scale = np.sum(np.abs(e[:, :1]) ** k, axis=-1)
        worst = max(worst, float(np.max(np.abs(p - p[:, :1]) / scale)))
    return worst


def _peak_memory_gb() -> float | None:
    """The process's peak resident memory so far, in GB (`None` where the OS does not say)."""
    try:
        import resource
    except ImportError:  # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**30 if sys.platform == "darwin" else peak / 2**20  # bytes on macOS, KiB on Linux


def measure(condition: Condition, model: AbstractFluidModel, progress: bool) -> W8Row:
    """Fit `model` on `condition`'s data and measure its forecasts."""
    base = {"N": condition.N, "truth": condition.truth.name, "noise": condition.noise, "model": model.label}
    data = condition.data
    begin = time.perf_counter()
    forecaster = model.fit(condition, data, progress=progress)
    fit_seconds = time.perf_counter() - begin if forecaster.fit_seconds is None else forecaster.fit_seconds
    peak_memory_gb = _peak_memory_gb()
    starts, reference = condition.test
    ys = forecaster.predict(starts, condition.step, reference.shape[1] - 1)
    scale = np.linalg.norm(reference[:, 0], axis=-1)
    errors = {h: float(np.mean(np.linalg.norm(ys[:, h * condition.steps] - reference[:, h * condition.steps], axis=-1)
                               / scale)) for h in HORIZONS}
    truth = condition.truth.model(condition.system)
    end_true, end = reference[:, -1], ys[:, -1]
    hamiltonian = jax.vmap(truth.hamiltonian)
    energy_true = np.asarray(hamiltonian(jnp.asarray(end_true)))
    energy = np.asarray(hamiltonian(jnp.asarray(end))) if np.all(np.isfinite(end)) else np.full_like(
        energy_true, np.inf)
    enstrophy_true, enstrophy = 0.5 * np.sum(end_true**2, axis=-1), 0.5 * np.sum(end**2, axis=-1)

    def finite(x):
        x = float(x)
        return x if np.isfinite(x) else math.inf

    return W8Row(**base, error_1=finite(errors[1]), error_5=finite(errors[5]),
                 energy_error=finite(np.mean(np.abs(energy - energy_true) / np.abs(energy_true))),
                 enstrophy_error=finite(np.mean(np.abs(enstrophy - enstrophy_true) / enstrophy_true)),
                 z=forecaster.z, casimir_drift=casimir_drift(
                     condition.system, ys, condition.truth.rotation if forecaster.rotation is None else forecaster.rotation), fit_seconds=fit_seconds,
                 parameters=forecaster.parameters, note=forecaster.note, peak_memory_gb=peak_memory_gb,
                 spectrum=forecaster.spectrum)


def spectrum_figure(rows: list[W8Row], out_dir: Path) -> list[str]:
    r"""`spectrum.png`: per condition whose learned row kept its spectrum (`W8Row.spectrum`), the
    error of each degree's eigenvalue against the truth's in standard errors, $(\hat\lambda_l -
    \lambda_l)/\sigma_l$, the same less the step's estimated bias, and the band of 3; a fast
    check (no standard errors) its relative error instead. Nothing if no row kept one."""
    kept = [r for r in rows if r.spectrum is not None]
    if not kept:
        return []
    columns = min(len(kept), 3)
    fig = figure(figsize=(4.6 * columns, 3.4 * math.ceil(len(kept) / columns)))
    axes = np.atleast_1d(fig.subplots(math.ceil(len(kept) / columns), columns, squeeze=False)).ravel()
    for ax, row in zip(axes, kept):
        sp = {k: np.asarray(v, dtype=float) for k, v in row.spectrum.items()}  # null (NaN) stays NaN
        degrees = np.arange(1, len(sp["values"]))  # the gauge's degree N - 1 is held: left out
        error = (sp["values"] - sp["true"])[:-1]
        if "standard_errors" in sp:
            se = sp["standard_errors"][:-1]
            ax.axhspan(-3, 3, color="0.9", label="within 3 SE")
            ax.plot(degrees, error / se, "o", ms=4, color="black", label="fit")
            if np.all(np.isfinite(sp["step_bias"])):
                ax.plot(degrees, (error - sp["step_bias"][:-1]) / se, "x", ms=4, color="crimson",
                        label="less the step's bias")
            ax.set_ylabel("(fit - truth) / SE")
        else:
            ax.semilogy(degrees, np.abs(error) / np.abs(sp["true"][:-1]), "o", ms=3, color="black")
            ax.set_ylabel("|fit - truth| / |truth|")
        ax.set_xlabel("degree l")
        ax.set_title(f"N = {row.N}, {row.truth}, noise {row.noise:g}", fontsize=9)
    next((ax for ax, row in zip(axes, kept) if "standard_errors" in row.spectrum), axes[0]).legend(fontsize=7)
    for ax in axes[len(kept):]:
        ax.set_visible(False)
    fig.tight_layout()
    save_figure(fig, Path(out_dir) / "spectrum.png", dpi=110)
    return ["spectrum.png"]


COLUMNS = (
    Column("N", lambda r: str(r.N)),
    Column("truth", lambda r: r.truth),
    Column("noise", lambda r: f"{r.noise:g}"),
    Column("model", lambda r: r.model),
    Column("field error at tau", lambda r: r.error_1),
    Column("field error at 5 tau", lambda r: r.error_5),
    Column("energy error at 5 tau", lambda r: r.energy_error),
    Column("enstrophy error at 5 tau", lambda r: r.enstrophy_error),
    Column("max |error|/SE", lambda r: r.z),
    Column("Casimir drift", lambda r: r.casimir_drift),
    Column("fit s", lambda r: r.fit_seconds),
    Column("peak memory GB", lambda r: r.peak_memory_gb),
    Column("identified", lambda r: r.parameters or "—"),
    Column("note", lambda r: r.note or "—"),
)

LEARNED, LIMIT = LearnedStreamModel.label, LimitModel.label
DMD_LABELS = ("DMD (exact)", "optimised DMD (BOPDMD)")


#: A fast check's budget (`FAST`): the learned fit's wall time and the process's peak memory.
FAST_SECONDS, FAST_MEMORY_GB = 600.0, 8.0


def verdict(rows: list[W8Row], fast: frozenset[tuple[int, str, float]] = frozenset()) -> list[str]:
    """The must-show statements per condition; `fast`: the conditions of fast checks (`FAST`),
    judged on their budget, not on standard errors they do not have."""
    out = []
    for condition in dict.fromkeys(r.condition for r in rows):
        here = {r.model: r for r in rows if r.condition == condition}
        learned, limit = here.get(LEARNED), here.get(LIMIT)
        if learned is None or limit is None:
            continue
        N, truth, noise = condition
        ratios = [learned.error_1 / limit.error_1, learned.error_5 / limit.error_5]
        line = (f"N = {N}, {truth}, noise {noise:g}: the learned operator's field error {fmt(learned.error_1)} at tau, "
                f"{fmt(learned.error_5)} at 5 tau against the limit's {fmt(limit.error_1)}, {fmt(limit.error_5)} "
                f"({max(ratios):.3g}x at most: {'within' if max(ratios) <= 1.5 else 'NOT within'} 1.5x)")
        peers = [here[m] for m in DMD_LABELS if m in here]
        if peers:
            below = all(learned.error_1 < p.error_1 and learned.error_5 < p.error_5 for p in peers)
            line += (f"; {'below' if below else 'NOT below'} DMD's ("
                     + ", ".join(f"{p.model} {fmt(p.error_1)}, {fmt(p.error_5)}" for p in peers) + ")")
        if condition in fast:
            memory = learned.peak_memory_gb
            line += (f"; a fast check: the learned fit {learned.fit_seconds:.0f} s "
                     f"({'under' if learned.fit_seconds <= FAST_SECONDS else 'NOT under'} {FAST_SECONDS:.0f} s), "
                     f"the process's peak memory {fmt(memory)} GB ("
                     + ("not known here" if memory is None else
                        f"{'under' if memory <= FAST_MEMORY_GB else 'NOT under'} {FAST_MEMORY_GB:g} GB")
                     + "), no standard errors")
        else:
            line += (f"; spectrum {fmt(learned.z)} standard errors at most "
                     f"({'within' if learned.z is not None and learned.z <= 3 else 'NOT within'} 3), the limit's "
                     f"{fmt(limit.z)}")
        line += (f"; Casimirs kept to {fmt(learned.casimir_drift)} "
                 f"({'within' if learned.casimir_drift <= 1e-13 else 'NOT within'} 1e-13).")
        out.append(line)
    return out


class W8(AbstractStudy):
    id = "W8"
    title = "Fluids from data: a learned stream operator vs the true family, DMD and optimised DMD"
    profiles = PROFILES
    row_type = W8Row
    columns = COLUMNS

    def conditions(self, P):
        overlap = set(P.fast_checks) & ({(N, t, e) for N in P.sizes for t in P.truths for e in P.noises}
                                        | set(P.spot_checks))
        if overlap:
            raise ValueError(f"W8: the fast checks {sorted(overlap)} are also conditions of the grid or spot "
                             "checks (their rows would be judged together): run them apart")
        for N in P.sizes:
            for name in P.truths:
                for noise in P.noises:
                    yield Condition(N, TRUTHS[name], noise, P)
        for N, name, noise in P.spot_checks:
            yield Condition(N, TRUTHS[name], noise, P)
        for N, name, noise in P.fast_checks:
            yield Condition(N, TRUTHS[name], noise, P, fast=True)

    def announce(self, condition):
        return f"W8: N = {condition.N}, {condition.truth.name}, noise {condition.noise:g}"

    def models(self, P, condition):
        return models(condition.P)

    def admits(self, condition, model):
        reason = model.skip()
        if reason is not None:
            print(f"W8: {model.label} skipped: {reason}", flush=True)
        return reason is None

    def row_name(self, profile, condition, model):
        return f"{profile}-{condition.key}-{model.label.split(' (')[0].replace(' ', '_')}.json"

    def condition_rows(self, profile, condition, models, out_dir, progress):
        condition.folder = out_dir / "snapshots" / f"{profile}-{condition.key}"
        condition.checkpoints = out_dir / "checkpoints" / f"{profile}-{condition.key}"
        return super().condition_rows(profile, condition, models, out_dir, progress)

    def evaluate(self, condition, model, progress):
        return measure(condition, model, progress)

    def line(self, row):
        return (f"  {row.model}: field error {fmt(row.error_1)} at tau, {fmt(row.error_5)} at 5 tau; |error|/SE "
                f"{fmt(row.z)}; Casimir drift {fmt(row.casimir_drift)}; fit {row.fit_seconds:.1f} s"
                + (f"; {row.note}" if row.note else ""))

    def verdict(self, rows, conditions):
        lines = verdict(rows, frozenset((c.N, c.truth.name, c.noise) for c in conditions if c.fast))
        missing = _dmd.pydmd_missing()
        if missing is not None:
            lines.append(f"No DMD rows: {missing}.")
        return lines

    def summary(self, P, rows, conditions):
        return {"profile_settings": P.as_dict(), "horizons": list(HORIZONS), "rotation": ROTATION}

    def figures(self, rows, conditions, out_dir):
        return spectrum_figure(rows, out_dir)

    def summary_rows(self, rows):
        return [(f"N = {r.N} {r.truth} noise {r.noise:g} {r.model}: field error at 5 tau", "—", fmt(r.error_5), "—")
                for r in rows]

    def description(self, metrics):
        P = metrics.get("profile_settings", {})
        return (f"Truths: {', '.join(P.get('truths', ()))} (`learn.StreamOperator` at the true parameters, "
                f"{P.get('fine')} steps per interval); {P.get('n_train')} training fields x {P.get('snapshots')} "
                f"noisy snapshots on one uneven clock (mean interval {P.get('interval')} tau), through snapshot "
                f"files; {P.get('n_test')} test fields forecast from a noisy start. tau = 1/omega_rms (the eddy "
                "turnover time from the enstrophy). The learned spectrum's gauge: degree N - 1 at the Laplacian's. "
                "The limit: the QG family (Euler, QG), the Laplacian with the rotation learned (rotating). No LPNet "
                "row: it needs pairs at one step (these snapshots are uneven) and N^4 weights."
                + (f" Fast checks {P.get('fast_checks')}: the settings {P.get('fast_settings')} (no standard "
                   "errors, a midpoint a step)." if P.get("fast_checks") else ""))


EXPERIMENT = W8()
