"""Polynomials in the coordinates of g*, the representation of Casimir functions."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class Polynomial:
    r"""A real polynomial $P(\mu) = \sum_m c_m \mu^m$ in `dim` variables.

    `terms` is a tuple of `(coefficient, exponents)` with `exponents` a tuple of `dim`
    non-negative integers. Evaluation works on components (`mu[0], mu[1], ...`) that may be
    numpy arrays, JAX arrays or heyoka expressions, so one polynomial serves every backend.
    """

    dim: int
    terms: tuple[tuple[float, tuple[int, ...]], ...]

    def __post_init__(self):
        for coef, exps in self.terms:
            if len(exps) != self.dim or any(e < 0 for e in exps):
                raise ValueError(
                    f"Polynomial exponents must be {self.dim} non-negative integers; got {exps}"
                )
            if not np.isfinite(coef):
                raise ValueError(f"Polynomial coefficients must be finite; got {coef}")

    @classmethod
    def from_coefficients(
        cls, dim: int, monomials: Sequence[tuple[int, ...]], coefficients: np.ndarray
    ) -> Polynomial:
        terms = tuple(
            (float(c), tuple(int(e) for e in m))
            for c, m in zip(coefficients, monomials)
            if c != 0.0
        )
        return cls(dim, terms)

    @property
    def degree(self) -> int:
        return max((sum(e) for _, e in self.terms), default=0)

    def evaluate(self, components: Sequence[Any]) -> Any:
        """$P(\\mu)$ from the components of $\\mu$ (any backend)."""
        total = 0.0
        for coef, exps in self.terms:
            term = coef
            for i, e in enumerate(exps):
                if e == 1:
                    term = term * components[i]
                elif e > 1:
                    term = term * components[i] ** e
            total = total + term
        return total

    def derivative(self, i: int) -> Polynomial:
        """$\\partial P / \\partial \\mu_i$."""
        terms = []
        for coef, exps in self.terms:
            if exps[i] > 0:
                new = list(exps)
                new[i] -= 1
                terms.append((coef * exps[i], tuple(new)))
        return Polynomial(self.dim, tuple(terms))

    def gradient(self) -> tuple[Polynomial, ...]:
        return tuple(self.derivative(i) for i in range(self.dim))

    def shifted(self, offset: int, dim: int) -> Polynomial:
        """The same polynomial on a larger space, its variables starting at `offset`."""
        terms = tuple(
            (c, (0,) * offset + e + (0,) * (dim - offset - self.dim)) for c, e in self.terms
        )
        return Polynomial(dim, terms)

    def __mul__(self, other: Polynomial) -> Polynomial:
        acc: dict[tuple[int, ...], float] = {}
        for c1, e1 in self.terms:
            for c2, e2 in other.terms:
                e = tuple(a + b for a, b in zip(e1, e2))
                acc[e] = acc.get(e, 0.0) + c1 * c2
        return Polynomial(self.dim, tuple((c, e) for e, c in acc.items() if c != 0.0))

    def __repr__(self) -> str:
        if not self.terms:
            return "Polynomial(0)"
        parts = []
        for c, e in self.terms:
            mono = "*".join(
                f"mu{i}" if k == 1 else f"mu{i}^{k}" for i, k in enumerate(e) if k > 0
            )
            parts.append(f"{c:+.6g}" + (f"*{mono}" if mono else ""))
        return "Polynomial(" + " ".join(parts) + ")"
