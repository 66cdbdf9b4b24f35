"""The neural ODE peer (`learn.NeuralODE`, an MLP field without structure) as every study runs
it, its size and budget chosen on the training data by one rule (`fit_neural_ode`;
docs/conventions.md, "Peers"):

- **budget**: L-BFGS-B (`learn.ScipyLBFGSB`, 50 correction pairs, kept if it lowers the loss)
  until the training loss falls by less than `RTOL` of itself over 20 iterations, at most
  `iterations` (the study's cap). Not SciPy's BFGS: its inverse-Hessian update is two dense
  n x n products a step, O(n^3) in the ~4,600 weights of a 64 x 64 net, and at 100 iterations
  on W6's data it was far slower and ended far higher in loss (BENCHMARKS.md, "W6: learned maps
  that keep the constraint");
- **size**: every hidden-layer shape of `hidden` (tanh, scalings from the training data: the
  states' mean and spread in, the spread of their finite-difference rates out) fitted so to the
  training trajectories less a held-out `HELD_OUT` of them (whole trajectories, seeded); each
  fitted net rolled out by its own step (`rk4_flow`: its RK4 sub-steps over each interval)
  from every held-out trajectory's first observation over its times
  (`paper._sindy.rollout_error`, SINDy's score); the shape of the lowest mean relative RMS
  error kept and refitted, the same way, to every training trajectory. Never the test.

With one trajectory there is nothing to hold out: the shape is scored on the training rollouts.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import numpy as np

import integrators as it
import learn

from ._sindy import rollout_error

#: The hidden-layer shapes tried by default.
HIDDEN = ((16, 16), (32, 32), (64, 64))
#: The fraction of the training trajectories held out to choose the shape.
HELD_OUT = 0.2
#: L-BFGS-B stops once the loss falls by less than this fraction over 20 iterations (the budget).
RTOL = 1e-9


class NetworkField:
    """A fitted `NeuralODE`'s field with pysindy's `predict` signature, compiled once (LSODA
    calls it thousands of times)."""

    def __init__(self, net: learn.NeuralODE):
        self.net = net
        self.field = jax.jit(lambda y: net.vector_field(y))

    def predict(self, y: np.ndarray) -> np.ndarray:
        return np.asarray(self.field(np.asarray(y, dtype=np.float64)))


def rk4_flow(field: Any, y: np.ndarray, t: np.ndarray, blow_up: float = np.inf, substeps: int = 4) -> np.ndarray:
    """The states of `field.predict` at the times `t` from `y` by `substeps` classical
    Runge-Kutta steps per interval (the neural ODE's own step, its cost bounded whatever the
    field), NaN from where |y| exceeds `blow_up` (`paper._sindy._flow`'s signature)."""
    out = np.full((t.size, y.size), np.nan)
    out[0] = y
    z = np.asarray(y, dtype=np.float64)[None]
    for i, dt in enumerate(np.diff(t)):
        h = dt / substeps
        for _ in range(substeps):
            k1 = field.predict(z)
            k2 = field.predict(z + 0.5 * h * k1)
            k3 = field.predict(z + 0.5 * h * k2)
            k4 = field.predict(z + h * k3)
            z = z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        if not np.all(np.isfinite(z)) or np.linalg.norm(z) > blow_up:
            break
        out[i + 1] = z[0]
    return out


@dataclasses.dataclass(frozen=True)
class NeuralODEChoice:
    """The neural ODE `fit_neural_ode` kept: `net` (fitted to every training trajectory), its
    `hidden` shape, the L-BFGS-B `iterations` it ran, and every shape's held-out rollout error
    (`scores`). Predicts as its field."""

    net: learn.NeuralODE
    hidden: tuple[int, ...]
    iterations: int
    scores: dict[tuple[int, ...], float]
    field: Any = dataclasses.field(repr=False, compare=False, default=None)

    def __post_init__(self):
        object.__setattr__(self, "field", NetworkField(self.net))

    def predict(self, y: np.ndarray) -> np.ndarray:
        return self.field.predict(y)

    def describe(self) -> str:
        scores = ", ".join(f"{'x'.join(map(str, h))}: {e:.3g}" for h, e in self.scores.items())
        return f"hidden {'x'.join(map(str, self.hidden))}, {self.iterations} L-BFGS-B iterations (held-out errors {scores})"


def _check(hidden: Any, iterations: Any) -> tuple[tuple[int, ...], ...]:
    shapes = tuple(tuple(h) for h in hidden) if isinstance(hidden, (tuple, list)) else ()
    if not shapes or any(not h or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in h)
                         for h in shapes):
        raise ValueError(f"hidden must be a non-empty sequence of hidden-layer shapes (sequences of ints >= 1); "
                         f"got {hidden!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise ValueError(f"iterations must be an int >= 1; got {iterations!r}")
    return shapes


def _fit(data: it.Observations, hidden: tuple[int, ...], iterations: int, key: int, seed: int
         ) -> tuple[learn.NeuralODE, int]:
    """One neural ODE of shape `hidden` fitted to `data` by the budget rule; the iterations run."""
    states = np.concatenate(data.states)
    rates = np.concatenate([np.diff(y, axis=0) / np.diff(t)[:, None] for y, t in zip(data.states, data.times)])
    net = learn.NeuralODE(data.system, hidden=hidden, activation="tanh", key=key,
                          input_scaling=(tuple(states.mean(0)), tuple(np.maximum(states.std(0), 1e-12))),
                          output_scaling=((0.0,) * states.shape[1], tuple(np.maximum(rates.std(0), 1e-12))))
    fitted, record = learn.fit(net, data, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(iterations, rtol=RTOL)),
                               validation_fraction=0.0, seed=seed, progress=False)
    return fitted, int(record.stages[-1].iterations)


def fit_neural_ode(data: it.Observations, iterations: int, hidden: Any = HIDDEN, key: int = 0,
                   seed: int = 0) -> NeuralODEChoice:
    """The neural ODE of `data` (an `integrators.Observations`, its trajectory loss with fitted
    starts) by the rule of this module's docstring: the shape of `hidden` whose fit to the
    training trajectories less `HELD_OUT` of them (drawn by `seed`) best follows the held-out
    ones, refitted to all; L-BFGS-B at most `iterations`, stopped at `RTOL`. Weights drawn by
    `key`."""
    shapes = _check(hidden, iterations)
    if len(data) > 1:
        fit_part, held_out = data.split(HELD_OUT, seed=seed)
    else:
        fit_part, held_out = data, data
    scores: dict[tuple[int, ...], float] = {}
    for shape in shapes:
        net, _ = _fit(fit_part, shape, iterations, key, seed) if len(shapes) > 1 else (None, 0)
        scores[shape] = (rollout_error(NetworkField(net), list(held_out.times), list(held_out.states),
                                       flow=functools.partial(rk4_flow, substeps=net.substeps))
                         if net is not None else np.nan)
    best = min(shapes, key=lambda h: (np.nan_to_num(scores[h], nan=np.inf), shapes.index(h)))
    net, ran = _fit(data, best, iterations, key, seed)
    return NeuralODEChoice(net, best, ran, scores)
