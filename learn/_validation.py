"""Input checks for `learn`: every message names the argument, the expectation and the value."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from liepoisson.systems import AbstractPoissonSystem


def check_system(system: Any) -> AbstractPoissonSystem:
    """A `liepoisson.systems.AbstractPoissonSystem`."""
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(
            f"system must be a liepoisson.systems.AbstractPoissonSystem; got {type(system).__name__}"
        )
    return system


def positive_float(x: Any, name: str) -> float:
    """A finite, strictly positive Python float."""
    if isinstance(x, bool) or not (
        isinstance(x, numbers.Real) or (isinstance(x, np.ndarray) and x.ndim == 0)
    ):
        raise TypeError(f"{name} must be a positive real number; got {type(x).__name__} {x!r}")
    value = float(x)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be finite and > 0; got {value!r}")
    return value


def positive_int(x: Any, name: str, minimum: int = 1) -> int:
    """An integer >= `minimum`."""
    if isinstance(x, bool) or not isinstance(x, (numbers.Integral, np.integer)):
        if isinstance(x, float) and x.is_integer():
            x = int(x)
        else:
            raise TypeError(f"{name} must be an integer >= {minimum}; got {type(x).__name__} {x!r}")
    if int(x) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {int(x)}")
    return int(x)


def fraction(x: Any, name: str) -> float:
    """A number in [0, 1)."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        raise TypeError(f"{name} must be a number in [0, 1); got {type(x).__name__} {x!r}")
    value = float(x)
    if not (0.0 <= value < 1.0):
        raise ValueError(f"{name} must be in [0, 1); got {value!r}")
    return value


def states(x: Any, name: str, dim: int) -> np.ndarray:
    """A finite float64 array of shape `(..., dim)` (numpy; for host-side preparation)."""
    if isinstance(x, (str, bytes)) or x is None:
        raise TypeError(f"{name} must be an array of shape (..., {dim}); got {type(x).__name__}")
    try:
        arr = np.asarray(x)
    except Exception as err:  # ragged lists and the like
        raise TypeError(f"{name} must be an array of shape (..., {dim}); got {x!r}") from err
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise TypeError(f"{name} must be a real numeric array; got dtype {arr.dtype}")
    if arr.ndim < 1 or arr.shape[-1] != dim:
        raise ValueError(
            f"{name} must have shape (..., {dim}) (last axis = the system's dimension {dim}); "
            f"got shape {arr.shape}"
        )
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(f"{name} must be finite; found {arr[bad]} at index {bad}")
    return arr


def pairs(y0: Any, y1: Any, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Two state arrays of the same shape `(..., dim)`."""
    y0 = states(y0, "y0", dim)
    y1 = states(y1, "y1", dim)
    if y0.shape != y1.shape:
        raise ValueError(f"y0 and y1 must have the same shape; got {y0.shape} and {y1.shape}")
    return y0, y1
