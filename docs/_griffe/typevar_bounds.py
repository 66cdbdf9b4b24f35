"""A griffe extension for the API pages (loaded by mkdocstrings, see mkdocs.yml): a type
variable private to its module, such as `_Map = TypeVar("_Map", bound=AbstractLearnedMap)` in
`learn.fit`'s signature, is shown as its bound, a public name, instead of a private name the
reader cannot look up. Only the rendering changes; the code is not touched."""

from __future__ import annotations

from typing import Any

import griffe


def _names(annotation: Any) -> list[griffe.ExprName]:
    if isinstance(annotation, griffe.ExprName):
        return [annotation]
    if isinstance(annotation, griffe.Expr):
        return [part for part in annotation.iterate(flat=True) if isinstance(part, griffe.ExprName)]
    return []


def _bound(module: griffe.Module, name: str) -> str | None:
    """The bound of the private TypeVar `name` of `module` (`None` if it is not one)."""
    if not name.startswith("_") or name not in module.members:
        return None
    value = getattr(module.members[name], "value", None)
    if not (isinstance(value, griffe.ExprCall) and str(value.function).split(".")[-1] == "TypeVar"):
        return None
    for argument in value.arguments:
        if isinstance(argument, griffe.ExprKeyword) and argument.name == "bound":
            return str(argument.value).strip("'\"")
    return "object"


class TypeVarBounds(griffe.Extension):
    """Replace the private type variables of every function's signature by their bounds."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        self._visit(pkg)

    def _visit(self, obj: griffe.Object) -> None:
        for member in obj.members.values():
            if member.is_alias:
                continue
            if member.is_function:
                annotations = [p.annotation for p in member.parameters] + [member.returns]
                for name in (n for a in annotations for n in _names(a)):
                    bound = _bound(member.module, name.name)
                    if bound is not None:
                        name.name = bound
            elif member.is_module or member.is_class:
                self._visit(member)
