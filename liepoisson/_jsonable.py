"""JSON values as they come back from a file: what metadata and parameters are compared as."""

from __future__ import annotations

import json
from typing import Any


def jsonable(value: Any) -> Any:
    """`value` as reading it back from JSON gives it (tuples as lists, keys as strings);
    `TypeError` or `ValueError` from `json` if it is not made of JSON values."""
    return json.loads(json.dumps(value))
