r"""The inverse of an exact test flow: the parameters $\alpha$ that carry $y_0$ to $y_1$.

$\mathbb T(t, \alpha)\,y_0 = y_1$ fixes $\alpha$ only up to the span of the Casimir gradients
at $y_0$ (they span the kernel of $\mathbb B(y_0)$); the solution returned is the one
orthogonal to that span ([the paper](https://arxiv.org/abs/2308.15349), Sec. 4, eqs. (25)
and (26)). Closed forms live beside their flows (`RodriguesFlow.parameters`); this module
holds the generic path, Gauss-Newton, and the checks shared by
`LieAlgebra.coadjoint_flow_parameters` and `AbstractPoissonSystem.test_flow_parameters`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._casimir_values import casimir_scale
from ._validation import nonzero_time, pairs, positive_float, positive_int

Flow = Callable[[jax.Array, jax.Array, jax.Array], jax.Array]

# A pair passes when the flow of the parameters found reproduces y1 to this multiple of rtol
# (relative to the size of the states): Gauss-Newton stalls at round-off amplified by the
# conditioning of the flow, well below it, while a failure leaves an O(|y1 - y0|) residual.
_RESIDUAL_FACTOR = 100.0
# Step lengths tried by the backtracking of Gauss-Newton, longest first.
_STEP_LENGTHS = 0.5 ** np.arange(10.0)


def gauss_newton_parameters(
    flow: Flow,
    mu0: jax.Array,
    mu1: jax.Array,
    t: ArrayLike,
    casimir_gradients: jax.Array,
    *,
    max_iter: int = 30,
) -> jax.Array:
    r"""Solve $\mathrm{flow}(\alpha, t, \mu_0) = \mu_1$ for $\alpha \perp \nabla C_j(\mu_0)$ by
    Gauss-Newton with backtracking ([the paper](https://arxiv.org/abs/2308.15349), Sec. 4,
    eqs. (25) and (26)).

    With $P$ an orthonormal basis of the complement of the Casimir gradients at $\mu_0$,
    $\alpha = P z$ and the iteration $z \leftarrow z - J^+ r(z)$, $r(z) = \mathrm{flow}(Pz, t,
    \mu_0) - \mu_1$, starts at $z = 0$: every test flow has Jacobian $t\,\mathbb B(\mu_0)$ in
    $\alpha$ at $\alpha = 0$, so the first iterate is the least-squares solution of
    $t\,\mathbb B(\mu_0)\,\alpha = \mu_1 - \mu_0$. Each step is the first of $\delta z,
    \delta z/2, \dots$ that lowers $|r|$; near the solution that is the full step and the
    convergence is quadratic. Nothing is checked here: the caller checks the residual.

    **Arguments:**

    - `flow`: `flow(alpha, t, mu)` on one sample, `(n,)`, scalar, `(n,)` -> `(n,)`; traceable.
      Compiled once per flow: pass a `jax.tree_util.Partial` (its function static, its
      arguments traced) or a callable that compares equal between calls (a bound method).
    - `mu0`, `mu1`: `(N, n)`; `t`: a non-zero scalar (either sign).
    - `casimir_gradients`: `(N, k, n)`, the gradients of the Casimirs at `mu0` (`k` may be 0).
    - `max_iter`: number of Gauss-Newton iterations.

    **Returns:** $\alpha$, `(N, n)`, orthogonal to the rows of `casimir_gradients`.
    """
    if not isinstance(flow, jax.tree_util.Partial):
        flow = jax.tree_util.Partial(flow)
    max_iter = positive_int(max_iter, "max_iter")
    return _gauss_newton(
        flow,
        jnp.asarray(mu0, jnp.float64),
        jnp.asarray(mu1, jnp.float64),
        jnp.asarray(t, jnp.float64),
        jnp.asarray(casimir_gradients, jnp.float64),
        max_iter,
    )


@functools.partial(jax.jit, static_argnums=5)
def _gauss_newton(flow, mu0, mu1, t, casimir_gradients, max_iter):
    solve = functools.partial(_gauss_newton_one, flow, t=t, max_iter=max_iter)
    return jax.vmap(solve)(mu0, mu1, casimir_gradients)


def _gauss_newton_one(flow, mu0, mu1, casimir_gradients, *, t, max_iter):
    n, k = mu0.shape[-1], casimir_gradients.shape[-2]
    if k:
        _, _, Vt = jnp.linalg.svd(casimir_gradients, full_matrices=True)
        P = Vt[k:].T  # (n, n - k), orthonormal, orthogonal to every Casimir gradient
    else:
        P = jnp.eye(n, dtype=mu0.dtype)

    def residual(z):
        return flow(P @ z, t, mu0) - mu1

    def step(_, z):
        r = residual(z)
        dz = jnp.linalg.lstsq(jax.jacfwd(residual)(z), r)[0]
        # Backtracking: the first of the steps dz, dz/2, ... that lowers |r| (plain
        # Gauss-Newton diverges from alpha = 0 on strongly stretching flows, e.g. sl(2) at
        # |t alpha| ~ 2); none at the round-off floor: stay. A fixed set, so reverse mode works.
        candidates = z - _STEP_LENGTHS[:, None] * dz
        lower = jnp.sum(jax.vmap(residual)(candidates) ** 2, axis=-1) < jnp.sum(r * r)
        return jnp.where(jnp.any(lower), candidates[jnp.argmax(lower)], z)

    z = jax.lax.fori_loop(0, max_iter, step, jnp.zeros(n - k, dtype=mu0.dtype))
    return P @ z


def check_casimirs_agree(
    a: np.ndarray,
    b: np.ndarray,
    rtol: float,
    casimirs: Callable[[Any], jax.Array],
    gradients: np.ndarray,
    names: tuple[str, str],
    label: Callable[[int], str] = lambda i: f"pair {i}",
) -> None:
    r"""`ValueError` naming the first pair (`label(i)`) of rows `a`, `b` `(N, dim)` whose Casimirs
    differ by more than `rtol` relative to $\max(|\nabla C||y|, |C|)$ (`gradients` at `a`,
    `(N, k, dim)`): no Poisson map, hence no Casimir-preserving step, connects them."""
    if not gradients.shape[-2]:
        return
    C0, C1 = np.asarray(casimirs(a)), np.asarray(casimirs(b))
    # A Casimir change comparable to rtol times |grad C| |y| is round-off-level.
    cscale = np.maximum(casimir_scale(gradients, a), np.abs(C0)) + np.finfo(float).tiny
    bad = np.abs(C1 - C0) > rtol * cscale
    if np.any(bad):
        i, j = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"{label(i)}: Casimir {j} differs between {names[0]} and {names[1]} "
            f"({C0[i, j]:.17g} vs {C1[i, j]:.17g}, relative "
            f"{abs(C1[i, j] - C0[i, j]) / cscale[i, j]:.3g} > rtol = {rtol:g}); no Poisson "
            "map connects them"
        )


def checked_flow_parameters(
    y0: ArrayLike,
    y1: ArrayLike,
    t: ArrayLike,
    rtol: Any,
    *,
    dim: int,
    names: tuple[str, str],
    flow: Flow,
    casimirs: Callable[[Any], jax.Array],
    casimir_gradients: Callable[[Any], jax.Array],
    solve: Callable[[np.ndarray, np.ndarray, float, np.ndarray], jax.Array],
) -> np.ndarray:
    """The validated inverse of a test flow, shared by algebras and systems.

    Checks the input (finite states of one shape `(..., dim)`, `t` finite and non-zero,
    `rtol` > 0), that every Casimir agrees between the states of a pair, calls
    `solve(y0, y1, t, casimir_gradients_at_y0)` on `(N, dim)` rows, and checks that
    `flow(alpha, t, y0)` reproduces `y1`. Errors name the pair by its index over the
    flattened leading axes.
    """
    a, b = pairs(y0, y1, dim, names)
    t = nonzero_time(t)
    rtol = positive_float(rtol, "rtol")
    batch = a.shape[:-1]
    a, b = a.reshape(-1, dim), b.reshape(-1, dim)
    G = np.asarray(casimir_gradients(a))
    check_casimirs_agree(a, b, rtol, casimirs, G, names)
    alpha = np.asarray(solve(a, b, t, G))
    res = np.max(np.abs(np.asarray(flow(alpha, t, a)) - b), axis=-1)
    scale = np.maximum(np.max(np.abs(a), axis=-1), np.max(np.abs(b), axis=-1))
    tol = _RESIDUAL_FACTOR * rtol * np.maximum(scale, np.finfo(float).tiny)
    bad = ~(res <= tol)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ValueError(
            f"pair {i}: found no parameters alpha with flow(alpha, t, {names[0]}) = {names[1]} "
            f"(residual {res[i]:.3g} > {tol[i]:.3g}); Gauss-Newton may fail when |t alpha| is "
            "too large for its start at alpha = 0, and no test flow connects points of "
            "different coadjoint orbits"
        )
    return alpha.reshape(batch + (dim,))
