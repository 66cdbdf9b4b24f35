r"""Exact coadjoint flows $\mu(t) = \exp(t\,\mathbb{M}(\alpha))\,\mu(0)$ of linear Hamiltonians.

Every flow here follows the body convention of DESIGN.md (`sign = -1`):
$\mathbb{M}(\alpha)_{ad} = -C_{abd}\,\alpha_b$, so that $\dot\mu = \mathbb{B}(\mu)\,\alpha$.
`LieAlgebra` converts other signs by reversing time. The generic path is the matrix
exponential; `RodriguesFlow` (so(3)) and `SE3Flow` (se(3)) are closed-form fast paths with
the same interface, tested against it. Each flow also knows its inverse, `parameters`: the
closed form of the shortest rotation for so(3), Gauss-Newton (`gauss_newton_parameters`)
otherwise.
"""

from __future__ import annotations

import abc
import contextvars
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._inverse import gauss_newton_parameters
from ._validation import is_traced

# Below this rotation angle the closed-form coefficients switch to their Taylor series; the
# first neglected term is O(theta^6) < 1e-18, far below round-off.
_SMALL_ANGLE = 1e-3
# Below this ratio |a x b| / (a . b) the shortest rotation's angle/sine uses its series
# (relative error O(r^6) < 1e-24).
_SMALL_RATIO = 1e-4
# |a x b| <= this * |a| |b| with a . b < 0: antiparallel, the rotation axis is not unique.
_ANTIPARALLEL = 1e-8


def _cross(a: jax.Array, b: jax.Array) -> jax.Array:
    return jnp.cross(a, b)


def rotation_coefficients(theta2: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    r"""$(\sin\theta/\theta,\ (1-\cos\theta)/\theta^2,\ (\theta-\sin\theta)/\theta^3)$ from $\theta^2$.

    Safe (finite value and gradient) at $\theta = 0$: the double-`where` keeps the
    unselected branch away from the singular point.
    """
    small = theta2 < _SMALL_ANGLE**2
    t2 = jnp.where(small, 1.0, theta2)
    theta = jnp.sqrt(t2)
    s = jnp.sin(theta)
    half = jnp.sin(0.5 * theta)
    sinc = jnp.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, s / theta)
    c1 = jnp.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, 2.0 * half * half / t2)
    c2 = jnp.where(small, 1.0 / 6.0 - theta2 / 120.0 + theta2**2 / 5040.0, (theta - s) / (t2 * theta))
    return sinc, c1, c2


def rotate(k: jax.Array, v: jax.Array) -> jax.Array:
    r"""$\exp(-\hat k)\,v$: rotation of $v$ by the angle $-|k|$ about $k$ (Rodrigues).

    $\exp(-\hat k) = I - \frac{\sin\theta}{\theta}\hat k + \frac{1-\cos\theta}{\theta^2}\hat k^2$,
    $\theta = |k|$.
    """
    sinc, c1, _ = rotation_coefficients(jnp.sum(k * k, axis=-1))
    kv = _cross(k, v)
    return v - sinc[..., None] * kv + c1[..., None] * _cross(k, kv)


