r"""The Pfaffian of a real antisymmetric matrix, with its first and second derivatives, by
Householder tridiagonalization: the Casimir of so(2k) that the traces of powers miss.

$\mathrm{Pf}(A)^2 = \det A$: the traces $\mathrm{tr}A^{2j}$, $j \le k$, fix $\det A$ but not the
sign of $\mathrm{Pf}(A)$, which tells apart coadjoint orbits of SO(2k) (so(4) = so(3) x so(3):
$\mathrm{Pf}$ is $|a|^2 - |b|^2$ of the two parts, up to a factor), and the gradient of $\det$
vanishes where $\mathrm{Pf} = 0$ while that of $\mathrm{Pf}$ does not.

$A = Q T Q^\top$ with $Q$ a product of Householder reflections and $T$ antisymmetric
tridiagonal (superdiagonal $t_0, \dots, t_{n-2}$), so $\mathrm{Pf}(A) = \det Q\,\mathrm{Pf}(T)
= \det Q\,t_0 t_2\cdots t_{n-2}$ (Parlett & Reid 1970; Wimmer, ACM TOMS 38, 2012), $O(n^3)$.
Derivatives at fixed $Q$ ($\mathrm{Pf}(A) = \det Q\,\mathrm{Pf}(Q^\top A Q)$ for every orthogonal
$Q$): with $dT = Q^\top dA\,Q$, they are those of $\mathrm{Pf}$ at the tridiagonal $T$, in closed
form. $\partial\mathrm{Pf}/\partial T_{ij}$ ($i < j$) is the Pfaffian of $T$ without rows and
columns $i, j$, and $\partial^2\mathrm{Pf}/\partial T_{ij}\partial T_{kl}$ that without $i, j, k,
l$ times $-1$ if the pairs cross ($i < k < j < l$): removing indices splits the tridiagonal $T$
into blocks, each of even length or the minor is 0, whose Pfaffians are products of every other
$t$ (the rest of the matching pairs neighbours, which cross nothing). Polynomials in the $t$'s
with no division: exact where $\mathrm{Pf} = 0$ or a column is already reduced, no NaN. Third
and higher derivatives differentiate through the reduction: exact at generic matrices only.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def _reduce(A: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    r"""`(t, V, det Q)` for antisymmetric `A` `(n, n)`: the superdiagonal of $T = Q^\top A Q$, the
    Householder vectors (row $j$ reduces column $j$; zero rows are no reflection) and $\det Q$."""
    n = A.shape[-1]
    index = jnp.arange(n)

    def reduce(j, state):
        A, V, sign = state
        x = jnp.where(index > j, A[:, j], 0.0)
        squared = x @ x
        reflect = squared > 0  # a column already reduced: no reflection (and no 0/0)
        norm = jnp.sqrt(jnp.where(reflect, squared, 1.0))
        v = x.at[j + 1].add(jnp.where(x[j + 1] >= 0, norm, -norm))  # H x = -+|x| e_{j+1}
        v = jnp.where(reflect, v, 0.0)
        beta = jnp.where(reflect, 2.0 / jnp.where(reflect, v @ v, 1.0), 0.0)
        w = A.T @ v  # H A H = A - beta v w^T + beta w v^T (v^T A v = 0)
        A = A - beta * jnp.outer(v, w) + beta * jnp.outer(w, v)
        return A, V.at[j].set(v), jnp.where(reflect, -sign, sign)

    A, V, sign = jax.lax.fori_loop(0, max(n - 2, 0), reduce, (A, jnp.zeros_like(A), jnp.asarray(1.0, A.dtype)))
    return jnp.diagonal(A, offset=1), V, sign


def _reflect(V: jax.Array, X: jax.Array, forward: bool) -> jax.Array:
    r"""$Q^\top X Q$ (`forward`) or $Q X Q^\top$ for antisymmetric `X`, $Q = H_0 H_1\cdots$ from
    the Householder vectors `V` (zero rows: no reflection)."""
    n = X.shape[-1]

    def apply(i, X):
        v = V[i if forward else n - 3 - i]
        vv = v @ v
        beta = jnp.where(vv > 0, 2.0 / jnp.where(vv > 0, vv, 1.0), 0.0)
        w = X.T @ v
        return X - beta * jnp.outer(v, w) + beta * jnp.outer(w, v)

    return jax.lax.fori_loop(0, max(n - 2, 0), apply, X)


def _segments(t: jax.Array) -> jax.Array:
    r"""`S` `(n + 1, n + 1)`: `S[s, L]` the Pfaffian of the diagonal block of length `L` starting
    at `s` of the tridiagonal $T$ of superdiagonal `t`: $t_s t_{s+2}\cdots t_{s+L-2}$ for even
    $L$ (1 for $L = 0$), 0 for odd $L$ or past the end. $O(n^2)$."""
    n = t.shape[0] + 1
    s, m = np.arange(n + 1)[:, None], np.arange(n // 2 + 1)[None, :]
    index = s + 2 * m  # the m-th factor of a block from s
    factors = jnp.where(jnp.asarray(index < n - 1), t[np.minimum(index, n - 2)], 0.0)
    products = jnp.concatenate([jnp.ones((n + 1, 1), t.dtype), jnp.cumprod(factors, axis=1)[:, :-1]], axis=1)
    L = np.arange(n + 1)[None, :]
    valid = (L % 2 == 0) & (s + L <= n)
    return jnp.where(jnp.asarray(valid), products[:, np.arange(n + 1) // 2], 0.0)


def _gradient_at_tridiagonal(t: jax.Array) -> jax.Array:
    r"""$\partial\,\mathrm{Pf}(T)/\partial T_{ij}$ above the diagonal, antisymmetric `(n, n)`."""
    n = t.shape[0] + 1
    S = _segments(t)
    i, j = np.triu_indices(n, 1)
    values = S[0, i] * S[i + 1, j - i - 1] * S[j + 1, n - j - 1]
    G = jnp.zeros((n, n), t.dtype).at[i, j].set(values)
    return G - G.T


@jax.custom_jvp
def _gradient(A: jax.Array) -> jax.Array:
    r"""$\partial\,\mathrm{Pf}(A)/\partial A_{ij}$ above the diagonal, antisymmetric `(n, n)`:
    $d\,\mathrm{Pf} = \tfrac12\mathrm{tr}(G^\top dA)$."""
    t, V, sign = _reduce(A)
    return sign * _reflect(V, _gradient_at_tridiagonal(t), forward=False)


@_gradient.defjvp
def _gradient_jvp(primals, tangents):
    (A,), (dA,) = primals, tangents
    t, V, sign = _reduce(A)
    n = A.shape[-1]
    G = sign * _reflect(V, _gradient_at_tridiagonal(t), forward=False)
    dT = _reflect(V, 0.5 * (dA - dA.T), forward=True)
    S = _segments(t)
    a, b, c, d = _quadruples(n)
    # the minor without a < b < c < d, shared by the three pairings of the four indices
    v = S[0, a] * S[a + 1, b - a - 1] * S[b + 1, c - b - 1] * S[c + 1, d - c - 1] * S[d + 1, n - d - 1]
    dG = jnp.zeros((n, n), A.dtype)
    for (p, q), (r, s), sign_pairs in (((a, b), (c, d), 1.0), ((a, d), (b, c), 1.0), ((a, c), (b, d), -1.0)):
        dG = dG.at[p, q].add(sign_pairs * v * dT[r, s]).at[r, s].add(sign_pairs * v * dT[p, q])
    dG = _reflect(V, dG - dG.T, forward=False)
    return G, sign * dG


def _quadruples(n: int) -> tuple[np.ndarray, ...]:
    """All a < b < c < d of `range(n)` whose minor can be nonzero (a, c even; b, d odd):
    a = 2 p, b = 2 q + 1, c = 2 r, d = 2 s + 1 with p <= q < r <= s."""
    k = n // 2
    rows = [(2 * p, 2 * q + 1, 2 * r, 2 * s + 1)
            for p in range(k) for q in range(p, k) for r in range(q + 1, k) for s in range(r, k)]
    return tuple(np.asarray(x, dtype=np.int32) for x in zip(*rows)) if rows else (np.zeros(0, np.int32),) * 4


def _value(A: jax.Array) -> jax.Array:
    t, _, sign = _reduce(A)
    return sign * jnp.prod(t[0::2])


@jax.custom_jvp
def _pfaffian(A: jax.Array) -> jax.Array:
    return _value(A)


@_pfaffian.defjvp
def _pfaffian_jvp(primals, tangents):
    (A,), (dA,) = primals, tangents
    return _value(A), 0.5 * jnp.sum(_gradient(A) * dA)


def pfaffian(A: jax.Array) -> jax.Array:
    r"""$\mathrm{Pf}(A)$ for real antisymmetric `A` `(..., n, n)`, $n$ even (of
    $(A - A^\top)/2$); first and second derivatives exact everywhere (module docstring)."""
    A = jnp.asarray(A)
    n = A.shape[-1]
    if A.ndim < 2 or A.shape[-2] != n or n % 2:
        raise ValueError(f"the Pfaffian is defined for square matrices of even size; got shape {A.shape}")
    flat = 0.5 * (A - jnp.swapaxes(A, -1, -2)).reshape((-1, n, n))
    return jax.vmap(_pfaffian)(flat).reshape(A.shape[:-2])
