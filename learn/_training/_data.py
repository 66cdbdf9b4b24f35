"""Training data: `(y0, y1)` pairs from an `integrators.Trajectories` or from arrays."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from integrators import Trajectories
from integrators.internals import validation_split
from liepoisson.internals import check_casimirs_agree, fraction, pairs, positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem


class PairData:
    """Training and validation pairs with their time step (host-side, numpy)."""

    def __init__(self, train, val, h):
        self.y0, self.y1 = train
        self.y0_val, self.y1_val = val
        self.h = h

    @property
    def has_validation(self) -> bool:
        return self.y0_val.shape[0] > 0


def _split(y0, y1, validation_fraction, seed):
    train, val = validation_split(y0.shape[0], validation_fraction, seed, "pairs")
    return (y0[train], y1[train]), (y0[val], y1[val])


# Pairs whose Casimirs differ by more than this (relative to |grad C| |y|) cannot be joined by a
# Casimir-preserving map: far above the drift of any integrator (heyoka data: ~1e-15), far below
# a mislabelled or mixed-up pair.
CASIMIR_RTOL = 1e-8


def _check_finite(states: Any, name: str, label: Callable[[tuple[int, ...]], str]) -> None:
    """`ValueError` naming the first non-finite state of `states` `(..., dim)` by
    `label(batch index)`; input that is not a float array is left to the shape and type checks
    that follow."""
    try:
        arr = np.asarray(states)
    except (TypeError, ValueError):
        return
    if arr.ndim < 1 or not np.issubdtype(arr.dtype, np.floating) or np.all(np.isfinite(arr)):
        return
    bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
    raise ValueError(
        f"{name} must be finite; found {arr[bad]} at index {bad}: {label(bad[:-1])}, component {bad[-1]}"
    )


def _pair_name(index: tuple[int, ...]) -> str:
    """Pair `index` of `(y0, y1)` arrays as the user indexes them."""
    index = tuple(int(i) for i in index)
    if not index:
        return "the data pair"  # y0, y1 of shape (dim,)
    return f"data pair {index[0] if len(index) == 1 else index}"


def _check_casimirs(system: AbstractPoissonSystem, y0: np.ndarray, y1: np.ndarray, label) -> None:
    if system.n_casimirs:
        G = np.asarray(system.casimir_gradients(y0))
        check_casimirs_agree(y0, y1, CASIMIR_RTOL, system.casimirs, G, ("y0", "y1"), label)


def prepare(data: Trajectories | tuple[ArrayLike, ArrayLike], system: AbstractPoissonSystem, h: float | None,
            validation_fraction: float, seed: int, *, conserves_casimirs: bool = False) -> PairData:
    """Turn `data` into training/validation pairs for `system`: an `integrators.Trajectories`
    (consecutive states; its own split) or a tuple `(y0, y1)` of arrays `(N, dim)` with `h`.
    With `conserves_casimirs` (a model that moves on coadjoint orbits), every pair's Casimirs
    must agree to `CASIMIR_RTOL`; the error names the pair as the user's data indexes it."""
    validation_fraction = fraction(validation_fraction, "validation_fraction")
    seed = positive_int(seed, "seed", minimum=0)
    if isinstance(data, (tuple, list)):
        if len(data) != 2:
            raise ValueError(f"data given as a tuple must be (y0, y1); got {len(data)} entries")
        if h is None:
            raise ValueError("h (the time step between y0 and y1) is required when data is (y0, y1)")
        h = positive_float(h, "h")
        for name, states in zip(("y0", "y1"), data):
            _check_finite(states, name, _pair_name)
        y0, y1 = pairs(data[0], data[1], system.dim)
        batch_shape = y0.shape[:-1]
        y0, y1 = y0.reshape(-1, system.dim), y1.reshape(-1, system.dim)
        if y0.shape[0] == 0:
            raise ValueError("data must contain at least one pair; got 0")
        if conserves_casimirs:
            _check_casimirs(system, y0, y1, lambda i: _pair_name(np.unravel_index(i, batch_shape)))
        train, val = _split(y0, y1, validation_fraction, seed)
        return PairData(train, val, h)
    if not isinstance(data, Trajectories):
        raise TypeError(
            "data must be an integrators.Trajectories or a tuple (y0, y1) of arrays with h=...; "
            f"got {type(data).__name__}"
        )
    data_h = positive_float(data.h, "data.h")
    if h is not None and abs(positive_float(h, "h") - data_h) > 1e-12 * data_h:
        raise ValueError(f"h={h} disagrees with the data's time step data.h={data_h}")
    if data.system.dim != system.dim:
        raise ValueError(
            f"data is for {data.system!r} (dim {data.system.dim}); the model is for {system!r} "
            f"(dim {system.dim})"
        )
    _check_finite(data.states, "data.states", lambda i: f"data trajectory {i[0]}, step {i[1]}")
    if conserves_casimirs:
        n_steps = data.states.shape[1] - 1
        _check_casimirs(system, *data.pairs(),
                        lambda i: f"data trajectory {i // n_steps}, step {i % n_steps} -> {i % n_steps + 1}")
    if validation_fraction > 0:
        (y0, y1), (v0, v1) = data.split(validation_fraction, seed)
        y0, y1 = pairs(y0, y1, system.dim)
        v0, v1 = pairs(v0, v1, system.dim)
        return PairData((y0.reshape(-1, system.dim), y1.reshape(-1, system.dim)),
                        (v0.reshape(-1, system.dim), v1.reshape(-1, system.dim)), data_h)
    y0, y1 = pairs(*data.pairs(), system.dim)
    train, val = _split(y0.reshape(-1, system.dim), y1.reshape(-1, system.dim), validation_fraction, seed)
    return PairData(train, val, data_h)
