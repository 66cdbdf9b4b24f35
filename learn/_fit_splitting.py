r"""The data-driven splitting recipe: a symmetric G-LPNet is a Strang step of a learned
Hamiltonian $\widetilde H = \sum_s\Phi_s(\langle\alpha_s, y\rangle)$; fitted, composed into a
higher-order composition of its own Strang steps, and fitted again."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
from numpy.typing import ArrayLike

from integrators import Trajectories
from integrators.splitting import TripleJump
from liepoisson.systems import AbstractPoissonSystem

from ._fit import QuasiNewton, fit
from ._glpnet import GLPNet, composition_coefficients
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

    1. **Strang.** `GLPNet(system, n, symmetric=True, linear_term=True)`: one module per basis
       direction $e_k$ ($n$ = `system.dim`), $\Phi_k' = a_k\sigma(x) + e_kx + b_k$, whose step
       is the Strang splitting of $\widetilde H = \sum_k\Phi_k(c_ky_k)$, order 2. Fitted by
       BFGS (`iterations`) from the identity warm start (`QuasiNewton(..., warm_start=True)`).
    2. **Composition** (`method`, default `integrators.splitting.TripleJump`; `None` stops at
       step 1): `GLPNet.composed` turns the Strang network into the one network equal to
       `method` of its Strang steps ($3n-2$ modules for `TripleJump`), fitted again by BFGS
       from there. Both stages are exact Poisson maps for any weights.

    Measured on so(4), h = 0.1, 2000 pairs (BENCHMARKS.md): the Strang stage reaches loss 3.0e-12
    (`benchmarks/glpnet_ablation/`; the paper's 2n one-sigmoid modules: 1.9e-8) and the
    TripleJump stage 2.4e-13, max energy error 9.9e-6 over 2000 steps (`benchmarks/any_algebra.py`;
    the classical Strang splitting of the exact H: 2.4e-4). The other arguments are `learn.fit`'s.
    """
    if method is not None:
        composition_coefficients(method)  # a wrong method fails before the first fit
    net = GLPNet(system, system.dim, key=key, symmetric=True, linear_term=True)
    common = {"h": h, "validation_fraction": validation_fraction, "seed": seed, "progress": progress}
    strang, first = fit(net, data, optimiser=QuasiNewton(iterations, "bfgs", warm_start=True), **common)
    if method is None:
        return strang, (first,)
    composed = strang.composed(method)
    fitted, second = fit(composed, data, optimiser=QuasiNewton(iterations, "bfgs", warm_start=False), **common)
    return fitted, (first, second)
