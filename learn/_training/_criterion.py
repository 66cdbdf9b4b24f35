r"""The Bayesian information criterion that chooses between fits: the one count of effective
parameters and the one formula, shared by the trajectory fits and the selection of terms."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: Two criteria closer than this are equal: a difference $n\log(\mathrm{SSR}/n)$ cannot tell
#: from none (a relative change of the SSR by 0.1/$n$), such as round-off between two families
#: that give the same map ("quadratic, even" and a selection that kept every term).
BIC_RESOLUTION = 0.1


def effective_parameters(jacobian: np.ndarray) -> int:
    r"""The numerical rank of `jacobian` (residuals x parameters) with each column at unit norm,
    so that the count does not depend on the parameters' units (a time in ms scales the rates'
    columns by 1e3; conventions, [Units][units]); zero columns (parameters nothing moves) do not
    count. A direction that moves the residuals 1e8 times less than the best determined one is
    not fitted by the data (redundant parameters give 0 to round-off)."""
    norms = np.linalg.norm(jacobian, axis=0)
    singular = np.linalg.svd(jacobian[:, norms > 0] / norms[norms > 0], compute_uv=False)
    return int(np.sum(singular > 1e-8 * singular[0])) if singular.size else 0


def bic(ssr: float, n: int, k: int) -> float:
    r"""$n\log(\mathrm{SSR}/n) + k\log n$: `n` residual components, `k` effective parameters."""
    return n * math.log(ssr / n) + k * math.log(n)


def lowest(criteria: Sequence[tuple[float, int]]) -> int:
    """The index of the chosen fit among `(bic, effective parameters)` pairs: the lowest
    criterion, and of those within `BIC_RESOLUTION` of it the one with the fewest effective
    parameters, then the first (so that round-off does not decide between equal fits)."""
    best = min(b for b, _ in criteria)
    return min((k, i) for i, (b, k) in enumerate(criteria) if b <= best + BIC_RESOLUTION)[1]


@dataclasses.dataclass(frozen=True)
class FamilyScore:
    r"""One family fitted by `learn.fit_splitting`: its `family` name, its sum of squared
    residuals `ssr` over `n` observed components, `effective_parameters` $k$, Bayesian
    information criterion `bic` $= n\log(\mathrm{SSR}/n) + k\log n$ and, with held-out
    selection, `held_out_error`: the mean squared prediction error per observed component of
    the held-out trajectories (each refitted fold's map, the held-out trajectory's start fitted
    to its observations with the map held), with `held_out_standard_error` the standard error
    of its difference from the lowest family's over the groups (`None` without held-out
    selection); `substeps`: the sub-steps of each observed interval its map was fitted with,
    where they were chosen from the data (body records, drag families; `None` otherwise)."""

    family: str
    ssr: float
    n: int
    effective_parameters: int
    bic: float
    held_out_error: float | None = None
    held_out_standard_error: float | None = None
    substeps: int | None = None


def family_score(name: str, criterion: dict[str, Any]) -> FamilyScore:
    """The `FamilyScore` of the family `name` from its `information_criterion` (and the
    sub-steps, where measured)."""
    substeps = criterion.get("substeps")
    return FamilyScore(family=name, ssr=float(criterion["ssr"]), n=int(criterion["n"]),
                       effective_parameters=int(criterion["effective_parameters"]), bic=float(criterion["bic"]),
                       substeps=None if substeps is None else int(substeps))


@dataclasses.dataclass(frozen=True)
class SkippedFamily:
    """A family `learn.fit_splitting` did not fit: its `family` name and the `reason` (which
    rule, the figures, and what to pass to fit it anyway)."""

    family: str
    reason: str


@dataclasses.dataclass(frozen=True)
class FamilyChoice:
    r"""How `learn.fit_splitting` chose among families: `chosen` (a family name), by
    `selection` (`"bic"` or `"held-out"`), the `scores` of every family fitted (in fitting order),
    the families `skipped` with their reasons, and for held-out selection the number of
    `folds` and of `groups` (`None`, and no held-out errors, when one family alone was fitted).
    `by_bic` and `by_held_out` name what each criterion chooses (the latter `None` without
    held-out errors)."""

    chosen: str
    selection: str
    scores: tuple[FamilyScore, ...]
    skipped: tuple[SkippedFamily, ...] = ()
    folds: int | None = None
    groups: int | None = None

    def score(self, family: str) -> FamilyScore:
        """The `FamilyScore` of the family named `family`."""
        for s in self.scores:
            if s.family == family:
                return s
        raise KeyError(f"family {family!r} was not fitted; fitted: {[s.family for s in self.scores]}")

    @property
    def by_bic(self) -> str:
        """The family the information criterion chooses (`lowest`)."""
        return self.scores[lowest([(s.bic, s.effective_parameters) for s in self.scores])].family

    @property
    def by_held_out(self) -> str | None:
        """The family held-out prediction chooses (`lowest_held_out`), `None` if not measured."""
        if any(s.held_out_error is None for s in self.scores):
            return None
        return self.scores[lowest_held_out(self.scores)].family


def lowest_held_out(scores: Sequence[FamilyScore]) -> int:
    """The index of the chosen family by held-out prediction: of the families whose held-out
    error is within one standard error (`held_out_standard_error`, of the per-group paired
    difference) of the lowest, the one with the fewest effective parameters, then the first
    fitted (the one-standard-error rule: a difference the held-out groups cannot resolve does
    not buy parameters). A difference below `BIC_RESOLUTION` / $n$ of the lowest error (the
    criterion's resolution, $n$ the observed components) is round-off: two families giving the
    same map tie."""
    best = min(s.held_out_error for s in scores)
    within = [(s.effective_parameters, i) for i, s in enumerate(scores)
              if s.held_out_error - best <= (s.held_out_standard_error or 0.0) + best * BIC_RESOLUTION / s.n]
    return min(within)[1]
