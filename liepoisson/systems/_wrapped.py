r"""Systems made from another Lie-Poisson system and one modification of their own
(`DoubleBracket`: damping; `LiePoissonDAlembert`: constraints; `Forced`: external forces):
what they take unchanged from the system they wrap, and how their params nest its params."""

from __future__ import annotations

import abc
from typing import Any

from ._base import AbstractDefinedByParams, AbstractLiePoissonSystem


class AbstractWrappedSystem(AbstractDefinedByParams):
    r"""A system made from the Lie-Poisson system `system`: its state names, Hamiltonian and
    singular set are `system`'s; it is defined by its params when `system` is, its params
    being `system`'s name and params and its own (`own_params`), from which `from_params`
    rebuilds it (`from_own_params`)."""

    system: AbstractLiePoissonSystem

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.system.state_names

    def hamiltonian_components(self, y, xp):
        return self.system.hamiltonian_components(y, xp)

    def singular(self, y):
        return self.system.singular(y)

    @property
    def singular_reason(self) -> str:  # type: ignore[override]
        return self.system.singular_reason

    def value_key(self) -> tuple[Any, ...] | None:
        """Defined by its params when the wrapped system is (else equal only to itself)."""
        return AbstractDefinedByParams.value_key(self) if self.system.value_key() is not None else None

    @property
    def params(self) -> dict[str, Any]:
        return {"system": self.system.name, "system_params": self.system.params, **self.own_params()}

    @abc.abstractmethod
    def own_params(self) -> dict[str, Any]:
        """The params of the modification (JSON values), beside the wrapped system's."""

    @classmethod
    @abc.abstractmethod
    def from_own_params(cls, system: AbstractLiePoissonSystem, params: dict[str, Any]) -> AbstractWrappedSystem:
        """The system wrapping `system` with the modification of `params` (`own_params`'s keys)."""

    @classmethod
    def from_params(cls, params: dict[str, Any], rebuild) -> AbstractWrappedSystem:
        """The system of `params` (as `params` returns them), the wrapped system rebuilt by
        `rebuild(name, params)`; a `ValueError` naming the class if they are not its."""
        try:
            return cls.from_own_params(rebuild(params["system"], params["system_params"]), params)
        except (KeyError, TypeError) as err:
            raise ValueError(f"not a valid {cls.__name__} definition: {type(err).__name__}: {err}") from err
