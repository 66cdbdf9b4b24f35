"""The seeded split of training data into a training and a validation part: one rule for the
one-step pairs of `Trajectories`, for whole `Observations` trajectories, and for `learn`."""

from __future__ import annotations

import numpy as np

from liepoisson.internals import fraction


def validation_split(n: int, validation_fraction: float, seed: int | None, unit: str = "pair") -> tuple[np.ndarray, np.ndarray]:
    """`(training, validation)` indices into `n` items, each sorted: `round(validation_fraction
    * n)` items drawn without replacement by `numpy.random.default_rng(seed)` go to validation.

    **Arguments:** `n` the number of items; `validation_fraction` in [0, 1); `seed` (checked by
    the caller); `unit` names an item in the error raised when no training item is left.
    """
    validation_fraction = fraction(validation_fraction, "validation_fraction")
    n_val = round(validation_fraction * n)
    if n - n_val < 1:
        raise ValueError(f"validation_fraction={validation_fraction} leaves no training {unit} out of {n}")
    if n_val == 0:
        return np.arange(n), np.arange(0)
    perm = np.random.default_rng(seed).permutation(n)
    return np.sort(perm[n_val:]), np.sort(perm[:n_val])
