"""Algebras rebuilt from their JSON definitions (data sets and models save them)."""

from __future__ import annotations

from typing import Any

from ._abstract_algebra import AbstractLieAlgebra
from ._algebra import LieAlgebra
from ._direct_sum import DirectSum
from ._matrix_algebra import MatrixLieAlgebra


def algebra_from_definition(definition: Any, what: str = "definition") -> AbstractLieAlgebra:
    """The algebra of `algebra.definition()`, of any kind (`MatrixLieAlgebra` or `DirectSum` when
    `definition["kind"]` says so, else `LieAlgebra`); `ValueError` naming `what` for a malformed
    one."""
    if isinstance(definition, dict) and definition.get("kind") == "DirectSum":
        try:
            parts = [algebra_from_definition(d, f"{what}['summands'][{i}]") for i, d in enumerate(definition["summands"])]
            return DirectSum(parts, definition.get("name"))
        except (KeyError, TypeError) as err:
            raise ValueError(f"{what} is not a valid direct sum definition: {type(err).__name__}: {err}") from err
    if isinstance(definition, dict) and definition.get("kind") == "MatrixLieAlgebra":
        try:
            return MatrixLieAlgebra(definition["family"], int(definition["N"]), sign=int(definition["sign"]))
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"{what} is not a valid matrix Lie algebra definition: {type(err).__name__}: {err}") from err
    return LieAlgebra.from_definition(definition, what)
