r"""The Bayesian information criterion that chooses between fits: the one count of effective
parameters and the one formula, shared by the trajectory fits and the selection of terms."""

from __future__ import annotations

import math
from collections.abc import Sequence

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
