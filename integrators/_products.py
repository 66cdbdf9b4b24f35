r"""Dense complex matrix products in real arithmetic (Gauss's 3M method).

XLA's CPU backend multiplies complex128 matrices several times slower than it multiplies
float64 ones: on the machine of BENCHMARKS.md ("Zeitlin's model") a complex128 N x N product
took 3.7-4.8x the time of the three float64 products that make the same product by Gauss's
method, and 1-3.3x an OpenBLAS ZGEMM. So the isospectral methods form their complex products as

$$(A_r + iA_i)(B_r + iB_i) = (T_1 - T_2) + i\,(T_3 - T_1 - T_2), \quad
T_1 = A_rB_r,\; T_2 = A_iB_i,\; T_3 = (A_r + A_i)(B_r + B_i),$$

three real products for four (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd
ed., Sec. 23.2.4: normwise stable, $|\hat C - C| \lesssim c\,n\,\varepsilon\,
(|A_r| + |A_i|)(|B_r| + |B_i|)$ entry by entry, a few eps of the product's norm). Plain `jax`
operations: compiled, batched and differentiable (forward and reverse) like `A @ B`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def matmul(A: jax.Array, B: jax.Array, *, real_products: int = 3) -> jax.Array:
    r"""`A @ B` (matrices, or stacks of them `(..., m, k)`, `(..., k, n)`); a complex
    product by Gauss's three real products (module docstring), or by the four of the
    definition (`real_products=4`: each part's error that of a real product, $\varepsilon
    (|A_r||B_r| + |A_i||B_i|)$, where 3M's imaginary part has $(|A_r| + |A_i|)(|B_r| + |B_i|)$:
    what compensated summation of small increments needs), a real one as it is."""
    if real_products not in (3, 4):
        raise ValueError(f"real_products must be 3 (Gauss) or 4; got {real_products!r}")
    if not (jnp.iscomplexobj(A) or jnp.iscomplexobj(B)):
        return A @ B
    dtype = jnp.result_type(A, B)
    A, B = jnp.asarray(A, dtype), jnp.asarray(B, dtype)
    Ar, Ai, Br, Bi = jnp.real(A), jnp.imag(A), jnp.real(B), jnp.imag(B)
    if real_products == 4:
        return jax.lax.complex(Ar @ Br - Ai @ Bi, Ar @ Bi + Ai @ Br)
    T1 = Ar @ Br
    T2 = Ai @ Bi
    T3 = (Ar + Ai) @ (Br + Bi)
    return jax.lax.complex(T1 - T2, T3 - T1 - T2)


#: Below this size `cayley_increment` solves with LAPACK (an LU with pivoting); above it, it
#: splits the matrix in two and recurses (BLOCK_SIZE measured: BENCHMARKS.md, "Zeitlin's model").
BLOCK_SIZE = 64


def cayley_increment(B: jax.Array) -> jax.Array:
    r"""$(1 - B)^{-1} - 1 = (1 - B)^{-1}B$ for a skew-Hermitian (real skew-symmetric) `B`
    `(..., n, n)`, to round-off relative to $B$ (not to 1: the Cayley transform
    $(1 - B)^{-1}(1 + B) = 1 + 2\,\mathrm{cayley\_increment}(B)$ then has its increment as
    accurate as $B$ is, what compensated summation of the steps needs).

    By block elimination, recursively: with $B = \begin{pmatrix}B_{11} & B_{12}\\ B_{21} &
    B_{22}\end{pmatrix}$, $F_{11}$ the increment of $B_{11}$ and $X_{11} = 1 + F_{11}$, the
    Schur complement of $1 - B$ is $1 - B'$, $B' = B_{22} + B_{21}X_{11}B_{12}$, whose
    increment $F'$ gives

    $$F = \begin{pmatrix}F_{11} + U T V & U T\\ T V & F'\end{pmatrix}, \quad
    U = X_{11}B_{12},\; V = B_{21}X_{11},\; T = 1 + F':$$

    six products of half size, so the whole costs about one product of size $n$ (`matmul`, in
    real arithmetic), where LAPACK's LU and triangular solves on CPU cost several. No
    pivoting: $1 - B$ has Hermitian part $1$, and so has every Schur complement (hence
    $\|(1 - B')^{-1}\|_2 \le 1$): elimination without pivoting is stable for it (Golub & Van
    Loan, *Matrix Computations*, 4th ed., Sec. 4.4.1). Below `BLOCK_SIZE`, LAPACK's solve.
    """
    n = B.shape[-1]
    if n <= BLOCK_SIZE:
        eye = jnp.eye(n, dtype=B.dtype)
        return jnp.linalg.solve(eye - B, B)
    m = n // 2
    B11, B12, B21, B22 = B[..., :m, :m], B[..., :m, m:], B[..., m:, :m], B[..., m:, m:]
    F11 = cayley_increment(B11)
    U = B12 + matmul(F11, B12)  # X11 B12
    V = B21 + matmul(B21, F11)  # B21 X11
    F2 = cayley_increment(B22 + matmul(B21, U))
    UT = U + matmul(U, F2)
    TV = V + matmul(F2, V)
    top = jnp.concatenate([F11 + matmul(UT, V), UT], axis=-1)
    bottom = jnp.concatenate([TV, F2], axis=-1)
    return jnp.concatenate([top, bottom], axis=-2)
