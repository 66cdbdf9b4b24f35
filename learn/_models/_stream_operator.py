r"""A learned stream operator for a fluid on the sphere (Zeitlin's model with an unknown
Hamiltonian): the isospectral midpoint step of $H(W) = \tfrac12\langle W, L^{-1}W\rangle$, $L$
diagonal in the quantized spherical harmonics with learned eigenvalues, optionally on a
rotating sphere."""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators import IsospectralMidpoint
from integrators._isospectral import PREDICTOR_POINTS
from integrators.internals import (
    ISOSPECTRAL_MAX_ITER,
    ISOSPECTRAL_TOL,
    check_h,
    check_isospectral,
    check_stage_tolerance,
)
from integrators.splitting import AbstractCompositionMethod, splitting_method_by_name
from liepoisson.internals import (
    as_state,
    harmonic_multiplier,
    is_traced,
    positive_float,
    positive_int,
)
from liepoisson.systems import AbstractPoissonSystem, Zeitlin

from .._solvers._stage import AbstractStage
from ._base import AbstractCasimirConservingMap
from ._spectrum import AbstractGaugedSpectrum, AbstractSpectrum, spectrum_of

#: Quasi-Newton iterations of the stage equation per step (a fixed count: straight-line steps,
#: which reverse-mode differentiation needs); a step that has not met `tol` after them is NaN.
DEFAULT_ITERATIONS = 4

#: The degree of the polynomial in time through the last `PREDICTOR_POINTS` steps that starts
#: each stage iteration of `rollout_intervals`: at uneven intervals 2 predicted best of 1, 2, 3
#: and 5 (a higher degree extrapolates wildly through unevenly spaced points).
PREDICTOR_DEGREE = 2



def composition_method(composition: Any) -> AbstractCompositionMethod | None:
    """`composition` as a composition method of `integrators.splitting` (a class, an instance,
    or a class name such as `"Suzuki"`), or `None` (one midpoint a step); `TypeError` or
    `ValueError` naming the argument otherwise."""
    if composition is None:
        return None
    if isinstance(composition, str):
        composition = splitting_method_by_name(composition, "composition")
    if not (isinstance(composition, AbstractCompositionMethod)
            or (isinstance(composition, type) and issubclass(composition, AbstractCompositionMethod))):
        raise TypeError(f"composition must be None (the isospectral midpoint) or a composition method of "
                        f"integrators.splitting (Suzuki, Yoshida6, TripleJump, McLachlan4: a class, an instance or "
                        f"its name); got {composition!r}")
    method = composition() if isinstance(composition, type) else composition
    if method.ordering is not None:
        raise ValueError(f"composition composes one step (the midpoint), so it takes no ordering; got {method!r}")
    return method


def planetary_vorticity(N: int) -> np.ndarray:
    r"""The matrix $T_{1,0}\cdot 2/\sqrt3$ `(N, N)`: the planetary vorticity $f = 2\Omega\cos\theta$ of
    a sphere turning at unit angular velocity $\Omega$ about its axis ($\cos\theta =
    \sqrt{4\pi/3}\,Y_{1,0}$; the field's normalisation is that of
    `liepoisson.systems.Zeitlin.vorticity`, $\omega = \sqrt{4\pi}\sum_{lm}\omega_{lm}Y^r_{lm}$)."""
    from liepoisson._quantized_sphere import harmonics_to_matrix

    omega = np.zeros(N * N)
    omega[2] = 2.0 / math.sqrt(3.0)  # index l^2 + l + m of (1, 0)
    return harmonics_to_matrix(omega, N)


def _weights_at(times: jax.Array, valid: jax.Array, t: jax.Array) -> jax.Array:
    r"""`(M,)`: the weights of the entries of a ring at `times` (`valid` those filled) in the
    value at time `t` of their least-squares polynomial of degree
    $\min(\text{filled} - 1, $ `PREDICTOR_DEGREE`$)$. No derivative (they only start the
    stage iteration)."""
    times = jax.lax.stop_gradient(times)
    scale = jnp.maximum(jnp.max(jnp.where(valid, jnp.abs(times - t), 0.0)), jnp.finfo(times.dtype).tiny)
    s = jnp.where(valid, (times - t) / scale, 0.0)
    powers = np.arange(PREDICTOR_DEGREE + 1)
    keep = valid[:, None] & (powers[None, :] < jnp.sum(valid))  # rows filled; degree below their count
    V = jnp.where(keep, s[:, None] ** powers[None, :], 0.0)
    return jnp.linalg.pinv(V)[0]  # the fitted polynomial's value at s = 0 (0 with nothing filled)


