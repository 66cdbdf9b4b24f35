"""A small closed family of behaviours chosen by the user (a noise law, a rollout's non-finite
policy): stateless classes, equal when of the same class, each also spelled by its `name` at
the public boundary."""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, ClassVar, TypeVar

Choice = TypeVar("Choice", bound="AbstractChoice")


@dataclasses.dataclass(frozen=True)
class AbstractChoice(abc.ABC):
    """A stateless behaviour; `name` is the string that also selects it."""

    name: ClassVar[str]


def by_name(value: Any, choices: dict[str, Choice], base: type[Choice], argument: str) -> Choice:
    """`value` if it is a `base`, else the member of `choices` it names; `ValueError` naming
    `argument`, the names and the class otherwise."""
    if isinstance(value, base):
        return value
    if isinstance(value, str) and value in choices:
        return choices[value]
    raise ValueError(f"{argument} must be one of {tuple(choices)} or an integrators.{base.__name__}; got {value!r}")