@jax.jit
def _shortest_rotation(a: jax.Array, b: jax.Array) -> jax.Array:
    r"""$\theta\,(a\times b)/|a\times b|$, $\theta = \operatorname{atan2}(|a\times b|, a\cdot b)$:
    the rotation vector $w$ of the shortest rotation, $\exp(\hat w)\,a = b$ for $|a| = |b|$.

    Zero when $a \times b = 0$ and $a\cdot b \ge 0$ (coinciding or zero vectors); the series
    $(1 - r^2/3 + r^4/5)/(a\cdot b)$, $r = |a\times b|/(a\cdot b)$, for small angles, so value
    and gradient stay finite at zero rotation (double `where`). Exactly antiparallel rows also
    give zero: callers reject them first (`_check_not_antiparallel`).
    """
    cross = jnp.cross(a, b)
    s2 = jnp.sum(cross * cross, axis=-1)
    c = jnp.sum(a * b, axis=-1)
    small = (c > 0) & (s2 < (_SMALL_RATIO * c) ** 2)
    degenerate = (s2 == 0) & ~small
    c_small = jnp.where(small, c, 1.0)
    r2 = jnp.where(small, s2, 0.0) / (c_small * c_small)
    s = jnp.sqrt(jnp.where(small | degenerate, 1.0, s2))
    factor = jnp.where(
        small,
        (1.0 - r2 / 3.0 + r2 * r2 / 5.0) / c_small,
        jnp.where(degenerate, 0.0, jnp.arctan2(s, c) / s),
    )
    return factor[..., None] * cross


def _check_not_antiparallel(a: Any, b: Any, names: tuple[str, str]) -> None:
    """`ValueError` naming the first antiparallel pair of rows (skipped for traced values)."""
    if is_traced(a) or is_traced(b):
        return
    a, b = np.asarray(a).reshape(-1, 3), np.asarray(b).reshape(-1, 3)
    s = np.linalg.norm(np.cross(a, b), axis=-1)
    c = np.einsum("ia,ia->i", a, b)
    anti = (s <= _ANTIPARALLEL * np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)) & (c < 0)
    if np.any(anti):
        i = int(np.argmax(anti))
        raise ValueError(
            f"pair {i}: {names[0]} = {a[i].tolist()} and {names[1]} = {b[i].tolist()} are "
            "antiparallel; the rotation axis carrying one to the other is not unique"
        )


class AbstractCoadjointFlow(abc.ABC):
    """How to evaluate $\\exp(t\\,\\mathbb{M}(\\alpha))\\mu$ for one algebra (body convention),
    and its inverse."""

    @abc.abstractmethod
    def __call__(
        self, structure_constants: np.ndarray, alpha: jax.Array, t: jax.Array, mu: jax.Array
    ) -> jax.Array:
        """`alpha`, `mu` of shape `(..., n)` and `t` of shape `(...)`, already broadcast."""

    @abc.abstractmethod
    def parameters(
        self,
        structure_constants: np.ndarray,
        mu0: jax.Array,
        mu1: jax.Array,
        t: ArrayLike,
        casimir_gradients: jax.Array,
    ) -> jax.Array:
        r"""The parameters $\alpha$ with $\exp(t\,\mathbb{M}(\alpha))\,\mu_0 = \mu_1$,
        orthogonal to the Casimir gradients at $\mu_0$ (paper eq. alpha_mod_Casimirs).

        **Arguments:** `mu0`, `mu1` of shape `(N, n)` on one coadjoint orbit; `t` a non-zero
        scalar of either sign (body convention: `LieAlgebra` passes `-sign * t`);
        `casimir_gradients` `(N, k, n)`, the gradients at `mu0` of the algebra's Casimirs in
        its order (a closed form orthogonal to them by construction may ignore them).

        **Returns:** `alpha` `(N, n)` with `self(C, alpha, t, mu0) == mu1`. May raise
        `ValueError` naming a pair whose solution is not unique; otherwise unchecked: use
        `LieAlgebra.coadjoint_flow_parameters`, which validates the input, compares the
        Casimirs of each pair and checks the residual.
        """

    # A flow without state is defined by its type: equal flows share compiled code (the
    # structure constants are an argument). A flow with state compares by identity.
    def __eq__(self, other):
        if self is other:
            return True
        return type(self) is type(other) and not vars(self) and not vars(other)

    def __hash__(self):
        return hash(type(self)) if not vars(self) else id(self)


