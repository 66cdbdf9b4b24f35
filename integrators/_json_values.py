"""Results as JSON values: what the paper's metrics files and the benchmarks' result files hold."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import jax
import numpy as np


def json_values(value: Any, nan: Any = None) -> Any:
    """`value` as JSON values: mappings (keys as strings) and sequences element by element,
    numpy scalars and arrays as numbers and lists, paths as strings; an infinite float as the
    string "inf" or "-inf" (strict JSON has no such numbers: a diverged rollout's error) and a
    NaN as `nan` (`None`, JSON null: "not measured"; or e.g. the string "nan")."""
    if isinstance(value, Mapping):
        return {str(k): json_values(v, nan) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_values(v, nan) for v in value]
    if isinstance(value, (np.ndarray, jax.Array)):
        return json_values(np.asarray(value).tolist(), nan)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return nan
        return value if math.isfinite(value) else str(value)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, np.generic):  # other numpy scalars (complex, strings)
        return value.item()
    return value
