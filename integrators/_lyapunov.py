r"""Largest Lyapunov exponent from heyoka's variational equations."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import as_state, check_system, positive_float
from liepoisson.systems import AbstractPoissonSystem

from ._ground_truth import EPS, taylor_integrator


def lyapunov_exponent(
    system: AbstractPoissonSystem,
    y0: ArrayLike,
    t_final: float,
    *,
    renormalization_time: float = 1.0,
    tol: float | None = None,
    seed: int = 0,
    return_history: bool = False,
):
    r"""Largest Lyapunov exponent $\lambda = \lim_{t\to\infty} \tfrac1t\log|\delta y(t)|$ along
    the trajectory from `y0` (Benettin et al. 1980).

    The state transition matrix $\Phi = \partial y(t+\tau)/\partial y(t)$ of each interval of
    length $\tau$ = `renormalization_time` comes from heyoka's first-order variational
    equations (`var_ode_sys`, reset to the identity at the start of each interval). A tangent
    vector $v$ (random unit vector, seeded) is mapped $v\leftarrow\Phi v$, its growth
    $\log|v|$ accumulated and $v$ renormalised, so it never overflows.
    $\lambda \approx \tfrac1{t}\sum_k \log|\Phi_k v_{k}|$ with $t$ the last renormalisation time.

    **Arguments:** `system`; `y0` `(dim,)`; `t_final` > 0; `renormalization_time` > 0; `tol`
    (heyoka, default eps); `seed` of the initial tangent vector.

    **Returns:** $\lambda$ as a float, or with `return_history=True` a tuple
    `(lambda, times, running_estimates)`.
    """
    system = check_system(system)
    y0 = np.asarray(as_state(y0, "y0", system.dim))
    if y0.ndim != 1:
        raise ValueError(f"y0 must have shape ({system.dim},); got {y0.shape}")
    t_final = positive_float(t_final, "t_final")
    tau = positive_float(renormalization_time, "renormalization_time")
    if tau > t_final:
        raise ValueError(f"renormalization_time ({tau}) must not exceed t_final ({t_final})")
    ta = taylor_integrator(system, EPS if tol is None else tol, variational=True)
    dim = system.dim
    identity = np.eye(dim).ravel()
    v = np.random.default_rng(seed).standard_normal(dim)
    v /= np.linalg.norm(v)
    ta.time = 0.0
    ta.state[:dim] = y0
    n_intervals = int(np.floor(t_final / tau + 1e-12))
    log_growth = 0.0
    times = tau * np.arange(1, n_intervals + 1)
    estimates = np.empty(n_intervals)
    for k in range(n_intervals):
        ta.state[dim:] = identity
        outcome = ta.propagate_until(float(times[k]))[0]
        if str(outcome) != str(type(outcome).time_limit):
            raise RuntimeError(f"heyoka stopped at t={ta.time} with outcome {outcome}")
        v = ta.state[dim:].reshape(dim, dim) @ v
        norm = np.linalg.norm(v)
        log_growth += np.log(norm)
        v /= norm
        estimates[k] = log_growth / times[k]
    if return_history:
        return float(estimates[-1]), times, estimates
    return float(estimates[-1])