# `jax.scipy.linalg.expm` is inaccurate for 1-norms above ~5 (its Pade-13 branch: errors of
# 1e-9 at norm 10 for a rotation generator, jax-ml/jax#26802) and slow to compile and
# differentiate. Scale to 1-norm <= 1/2, where the Taylor polynomial of degree 18 is exact to
# 0.5^19/19! < 1e-22 and backward stable (all terms are bounded by e^{1/2}), then square back.
# The squarings run in a loop of static length (masked), so jit and reverse mode work: 6
# checkpointed groups of 8, so that reverse mode stores 6 + 8 iterates instead of 48 (and 48
# masks). With 48 stored, a batch of 2000 6x6 matrices needed a 59 MB buffer: above glibc's
# mmap threshold (32 MB), so it was mapped afresh at every call, and every gradient of a
# program that merely contained this path (an untaken branch of `expm_action`) paid ~570 page
# faults, +25% on an LPNet epoch.
_EXPM_NORM = 0.5
_TAYLOR_DEGREE = 18
_SQUARING_GROUPS, _SQUARINGS_PER_GROUP = 6, 8
_MAX_SQUARINGS = _SQUARING_GROUPS * _SQUARINGS_PER_GROUP


def _squarings(E: jax.Array, s: jax.Array) -> jax.Array:
    """`E` squared `s` times (`s` broadcast against `E`, at most `_MAX_SQUARINGS`)."""

    @jax.checkpoint
    def group(j, E):
        def square_if(i, E):
            return jnp.where(j * _SQUARINGS_PER_GROUP + i < s, E @ E, E)

        return jax.lax.fori_loop(0, _SQUARINGS_PER_GROUP, square_if, E)

    return jax.lax.fori_loop(0, _SQUARING_GROUPS, group, E)


@jax.jit
def _expm(A: jax.Array) -> jax.Array:
    """Matrix exponential of a batch `(m, n, n)` of matrices by scaling and squaring."""
    norm = jax.lax.stop_gradient(jnp.max(jnp.sum(jnp.abs(A), axis=-2), axis=-1))
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / _EXPM_NORM)), 0, _MAX_SQUARINGS)
    X = A * jnp.exp2(-s)[:, None, None]
    eye = jnp.broadcast_to(jnp.eye(A.shape[-1], dtype=A.dtype), A.shape)
    E = eye
    for k in range(_TAYLOR_DEGREE, 0, -1):  # Horner: I + X (I + X/2 (I + X/3 (...)))
        E = eye + (X @ E) / k
    return _squarings(E, s[:, None, None])


# The library maps over samples (training pairs, trajectories) with `vmap_samples`, a `vmap`
# whose axis carries this name. Code under it can take a maximum over the whole batch
# (`lax.pmax`) and branch on it for real: a branch on a per-sample value under a plain `vmap`
# evaluates every branch.
SAMPLE_AXIS = "liepoisson_samples"


def vmap_samples(fun):
    """`jax.vmap(fun)` over the leading axis, named `SAMPLE_AXIS` (see `expm_action`)."""
    return jax.vmap(fun, axis_name=SAMPLE_AXIS)


def _sample_max(x: jax.Array) -> jax.Array | None:
    """`max(x)` over the arrays' axes and the named sample axis (unbatched), or `None` when
    not traced under `vmap_samples`."""
    x = jax.lax.stop_gradient(jnp.max(x))
    try:
        return jax.lax.pmax(x, SAMPLE_AXIS)
    except NameError:  # not under vmap_samples: the maximum would be per sample
        return None


# Paths of exp(A) v = exp(A/m)^m v by Taylor polynomials of degree d on vectors, tried in
# turn for |A|_1 <= bound: (bound, m, d). With theta = |A/m|_1 the remainder of one sub-step
# is at most theta^(d+1)/(d+1)! e^theta relative to |v|: 3e-18 (1/8, 10), 2e-17 (1, 18),
# below round-off; every term is bounded by e^theta |v|. Beyond the last bound, the matrix
# exponential by scaling and squaring. Few paths: each is compiled into every flow of a step
# (a G-LPNet with 6 paths compiled 3x slower than with 3).
# The first path is the common one in training (|h M(alpha)|_1 of 0.03 to 0.13 for an LPNet
# at h = 0.1), unrolled and outside any checkpoint (see `expm_action`).
_ACTION_PATHS = ((0.125, 1, 10), (1.0, 1, 18), (8.0, 8, 18))


