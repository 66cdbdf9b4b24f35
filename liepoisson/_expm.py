r"""$\exp(A)\,v$ to round-off for every $A$: the kernel of the generic coadjoint flow.
Taylor polynomials on vectors for moderate $|A|_1$ (the common case in training), the matrix
exponential by scaling and squaring otherwise."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

from ._samples import COMMON_PATH_ONLY, sample_max

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
    most $64\,\varepsilon\,|A|\,|v|^2$ per call on every path (tested for $|A|$ from 0.3 to
    $10^4$); on non-compact ones the result grows like
    $e^{|A|}$ and overflows to inf beyond $|A| \approx 700$, which rollouts report as a
    divergence.
    """
    norm = jnp.max(jnp.sum(jnp.abs(jax.lax.stop_gradient(A)), axis=-2), axis=-1)
    batch_norm = sample_max(norm)

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
    if COMMON_PATH_ONLY.get():  # under `common_path_first`: NaN makes it take every path
        return jnp.where(batch_norm <= bound, _taylor_action(A, v, m, d, unroll=True), jnp.nan)
    branches = [jax.checkpoint(lambda A, v, m=m, d=d: _taylor_action(A, v, m, d)) for _, m, d in rest]
    branches.append(jax.checkpoint(matrix))
    bounds = jnp.asarray([bound for bound, _, _ in rest], dtype=A.dtype)

    @jax.checkpoint
    def others(A, v):
        return jax.lax.switch(jnp.searchsorted(bounds, batch_norm), branches, A, v)

    return jax.lax.cond(batch_norm <= bound, lambda A, v: _taylor_action(A, v, m, d, unroll=True), others, A, v)


# The common path of `matrix_exponential` under `vmap_samples`: the Taylor polynomial of
# degree 14 for |A|_1 <= 1/2, whose remainder is at most (1/2)^15/15! e^{1/2} = 4e-17 relative
# (below round-off; every term is bounded by e^{1/2}). What a training batch's norms are, and
# what the path saves: BENCHMARKS.md, "Learned maps on matrix algebras".
_MATRIX_BOUND, _MATRIX_DEGREE = 0.5, 14


def _taylor(A: jax.Array) -> jax.Array:
    """The Taylor polynomial of exp(A) of degree `_MATRIX_DEGREE` (Horner: that many products)."""
    eye = jnp.broadcast_to(jnp.eye(A.shape[-1], dtype=A.dtype), A.shape)
    E = eye
    for k in range(_MATRIX_DEGREE, 0, -1):  # I + A (I + A/2 (I + A/3 (...)))
        E = eye + (A @ E) / k
    return E


def matrix_exponential(A: jax.Array) -> jax.Array:
    r"""$\exp(A)$ for `A` `(..., n, n)` (jit, vmap, grad, jvp): to round-off on the Taylor path;
    beyond it as accurate as `jax.scipy.linalg.expm` (less so than `expm_action` at large
    norms: the comment on `_EXPM_NORM`).

    Under `vmap_samples` (the library's training loss, rollout and Poisson defect), the
    largest $|A|_1$ over the batch picks the path for all samples: the Taylor polynomial of
    degree 14 up to 1/2 (14 matrix products, straight-line code), else `jax.scipy.linalg.expm`
    (Pade approximants and squarings: under `vmap` every branch of it is evaluated). Elsewhere
    `jax.scipy.linalg.expm`.
    """
    norm = jnp.max(jnp.sum(jnp.abs(jax.lax.stop_gradient(A)), axis=-2), axis=-1)
    batch_norm = sample_max(norm)
    if batch_norm is None:
        return jsl.expm(A)
    if COMMON_PATH_ONLY.get():  # under `common_path_first`: NaN makes it take every path
        return jnp.where(batch_norm <= _MATRIX_BOUND, _taylor(A), jnp.nan)
    return jax.lax.cond(batch_norm <= _MATRIX_BOUND, _taylor, jax.checkpoint(jsl.expm), A)