class _Ring(eqx.Module):
    r"""The last `PREDICTOR_POINTS` steps of a rollout, per unit step, at the middle time of
    each: $a = \Delta W/(2h)$ and $c = (D - \Delta W/2)/h^2$, $\Delta W$ the step's increment
    and $D$ its stage's. The isospectral midpoint's step is $\Delta W = h[\tilde B, \tilde W]$
    and its stage $D = \tfrac h2[\tilde B, \tilde W] + \tfrac{h^2}4\tilde B\tilde W\tilde B$
    exactly, so $a$ and $c$ are smooth functions of the middle time to $O(h^2)$ whatever $h$:
    extrapolated in time they start the next stage at $D = ha + h^2c$ across intervals of any
    lengths (an extrapolation of $D$ by step count would not)."""

    a: jax.Array
    c: jax.Array
    times: jax.Array
    valid: jax.Array
    count: jax.Array

    @classmethod
    def empty(cls, W: jax.Array) -> _Ring:
        M = PREDICTOR_POINTS
        zeros = jnp.zeros((M, *W.shape), W.dtype)
        return cls(zeros, zeros, jnp.zeros(M), jnp.zeros(M, bool), jnp.asarray(0))

    def predict(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        w = _weights_at(self.times, self.valid, t)
        return jnp.tensordot(w, self.a, axes=1), jnp.tensordot(w, self.c, axes=1)

    def push(self, a: jax.Array, c: jax.Array, t: jax.Array, keep: jax.Array) -> _Ring:
        """With `(a, c)` at time `t` written over the oldest entry if `keep` (else unchanged)."""
        slot = self.count % PREDICTOR_POINTS
        return _Ring(self.a.at[slot].set(jnp.where(keep, a, self.a[slot])),
                     self.c.at[slot].set(jnp.where(keep, c, self.c[slot])),
                     self.times.at[slot].set(jnp.where(keep, t, self.times[slot])),
                     self.valid.at[slot].set(self.valid[slot] | keep),
                     jnp.where(keep, self.count + 1, self.count) % (2 * PREDICTOR_POINTS))


def _checked_rollout(y0: Any, intervals: Any, dim: int) -> tuple[jax.Array, np.ndarray]:
    """`rollout_intervals`' arguments checked (called on concrete values only): `y0` one
    finite state `(dim,)`, `intervals` `(n,)` finite and >= 0."""
    y0 = as_state(y0, "y0", dim)
    if y0.ndim != 1:
        raise ValueError(f"y0 must be one state of shape ({dim},); got shape {tuple(y0.shape)}")
    if isinstance(intervals, (str, bytes)) or intervals is None:
        raise TypeError(f"intervals must be an array of shape (n,) of times; got {intervals!r}")
    arr = np.asarray(intervals)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise TypeError(f"intervals must be a real array of shape (n,); got dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"intervals must have shape (n,), the times between states; got shape {arr.shape}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        bad = int(np.argmax(~np.isfinite(arr) | (arr < 0)))
        raise ValueError(f"intervals must be finite and >= 0 (0: a padded interval, the state repeated); got "
                         f"{arr[bad]!r} at index {bad}")
    return y0, arr


class StreamOperator(IsospectralMidpoint, AbstractCasimirConservingMap):
    r"""The isospectral midpoint step (`integrators.IsospectralMidpoint`) of a fluid on the
    sphere whose stream operator is learned: with $W$ the vorticity (a skew-Hermitian
    $N\times N$ matrix, Zeitlin's model), $q = W + \Omega f$ the absolute vorticity ($f$ the
    planetary vorticity of unit rotation, `planetary_vorticity`; $\Omega = 0$ without
    `rotation`) and

    $$H(q) = \frac1{2\hbar}\langle q - \Omega f, L^{-1}(q - \Omega f)\rangle, \qquad
    \dot q = \tfrac1\hbar[L^{-1}(q - \Omega f), q],$$

    $L$ diagonal in the quantized spherical harmonics, $L\,T_{lm} = \lambda_{lm}T_{lm}$, its
    eigenvalues learned (`spectrum`: one per degree $l$ by default, per $(l, m)$, or the
    quasi-geostrophic family $-l(l+1) - F$; the Laplacian's $-l(l+1)$ is Zeitlin's model,
    `liepoisson.systems.Zeitlin`). Every step is a conjugation of $q$ by the unitary Cayley
    transform of $\tfrac h2 B(\tilde q)$, $B(q) = L^{-1}(q - \Omega f)/\hbar$: the spectrum of
    $q$, hence every Casimir $\mathrm{tr}(iq)^k$, is kept to round-off whatever the parameters
    (Modin & Viviani, JFM 2020). Without rotation $q = W$. $L^{-1}$ costs about one matrix
    product (`liepoisson.internals.harmonic_multiplier`); nothing larger than $N\times N$ is
    formed.

    The state `y` is the relative vorticity $W$ in u(N) coordinates (`system.algebra`), as
    observed; the step adds $\Omega f$, conjugates and subtracts it.

    **Arguments:**

    - `system`: `liepoisson.systems.Zeitlin(N)` (the Poisson structure, u(N)*, and $\hbar$).
    - `spectrum`: a `learn.DegreeSpectrum`, `learn.HarmonicSpectrum` or
      `learn.QuasiGeostrophicSpectrum` (its start), or the name of one of them (`"degree"`,
      the default, `"harmonic"`, `"quasi-geostrophic"`), started at the Laplacian's.
    - `rotation`: `None` (no rotation term, the default) or the start of the learned angular
      velocity $\Omega$ of the sphere.
    - `composition`: `None` (the default), one isospectral midpoint a step (order 2); or a
      symmetric composition method of `integrators.splitting` (class, instance or name), whose
      table $\gamma$ makes the step the midpoints of $\gamma_1 h, \dots, \gamma_s h$:
      `Suzuki` (order 4, five midpoints, $\gamma = p, p, 1 - 4p, p, p$, $p = 1/(4 - 4^{1/3})$),
      `Yoshida6` (order 6, seven), `TripleJump`, `McLachlan4`. Each midpoint is a unitary
      conjugation, so every composition keeps the Casimirs alike. A model fitted to data at
      steps $h$ carries the step's error into its parameters, $O(h^{order})$: at order 2
      enough to bias the identified spectrum by many standard errors at low noise; on
      Zeitlin's model Suzuki's reaches a given error at far fewer midpoints than the triple
      jump (BENCHMARKS.md, "The step's order").
    - `h`, `tol`, `max_iter` as `integrators.IsospectralMidpoint`; `iterations` the fixed
      quasi-Newton iterations of every midpoint (default `DEFAULT_ITERATIONS`: straight-line
      steps, differentiable in both modes; a step that has not met `tol` is NaN).

    Fit it to observations with `learn.fit_stream_operator`; roll it out at uneven times with
    `rollout_intervals`.
    """

    spectrum: AbstractSpectrum
    rotation: jax.Array | None
    composition: AbstractCompositionMethod | None = eqx.field(static=True)

    def __init__(self, system: AbstractPoissonSystem, spectrum: Any = "degree", *, rotation: float | None = None,
                 composition: Any = None, h: float | None = None, tol: float = ISOSPECTRAL_TOL,
                 iterations: int = DEFAULT_ITERATIONS, max_iter: int = ISOSPECTRAL_MAX_ITER, key: Any = None):
        if not isinstance(system, Zeitlin):
            raise TypeError(f"system must be liepoisson.systems.Zeitlin(N) (a fluid on the sphere, u(N)*); got "
                            f"{system!r}")
        self.system = check_isospectral(system)
        self.spectrum = spectrum_of(spectrum, system.N)
        if rotation is None:
            self.rotation = None
        else:
            if isinstance(rotation, (bool, np.bool_, str, bytes)) or np.ndim(rotation) != 0:
                raise TypeError(f"rotation must be None or a real number (the sphere's angular velocity); got "
                                f"{rotation!r}")
            if not np.isfinite(float(rotation)):
                raise ValueError(f"rotation must be finite; got {rotation!r}")
            self.rotation = jnp.asarray(float(rotation))
        self.composition = composition_method(composition)
        self.h = None if h is None else positive_float(h, "h")
        self.tol = check_stage_tolerance(tol)
        self.iterations = positive_int(iterations, "iterations")
        self.max_iter = positive_int(max_iter, "max_iter")

    @property
    def N(self) -> int:
        return self.system.N

    @property
    def substeps(self) -> tuple[float, ...]:  # type: ignore[override]
        """The midpoints of a step, as fractions of it (`composition`'s table)."""
        if self.composition is None:
            return IsospectralMidpoint.substeps
        return tuple(map(float, self.composition.coefficients))

    @property
    def order(self) -> int:
        """The step's order: 2 (the midpoint), else `composition`'s."""
        return 2 if self.composition is None else int(self.composition.order)

    # -- the operator ---------------------------------------------------------------------------
    def _planetary(self) -> jax.Array | float:
        r"""$\Omega f$ as a matrix (0 without rotation)."""
        if self.rotation is None:
            return 0.0
        return self.rotation * jnp.asarray(planetary_vorticity(self.N))

    def stream_matrix(self, W: jax.Array) -> jax.Array:
        r"""$\psi = L^{-1}W$ for the relative vorticity `W` `(N, N)`."""
        return harmonic_multiplier(W, self.spectrum.inverse(self.N))

    def velocity_matrix(self, W: jax.Array) -> jax.Array:
        r"""$B(q) = L^{-1}(q - \Omega f)/\hbar$ of the absolute vorticity $q$ `(N, N)`."""
        return self.stream_matrix(W - self._planetary()) / self.system.hbar

    def hamiltonian(self, y: ArrayLike) -> jax.Array:
        r"""$H = \frac1{2\hbar}\langle W, L^{-1}W\rangle$ of the relative vorticity (the pairing
        $\mathrm{Re}\,\mathrm{tr}(A^\dagger B)$; positive for a negative spectrum, Zeitlin's
        energy at the Laplacian's)."""
        W = self.system.algebra.matrix(jnp.asarray(y))
        return -jnp.real(jnp.sum(jnp.conj(W) * self.stream_matrix(W))) / (2 * self.system.hbar)

    # -- steps: the state is the relative vorticity ------------------------------------------------
    def _shift(self) -> jax.Array | float:
        if self.rotation is None:
            return 0.0
        return self.system.algebra.coordinates(self._planetary())

    def step(self, y: jax.Array) -> jax.Array:
        check_h(self)
        return super().step(y + self._shift()) - self._shift()

    def compensated_step(self, y: jax.Array) -> jax.Array:
        check_h(self)
        return super().compensated_step(y + self._shift()) - self._shift()

    def carry(self, y: jax.Array):
        check_h(self)
        return super().carry(y + self._shift())

    def uncarry(self, c) -> jax.Array:
        return super().uncarry(c) - self._shift()

    def rollout_intervals(self, y0: jax.Array, intervals: jax.Array, substeps: int = 1) -> jax.Array:
        r"""The states `(n + 1, dim)` at the start `y0` `(dim,)` and after each of the `n`
        `intervals` `(n,)` (each run in `substeps` equal steps; an interval of 0 repeats the
        state: padding). Traceable and differentiable in both modes in the parameters and `y0`
        (the fixed `iterations`; the history that starts each step's iteration is found without
        derivatives). The predictor's history is kept per unit step (increments divided by
        $h$), so that it extrapolates across intervals of other lengths. A midpoint whose stage
        iteration has not met `tol` makes the states after it NaN under `jit`, `vmap` or `grad`
        (a fit rejects such a step); called on values, the arguments are checked and such a
        step is a `ValueError` that says which interval."""
        substeps = positive_int(substeps, "substeps")
        eager = not (is_traced(y0) or is_traced(intervals))
        if eager:
            y0, intervals = _checked_rollout(y0, intervals, self.system.dim)
        intervals = jnp.asarray(intervals)
        shift = self._shift()
        W = self.system.algebra.matrix(jnp.asarray(y0) + shift)
        h0 = jax.lax.stop_gradient(intervals[0] / substeps)
        h0 = jnp.where(h0 > 0, h0, 1.0)

        def back(state, _):  # a step back from Wb: the stage of the step forward to Wb (no derivatives)
            Wb, ring, t = state
            a, c = ring.predict(t - 0.5 * h0)
            dW, D, _ = self._midpoint(Wb, -h0, -h0 * a + h0 * h0 * c, None)
            forward, stage = -dW, D - dW  # the forward step from Wb + dW and its stage
            ring = ring.push(forward / (2 * h0), (stage - 0.5 * forward) / (h0 * h0), t - 0.5 * h0, True)
            return (Wb + dW, ring, t - h0), None

        (_, ring, _), _ = jax.lax.scan(back, (jax.lax.stop_gradient(W), _Ring.empty(W), jnp.zeros_like(h0)),
                                       None, length=PREDICTOR_POINTS)
        ring = jax.lax.stop_gradient(ring)

        def interval(state, dt):
            W, ring, t = state
            step = dt / substeps
            moving = step > 0

            def substep(state, _):
                W, ring, t = state
                for fraction in self.substeps:  # the composition's midpoints (one at order 2)
                    h = fraction * step
                    safe = jnp.where(moving, h, 1.0)
                    a, c = ring.predict(t + 0.5 * h)
                    dW, D = self._stage_step(W, h, h * a + h * h * c)
                    ring = ring.push(dW / (2 * safe), (D - 0.5 * dW) / (safe * safe), t + 0.5 * h, moving)
                    W, t = W + dW, t + h
                return (W, ring, t), None

            (W, ring, t), _ = jax.lax.scan(substep, (W, ring, t), None, length=substeps)
            return (W, ring, t), self.system.algebra.coordinates(W) - shift

        _, ys = jax.lax.scan(interval, (W, ring, jnp.zeros_like(h0)), intervals)
        out = jnp.concatenate([jnp.asarray(y0)[None], ys])
        if eager and not is_traced(out) and not bool(jnp.all(jnp.isfinite(out))):
            first = int(np.argmin(np.all(np.isfinite(np.asarray(out)), axis=-1)))
            raise ValueError(f"the stage iteration of a midpoint did not meet tol={self.tol:g} in iterations="
                             f"{self.iterations} in interval {first - 1} (of length {float(intervals[first - 1]):g}, "
                             f"{substeps} substep(s)): the step is too long for this field; give more substeps (a "
                             f"shorter step) or more iterations")
        return out

    def _stage_step(self, W: jax.Array, h: jax.Array, D: jax.Array) -> tuple[jax.Array, jax.Array]:
        """`IsospectralMidpoint._midpoint` with `iterations` fixed, as a loop (`lax.scan`: one
        iteration compiled, not `iterations` copies; differentiable in both modes): the step's
        increment (NaN if the last iteration moved the stage by more than `tol`) and the
        stage's."""
        scale = self.tol * jnp.maximum(jnp.max(jnp.sum(jnp.abs(W), axis=-1)), jnp.finfo(jnp.float64).tiny)

        def iterate(state, _):
            Wt, _, _ = state
            dW, G, moved = self._iterate(W, h, Wt)
            return (G, dW, moved), None

        (Wt, dW, moved), _ = jax.lax.scan(iterate, (W + D, jnp.zeros_like(W), jnp.asarray(jnp.inf)), None,
                                          length=self.iterations)
        return jnp.where(moved <= scale, dW, jnp.nan), Wt - W

    # -- a learned map --------------------------------------------------------------------------
    def hyperparameters(self) -> dict[str, Any]:
        reference = self.spectrum.reference if isinstance(self.spectrum, AbstractGaugedSpectrum) else None
        return {"spectrum": self.spectrum.kind, "reference": reference, "rotation": self.rotation is not None,
                "composition": None if self.composition is None else type(self.composition).__name__, "tol": self.tol, "iterations": self.iterations, "max_iter": self.max_iter}

    @classmethod
    def from_hyperparameters(cls, system: AbstractPoissonSystem, hyperparameters: dict[str, Any], *,
                             key: Any = 0, h: float | None = None) -> StreamOperator:
        hp = dict(hyperparameters)
        if "order" in hp:  # files of 527b794..: an order named the composition
            hp["composition"] = {2: None, 4: "Suzuki", 6: "Yoshida6"}[hp.pop("order")]
        rotation = 0.0 if hp.pop("rotation", False) else None
        spectrum = spectrum_of(hp.pop("spectrum", "degree"), system.N)
        reference = hp.pop("reference", None)
        if reference is not None:  # the gauge's position; its value is a weight, read with the others
            spectrum = type(spectrum)(spectrum.values(), reference + (1 if spectrum.kind == "degree" else 0))
        return cls(system, spectrum, rotation=rotation, h=h, **hp)

    def reinitialised(self, key: int | jax.Array) -> StreamOperator:
        """The map itself: its parameters have no random start."""
        return self

    def default_optimiser(self) -> tuple[AbstractStage, ...]:
        """Levenberg-Marquardt, 50 steps (a few parameters; forward-mode Jacobian), for
        `learn.fit` on pairs; on observations of large fields use `learn.fit_stream_operator`."""
        from .._solvers._levenberg_marquardt import LevenbergMarquardt
        from .._solvers._stage import KeepIfBetter

        return (KeepIfBetter(LevenbergMarquardt(50)),)
