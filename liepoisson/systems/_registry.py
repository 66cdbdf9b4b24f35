"""Rebuild a system from its name and parameters (as stored in data files and models), or check
that a system given by the user matches them."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._abstract_algebra import AbstractLieAlgebra
from .._algebra import LieAlgebra
from .._definitions import algebra_from_definition
from .._jsonable import jsonable
from ._base import AbstractPoissonSystem
from ._charged_particle import ChargedParticle
from ._double_bracket import DoubleBracket
from ._forces import Forced
from ._generalized_rigid_body import GeneralizedRigidBody
from ._heavy_top import HeavyTop
from ._kirchhoff import Kirchhoff
from ._lie_poisson import KIND, LiePoissonSystem
from ._nonholonomic import LiePoissonDAlembert
from ._pendulum import ExtendedPendulum
from ._rigid_body import RigidBody
from ._zeitlin import Zeitlin

SYSTEMS: dict[str, type] = {
    cls.name: cls for cls in (RigidBody, HeavyTop, Kirchhoff, ExtendedPendulum, ChargedParticle, GeneralizedRigidBody, Zeitlin)
}

#: The systems built around another one, by name: the class (its `from_params(params,
#: from_name)` rebuilds the inner system by name), how errors call it, the fields of its params.
_WRAPPERS: dict[str, tuple[type, str, str]] = {
    DoubleBracket.name: (DoubleBracket, "a DoubleBracket", "system, system_params, gamma, metric"),
    Forced.name: (Forced, "a Forced system", "system, system_params, forces"),
    LiePoissonDAlembert.name: (LiePoissonDAlembert, "a LiePoissonDAlembert", "system, system_params, constraints"),
}

# A system given to a loader reproduces the saved Hamiltonian at the probe points to this
# relative tolerance: the same formula evaluated by another code path differs by a few
# roundings per operation, far below 1e-12 for any Hamiltonian of a few dozen operations.
_PROBE_RTOL = 1e-12


def from_name(name: str, params: dict[str, Any] | None = None) -> AbstractPoissonSystem:
    """`from_name("RigidBody", {"inertia": [1, 2, 3]})` -> `RigidBody(inertia=[1, 2, 3])`; a user
    `LiePoissonSystem` is rebuilt from the definition in its `params` (`params["kind"]`)."""
    if isinstance(params, dict) and params.get("kind") == KIND:
        return LiePoissonSystem.from_params(name, params)
    if name in _WRAPPERS:
        cls, what, fields = _WRAPPERS[name]
        if not isinstance(params, dict):
            raise ValueError(f"{what} is rebuilt from its params ({fields}); got {params!r}")
        return cls.from_params(params, from_name)
    if name not in SYSTEMS:
        raise ValueError(
            f"unknown system {name!r}; known systems are {sorted(SYSTEMS)}, DoubleBracket, Forced, LiePoissonDAlembert and user LiePoissonSystems "
            "(saved with their definition). For a system class of your own, pass system=... to the loader"
        )
    return SYSTEMS[name](**(params or {}))


def same_algebra(a: AbstractLieAlgebra, b: AbstractLieAlgebra) -> bool:
    """Equal definitions: the same kind and sign, the same structure constants or matrix family."""
    if type(a) is not type(b) or a.sign != b.sign:
        return False
    if isinstance(a, LieAlgebra):
        return a.structure_constants.shape == b.structure_constants.shape and bool(
            np.array_equal(a.structure_constants, b.structure_constants))
    return a.definition() == b.definition()


def check_system_matches(system: AbstractPoissonSystem, name: str, params: dict[str, Any], where: str) -> None:
    """`ValueError` unless `system` is the system saved as `(name, params)` in `where` (a file).

    A user `LiePoissonSystem` matches when its algebra (structure constants, sign) is the same
    and its Hamiltonian reproduces the saved values at the saved probe points; any other system
    when its name and parameters are equal."""
    saved = f"{name}" if not isinstance(params, dict) or params.get("kind") == KIND else f"{name}({params})"
    prefix = f"system {system!r} does not match {where}, written for {saved}"
    if system.name != name:
        raise ValueError(f"{prefix}: the names differ ({system.name!r} vs {name!r})")
    if isinstance(params, dict) and params.get("kind") == KIND:
        if not isinstance(system, LiePoissonSystem):
            raise ValueError(f"{prefix}: the file holds a LiePoissonSystem, got a {type(system).__name__}")
        try:
            algebra = params["algebra"]
            saved = algebra_from_definition(algebra, f"{where}: the algebra")
            y = np.asarray(params["probes"]["y"], dtype=np.float64)
            H = np.asarray(params["probes"]["H"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"{where} holds a damaged system definition: {type(err).__name__}: {err}") from err
        if not same_algebra(saved, system.algebra):
            raise ValueError(f"{prefix}: the algebras differ (structure constants or sign)")
        mine = np.asarray(system.hamiltonian(y))
        if not np.allclose(mine, H, rtol=_PROBE_RTOL, atol=_PROBE_RTOL * float(np.max(np.abs(H), initial=1.0))):
            k = int(np.argmax(np.abs(mine - H)))
            raise ValueError(
                f"{prefix}: the Hamiltonians differ (at the saved probe point {y[k].round(4).tolist()} the "
                f"file has H = {H[k]!r}, the given system {mine[k]!r})"
            )
        return
    if jsonable(system.params) != jsonable(params):
        raise ValueError(f"{prefix}: the parameters differ ({system.params} vs {params})")


def system_for_file(name: str, params: dict[str, Any], system: AbstractPoissonSystem | None, where: str) -> AbstractPoissonSystem:
    """The system saved in `where` as `(name, params)`: rebuilt (`from_name`) when `system` is
    None, else `system` itself after `check_system_matches`. `ValueError` naming `where`."""
    if system is None:
        try:
            return from_name(name, params)
        except (ValueError, TypeError) as err:
            raise ValueError(f"{where}: cannot rebuild the system: {err}") from err
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem or None; got {type(system).__name__}")
    check_system_matches(system, name, params, where)
    return system
