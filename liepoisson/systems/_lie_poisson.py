"""A Lie-Poisson system for any algebra and any Hamiltonian the user writes."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from .._algebra import LieAlgebra
from ._base import AbstractLiePoissonSystem, CollectiveTerm


class LiePoissonSystem(AbstractLiePoissonSystem):
    r"""$\dot\mu = \mathbb{B}(\mu)\nabla H(\mu)$ on $\mathfrak g^*$ for a user algebra and Hamiltonian.

    **Arguments:**

    - `algebra`: a `LieAlgebra`.
    - `hamiltonian`: `hamiltonian(mu, xp)` on the components `mu[0..n-1]`, written with the
      namespace `xp` (`xp.sqrt`, `xp.cos`, ...) so numpy, JAX and heyoka can all evaluate it.
    - `splitting`: optional exactly solvable pieces (`CollectiveTerm`s) for classical splitting.
    """

    def __init__(
        self,
        algebra: LieAlgebra,
        hamiltonian: Callable[[Sequence[Any], Any], Any],
        name: str = "LiePoissonSystem",
        splitting: Sequence[CollectiveTerm] = (),
    ):
        if not isinstance(algebra, LieAlgebra):
            raise TypeError(f"algebra must be a LieAlgebra; got {type(algebra).__name__}")
        if not callable(hamiltonian):
            raise TypeError(f"hamiltonian must be callable (mu, xp) -> H; got {hamiltonian!r}")
        self.algebra = algebra
        self._hamiltonian = hamiltonian
        self.name = str(name)
        self._splitting = tuple(splitting)

    @property
    def params(self):
        return {"algebra": self.algebra.name}

    def hamiltonian_components(self, y, xp):
        return self._hamiltonian(y, xp)

    def hamiltonian_splitting(self):
        if not self._splitting:
            raise ValueError(
                f"{self.name} has no Hamiltonian splitting; pass splitting=[CollectiveTerm(...), ...]"
            )
        return self._splitting