def _taylor_action(A: jax.Array, v: jax.Array, m: int, degree: int, unroll: bool = False) -> jax.Array:
    """exp(A) v as m sub-steps of the Taylor polynomial of exp(A/m) of degree `degree`
    (`unroll`: one sub-step as straight-line code)."""
    B = A / m
    if unroll and m == 1:
        term = total = v
        for k in range(1, degree + 1):
            term = jnp.einsum("...ad,...d->...a", B, term) / k
            total = total + term
        return total

    def add_term(k, carry):  # term_k = B term_{k-1} / k (loops, not unrolled: small programs)
        term, total = carry
        term = jnp.einsum("...ad,...d->...a", B, term) / k.astype(B.dtype)
        return term, total + term

    def substep(_, v):
        return jax.lax.fori_loop(1, degree + 1, add_term, (v, v))[1]

    return jax.lax.fori_loop(0, m, substep, v)


# Set while `common_path_first` traces its first attempt (read at trace time by `expm_action`).
_COMMON_PATH_ONLY: contextvars.ContextVar[bool] = contextvars.ContextVar("common_path_only", default=False)


def common_path_first(fun: Callable, ok: Callable[[Any], bool]) -> Callable:
    r"""`jax.jit(fun)` that runs `expm_action` on its common path only, and again with every
    path where that was not enough.

    Under `vmap_samples`, `expm_action` branches on the batch's largest $|A|_1$; reverse mode
    through that branch carries the other paths along (an LPNet epoch on so(4) cost 1.3-1.6x
    the straight-line common path, in the same compiled program). The first attempt is
    compiled with the common path alone, as straight-line code, and gives NaN wherever a
    batch is beyond its bound; when `ok(outputs)` (host values) is false, the call is
    repeated with the full `expm_action` (compiled on first need), and so are all later calls
    (norms beyond the bound tend to stay: without this, a G-LPNet on sl(3) would compute every
    gradient twice). Either way the result is
    that of `jax.jit(fun)`, so `fun` must be a pure function of its arguments, and `ok` must
    reject every output that went through a NaN (e.g. require a finite loss).
    """
    first = jax.jit(lambda *args: fun(*args))  # two function objects: two caches of traces
    every = jax.jit(lambda *args: fun(*args))

    rejected = False

    def call(*args):
        nonlocal rejected
        if rejected:
            return every(*args)
        token = _COMMON_PATH_ONLY.set(True)
        try:
            out = first(*args)
        finally:
            _COMMON_PATH_ONLY.reset(token)
        if ok(out):
            return out
        rejected = True
        return every(*args)

    return call


