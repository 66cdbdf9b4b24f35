"""Rebuild a system from its name and parameters (as stored in data files)."""

from __future__ import annotations

from typing import Any

from ._base import AbstractPoissonSystem
from ._charged_particle import ChargedParticle
from ._heavy_top import HeavyTop
from ._kirchhoff import Kirchhoff
from ._pendulum import ExtendedPendulum
from ._rigid_body import RigidBody

SYSTEMS: dict[str, type] = {
    cls.name: cls for cls in (RigidBody, HeavyTop, Kirchhoff, ExtendedPendulum, ChargedParticle)
}


def from_name(name: str, params: dict[str, Any] | None = None) -> AbstractPoissonSystem:
    """`from_name("RigidBody", {"inertia": [1, 2, 3]})` -> `RigidBody(inertia=[1, 2, 3])`."""
    if name not in SYSTEMS:
        raise ValueError(f"unknown system {name!r}; known systems are {sorted(SYSTEMS)}")
    return SYSTEMS[name](**(params or {}))
