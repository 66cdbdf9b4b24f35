r"""The data-driven splitting recipe: a G-LPNet is a splitting of a learned Hamiltonian
$\widetilde H = \sum_s\Phi_s(\langle\alpha_s, y\rangle)$; fitted as a Strang splitting,
then composed by a higher-order method and fitted again."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
from numpy.typing import ArrayLike

from integrators import Trajectories
from integrators.splitting import LieTrotter, Strang, TripleJump
from liepoisson.systems import AbstractPoissonSystem

from ._fit import QuasiNewton, fit
from ._glpnet import GLPNet, check_method
from ._record import TrainingRecord


def fit_splitting(
    system: AbstractPoissonSystem,
    data: Trajectories | tuple[ArrayLike, ArrayLike],
    method: Any = TripleJump,
    *,
    iterations: int = 1000,
    key: int | jax.Array = 0,
    h: float | None = None,
    validation_fraction: float = 0.2,
    seed: int = 0,
    progress: bool | None = None,
) -> tuple[GLPNet, Sequence[TrainingRecord]]:
    r"""A G-LPNet for any Poisson system with test flows, as a data-driven splitting method;
    returns `(network, records)`, one `TrainingRecord` per fit.

    1. **Strang.** `GLPNet(system, n, method=Strang, linear_term=True)`: one module per basis
       direction $e_k$ ($n$ = `system.dim`), $\Phi_k' = a_k\sigma(x) + e_kx + b_k$, whose step
       is the Strang splitting of $\widetilde H = \sum_k\Phi_k(c_ky_k)$, order 2. Fitted by
       BFGS (`iterations`) from the identity warm start (`QuasiNewton(..., warm_start=True)`).
    2. **Refit by `method`** (default `integrators.splitting.TripleJump`; `None` stops at
       step 1): the same learned pieces composed by `method`, fitted again by BFGS from there:
       the pieces move from the modified Hamiltonian of the Strang fit to that of the method.
       Both stages are exact Poisson maps for any weights.

    The other arguments are `learn.fit`'s.
    """
    if method is not None:  # a wrong method fails before the first fit
        method = check_method(method)
        if method is LieTrotter:
            raise ValueError("method=LieTrotter would not continue from the Strang fit: the paper's Lie-Trotter "
                             "G-LPNet weighs its Hamiltonian by 1/n_modules; use learn.GLPNet(system) and learn.fit")
        method.check_terms(system.dim, f"a G-LPNet of {system.dim} modules (one per basis direction)")
    net = GLPNet(system, system.dim, key=key, method=Strang, linear_term=True)
    common = {"h": h, "validation_fraction": validation_fraction, "seed": seed, "progress": progress}
    strang, first = fit(net, data, optimiser=QuasiNewton(iterations, "bfgs", warm_start=True), **common)
    if method is None:
        return strang, (first,)
    refit = GLPNet(system, terms=strang.terms, method=method, h=strang.h)
    fitted, second = fit(refit, data, optimiser=QuasiNewton(iterations, "bfgs", warm_start=False), **common)
    return fitted, (first, second)