def expm_action(A: jax.Array, v: jax.Array) -> jax.Array:
    r"""$\exp(A)\,v$ for `A` `(..., n, n)` and `v` `(..., n)`, exact to round-off for every
    $A$ (jit, vmap, grad, jvp).

    Under `vmap_samples` (the library's training loss, rollout and Poisson defect), the
    largest $|A|_1$ over the batch picks the path for all samples: $\exp(A/m)^m v$ by
    Taylor polynomials on vectors (matrix-vector products only; $m = 1$ with degree 10 up to
    1/8, degree 18 up to 1, $m = 8$ up to 8), else the matrix exponential by scaling and
    squaring. Elsewhere
    (a single call, a plain `vmap`) the matrix exponential, whose cost does not depend on $A$.

    Accuracy: on compact algebras ($A$ a rotation generator) a quadratic Casimir drifts by at
    most $64\,\varepsilon\,|A|\,|v|^2$ per call on every path (measured $\le 18$ for
    $|A|$ from 0.3 to $10^4$; tested); on non-compact ones the result grows like
    $e^{|A|}$ and overflows to inf beyond $|A| \approx 700$, which rollouts report as a
    divergence.
    """
    norm = jnp.max(jnp.sum(jnp.abs(jax.lax.stop_gradient(A)), axis=-2), axis=-1)
    batch_norm = _sample_max(norm)

    def matrix(A, v):
        n = A.shape[-1]
        E = _expm(A.reshape((-1, n, n))).reshape(A.shape)
        return jnp.einsum("...ad,...d->...a", E, v)

    if batch_norm is None:
        return matrix(A, v)
    # Reverse mode through a branch stores the residuals of every branch (zeros for those not
    # taken). The common first path keeps its own (12 vectors per sample); the others are
    # rematerialised, each and together, so that their residuals are only (A, v) once: a flat
    # switch of checkpointed paths cost 17% more per gradient when the first path was taken,
    # and the others without their own checkpoint 10x more (zeros for 8 x 18 vectors).
    (bound, m, d), *rest = _ACTION_PATHS
    if _COMMON_PATH_ONLY.get():  # under `common_path_first`: NaN makes it take every path
        return jnp.where(batch_norm <= bound, _taylor_action(A, v, m, d, unroll=True), jnp.nan)
    branches = [jax.checkpoint(lambda A, v, m=m, d=d: _taylor_action(A, v, m, d)) for _, m, d in rest]
    branches.append(jax.checkpoint(matrix))
    bounds = jnp.asarray([bound for bound, _, _ in rest], dtype=A.dtype)

    @jax.checkpoint
    def others(A, v):
        return jax.lax.switch(jnp.searchsorted(bounds, batch_norm), branches, A, v)

    return jax.lax.cond(batch_norm <= bound, lambda A, v: _taylor_action(A, v, m, d, unroll=True), others, A, v)


class MatrixExponentialFlow(AbstractCoadjointFlow):
    r"""Generic path: $\exp(t\,\mathbb{M}(\alpha))\,\mu$ by `expm_action` (Taylor on vectors
    for moderate $|t\,\mathbb M(\alpha)|$ under `vmap_samples`, else scaling and squaring);
    inverse by Gauss-Newton (`gauss_newton_parameters`)."""

    def __call__(self, structure_constants, alpha, t, mu):
        C = jnp.asarray(structure_constants)
        M = -jnp.einsum("abd,...b->...ad", C, alpha)
        return expm_action(t[..., None, None] * M, mu)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        flow = jax.tree_util.Partial(self, structure_constants)
        return gauss_newton_parameters(flow, mu0, mu1, t, casimir_gradients)

    def __repr__(self):
        return "MatrixExponentialFlow()"


class RodriguesFlow(AbstractCoadjointFlow):
    r"""so(3): $\dot\Pi = -\alpha\times\Pi$, the rotation $\Pi(t) = \exp(-t\hat\alpha)\Pi(0)$.

    `parameters` is the closed form of the shortest rotation carrying $\Pi^0$ to $\Pi^1$:
    $t\alpha = -\theta\,(\Pi^0\times\Pi^1)/|\Pi^0\times\Pi^1|$ with $\theta =
    \operatorname{atan2}(|\Pi^0\times\Pi^1|, \Pi^0\cdot\Pi^1)$, so $\alpha\perp\Pi^0$, the
    Casimir gradient (the paper's eq. SO3_A_def with the exact angle instead of
    $\sin\theta$). Zero for coinciding points; `ValueError` for antiparallel ones.
    """

    def __call__(self, structure_constants, alpha, t, mu):
        return rotate(t[..., None] * alpha, mu)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        _check_not_antiparallel(mu0, mu1, ("mu0", "mu1"))
        # exp(-t hat(alpha)) = exp(hat w) for t alpha = -w
        return -_shortest_rotation(mu0, mu1) / t

    def __repr__(self):
        return "RodriguesFlow()"


class SE3Flow(AbstractCoadjointFlow):
    r"""se(3)* with $\mu = (\Pi, p)$, $\alpha = (A, b)$: closed form of
    $\dot\Pi = -A\times\Pi - b\times p$, $\dot p = -A\times p$.

    With $R = \exp(-t\hat A)$ and $V = \int_0^1 \exp(-s\,t\hat A)\,ds
    = I - \frac{1-\cos\theta}{\theta^2}\hat k + \frac{\theta-\sin\theta}{\theta^3}\hat k^2$
    ($k = tA$, $\theta = |k|$): $p(t) = R p$, $\Pi(t) = R\Pi - (t V b)\times p(t)$.
    """

    def __call__(self, structure_constants, alpha, t, mu):
        k = t[..., None] * alpha[..., :3]
        Pi, p = mu[..., :3], mu[..., 3:]
        sinc, c1, c2 = rotation_coefficients(jnp.sum(k * k, axis=-1))
        p_t = p - sinc[..., None] * _cross(k, p) + c1[..., None] * _cross(k, _cross(k, p))
        Pi_r = Pi - sinc[..., None] * _cross(k, Pi) + c1[..., None] * _cross(k, _cross(k, Pi))
        tb = t[..., None] * alpha[..., 3:]
        ktb = _cross(k, tb)
        Vtb = tb - c1[..., None] * ktb + c2[..., None] * _cross(k, ktb)
        return jnp.concatenate([Pi_r - _cross(Vtb, p_t), p_t], axis=-1)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        # One exp(t M(A, b)) has no simple closed-form inverse (`se3_rotation_shear` is a
        # different, two-flow step that has one).
        flow = jax.tree_util.Partial(self, structure_constants)
        return gauss_newton_parameters(flow, mu0, mu1, t, casimir_gradients)

    def __repr__(self):
        return "SE3Flow()"


class DirectSumFlow(AbstractCoadjointFlow):
    """Blockwise flow of a direct sum: each summand keeps its own (fast) path.

    `n_casimirs`, the number of Casimirs of each summand (the algebra's Casimirs are the
    summands' in order, as `direct_sum` builds them), makes the inverse blockwise too; without
    it the inverse is Gauss-Newton on the whole sum.
    """

    def __init__(self, flows, dims, structure_constants, n_casimirs=None):
        self.flows = tuple(flows)
        self.dims = tuple(int(d) for d in dims)
        self.blocks = tuple(np.asarray(c) for c in structure_constants)
        self.n_casimirs = None if n_casimirs is None else tuple(int(k) for k in n_casimirs)

    def __call__(self, structure_constants, alpha, t, mu):
        out, start = [], 0
        for flow, n, C in zip(self.flows, self.dims, self.blocks):
            sl = slice(start, start + n)
            out.append(flow(C, alpha[..., sl], t, mu[..., sl]))
            start += n
        return jnp.concatenate(out, axis=-1)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        k = casimir_gradients.shape[-2]
        if self.n_casimirs is None or sum(self.n_casimirs) != k:
            flow = jax.tree_util.Partial(self, structure_constants)
            return gauss_newton_parameters(flow, mu0, mu1, t, casimir_gradients)
        # Each summand's Casimirs depend on its own block only: the problem separates.
        out, start, row = [], 0, 0
        for flow, n, k, C in zip(self.flows, self.dims, self.n_casimirs, self.blocks):
            sl, rows = slice(start, start + n), slice(row, row + k)
            grads = casimir_gradients[..., rows, sl]
            out.append(flow.parameters(C, mu0[..., sl], mu1[..., sl], t, grads))
            start, row = start + n, row + k
        return jnp.concatenate(out, axis=-1)

    def __repr__(self):
        return f"DirectSumFlow({list(self.flows)})"
