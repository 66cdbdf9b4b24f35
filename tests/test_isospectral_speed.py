"""The isospectral midpoint's fast path (issue 64): complex products by Gauss's three real
products, the Cayley transform's increment by block elimination, compensated summation of the
steps (`integrators.Compensated`), and the quflow benchmark's loader."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from benchmarks.zeitlin import casimirs, initial_state, load_quflow
from integrators._products import BLOCK_SIZE, cayley_increment, matmul

EPS = np.finfo(np.float64).eps


def _complex(rng, *shape):
    return rng.normal(size=shape) + 1j * rng.normal(size=shape)


def test_three_real_products_agree_with_the_complex_product():
    rng = np.random.default_rng(0)
    A, B = _complex(rng, 96, 80), _complex(rng, 80, 72)
    exact = np.asarray(A, np.clongdouble) @ np.asarray(B, np.clongdouble)  # 64-bit mantissa: the reference
    bound = (np.abs(A.real) + np.abs(A.imag)) @ (np.abs(B.real) + np.abs(B.imag))
    got = np.asarray(matmul(jnp.asarray(A), jnp.asarray(B)))
    ours = np.abs(got - exact) / bound
    theirs = np.abs(np.asarray(jnp.asarray(A) @ jnp.asarray(B)) - exact) / bound
    # Higham's bound for 3M: |error| <= c n eps (|Ar| + |Ai|)(|Br| + |Bi|) entrywise; a sum of 80
    # random terms rounds like sqrt(80) eps, far inside the bound's n eps: a few eps of it
    assert ours.max() < 4 * EPS
    assert ours.max() < 4 * max(theirs.max(), EPS)  # as accurate as XLA's complex product, to a small factor
    # four real products: each part's error relative to its own |Ar||Br| + |Ai||Bi| (real part) and
    # |Ar||Bi| + |Ai||Br| (imaginary part), a few eps (sqrt(80)-like rounding of the sums)
    four = np.asarray(matmul(jnp.asarray(A), jnp.asarray(B), real_products=4)) - exact
    aa, bb = np.abs(A.real), np.abs(A.imag)
    assert (np.abs(four.real) / (aa @ np.abs(B.real) + bb @ np.abs(B.imag))).max() < 4 * EPS
    assert (np.abs(four.imag) / (aa @ np.abs(B.imag) + bb @ np.abs(B.real))).max() < 4 * EPS
    with pytest.raises(ValueError, match="real_products must be 3"):
        matmul(jnp.asarray(A), jnp.asarray(B), real_products=2)
    # real operands: the plain product; stacks of matrices
    Ar = rng.normal(size=(5, 6))
    assert np.array_equal(np.asarray(matmul(jnp.asarray(Ar), jnp.asarray(Ar.T))), np.asarray(jnp.asarray(Ar) @ Ar.T))
    stack = _complex(rng, 3, 7, 7)
    np.testing.assert_allclose(np.asarray(matmul(jnp.asarray(stack), jnp.asarray(stack))), stack @ stack,
                               atol=16 * EPS * np.abs(stack).max() ** 2 * 7)


def test_three_real_products_differentiate_as_the_product():
    rng = np.random.default_rng(1)
    A, B, dA, dB = (jnp.asarray(_complex(rng, 6, 6)) for _ in range(4))
    _, tangent = jax.jvp(matmul, (A, B), (dA, dB))
    np.testing.assert_allclose(np.asarray(tangent), np.asarray(dA @ B + A @ dB), atol=64 * EPS)
    gradient = jax.grad(lambda A: jnp.sum(jnp.real(matmul(A, B))))(A)
    np.testing.assert_allclose(np.asarray(gradient), np.asarray(jax.grad(lambda A: jnp.sum(jnp.real(A @ B)))(A)),
                               atol=64 * EPS)


# n: LAPACK's solve; two levels of blocks, odd halves. The complex matrix at two levels with
# -m slow (~23 s of the default run's worker time, measured under load): the real one keeps the
# two levels, the complex one the complex arithmetic, by default
@pytest.mark.parametrize(("real", "n"), [(False, BLOCK_SIZE // 2), (True, BLOCK_SIZE // 2), (True, 2 * BLOCK_SIZE + 7),
                                         pytest.param(False, 2 * BLOCK_SIZE + 7, marks=pytest.mark.slow)])
def test_cayley_increment_solves_to_round_off_relative_to_b(real, n):
    rng = np.random.default_rng(2)
    S = rng.normal(size=(n, n)) if real else _complex(rng, n, n)
    B = S - S.conj().T
    B *= 0.3 / np.linalg.norm(B, 2)  # h/2 |B(W)| of a Zeitlin step is ~0.1-0.2
    F = np.asarray(cayley_increment(jnp.asarray(B)))
    exact = np.linalg.solve(np.eye(n) - B, B)  # LAPACK, pivoted: within a few eps of |F| itself
    # relative to |F| (not to |1 + F|): block elimination without pivoting is stable for 1 - B
    # (Hermitian part 1); a few eps times log2(n) levels of blocks
    assert np.abs(F - exact).max() < 32 * EPS * np.abs(exact).max()
    Q = np.eye(n) + 2 * F  # the Cayley transform: unitary to round-off
    assert np.abs(Q.conj().T @ Q - np.eye(n)).max() < 32 * n * EPS


def _carried_matrices(step_map, y0, count, every=100):
    """The carried matrices $W$ of a rollout at steps 0, every, ..., (count - 1) every (a
    rollout's states are rounded through coordinates)."""
    run = jax.jit(lambda c: jax.lax.scan(lambda c, _: (jax.lax.fori_loop(0, every, lambda _, c: step_map.step_carry(c), c),
                                                       c[0]), c, None, length=count))
    return np.asarray(run(step_map.carry(jnp.asarray(y0)))[1])


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_compensated_summation_keeps_the_casimirs_at_round_off():
    z = lp.systems.Zeitlin(8)
    y0 = initial_state(z)
    h = 0.25 * z.hbar

    def drift(compensated):
        method = it.Compensated(it.IsospectralMidpoint(z, h)) if compensated else it.IsospectralMidpoint(z, h)
        Ws = _carried_matrices(method, y0, 30)
        C, scale = casimirs(np.asarray(Ws))  # in extended precision: the drift, not the measurement's round-off
        return (np.abs(C - C[0]) / scale).max()

    plain, compensated = drift(False), drift(True)
    # 2900 steps: the plain sum's rounding (eps |W| a step) walks to ~15 eps (measured 11-17 eps at
    # N = 8 and 16); the compensated one leaves only the increments' round-off (eps |dW|, |dW|
    # ~ 0.1 |W| at h = 0.25 hbar): measured 2-3 eps (with 3M products in the increment)
    assert compensated < plain
    assert compensated < 6 * EPS
    # one compensated step is the plain step (the compensation starts at zero; its increment's
    # products by four real products, not three: the same to a few eps of |W|)
    method = it.Compensated(it.IsospectralMidpoint(z, h))
    c = method.carry(jnp.asarray(y0))
    W = np.asarray(c[0])
    np.testing.assert_allclose(np.asarray(method.step_carry(c)[0]),
                               np.asarray(method.step_map.step_carry(c[:3])[0]),
                               rtol=0, atol=8 * EPS * np.abs(W).max())


def test_compensated_wraps_only_compensable_maps():
    z = lp.systems.Zeitlin(4)
    # a step map without a compensated form (a Runge-Kutta method), and what is not a step map
    with pytest.raises(TypeError, match=r"step_map must be a step map that can run compensated "
                                        r"\(an integrators.AbstractCompensable.*; got RK4\("):
        it.Compensated(it.RK4(z, 0.1))
    with pytest.raises(TypeError, match="integrators.AbstractCompensable.*; got a str"):
        it.Compensated("IsospectralMidpoint")
    with pytest.raises(TypeError, match="compensated"):  # the flag is gone: the wrapper is the variant
        it.IsospectralMidpoint(z, 0.1, compensated=True)


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
@pytest.mark.parametrize("method", [it.IsospectralMidpoint, it.IsospectralTripleJump])
def test_compensated_isospectral_map_is_a_step_map_of_the_wrapped_one(method):
    z = lp.systems.Zeitlin(4)
    inner = method(z, 0.1)
    m = it.Compensated(inner)
    assert isinstance(inner, it.AbstractCompensable) and isinstance(m, it.AbstractStepMap)
    assert m.system is z and m.h == 0.1 and m.label == f"Compensated({method.__name__})"
    assert m.divergence_hint == inner.divergence_hint
    shorter = m.with_h(0.05)
    assert isinstance(shorter, it.Compensated) and shorter.h == 0.05 and type(shorter.step_map) is method
    y0 = initial_state(z)
    # one step from a cold start: the plain step to the round-off of the increments' products
    # (four real products, not three), a few eps of |y| a substep
    plain, one = np.asarray(inner.step(y0)), np.asarray(m.step(y0))
    assert np.abs(one - plain).max() <= 8 * EPS * np.abs(y0).max() * len(method.substeps)
    # a rollout's first step starts its stage iteration elsewhere (warm): the same to the
    # stage's tolerance, 1e-10 of |W| (10x for the substeps and the norms' ratios)
    assert np.abs(np.asarray(m.rollout(y0, 1))[-1] - plain).max() <= 1e-9 * np.abs(y0).max()


def _spectra(Ws: np.ndarray) -> np.ndarray:
    r"""The eigenvalues of $iW$ for each of `Ws` `(n, N, N)`, as Rayleigh quotients in extended
    precision of the float64 eigenvectors: their error is quadratic in the vectors' (eps^2 for
    separated eigenvalues), so a drift of a few eps is measured, not the eigensolver's round-off."""
    iW = 1j * np.asarray(Ws)
    _, V = np.linalg.eigh(iW)
    A, V = np.asarray(iW, np.clongdouble), np.asarray(V, np.clongdouble)
    AV = np.matmul(A, V)
    return (np.sum(V.conj() * AV, axis=-2) / np.sum(V.conj() * V, axis=-2)).real


def test_compensated_midpoint_keeps_the_spectrum_better_over_a_long_run():
    z = lp.systems.Zeitlin(4)
    y0 = initial_state(z)
    h = 0.25 * z.hbar

    def spread(step_map):
        spectra = _spectra(_carried_matrices(step_map, y0, 40))
        return float(np.max(np.abs(spectra - spectra[0])) / np.max(np.abs(spectra[0])))

    plain, compensated = spread(it.IsospectralMidpoint(z, h)), spread(it.Compensated(it.IsospectralMidpoint(z, h)))
    # 3900 steps at N = 4: each plain step rounds W + dW (eps |W|), a random walk of the
    # eigenvalues to several eps (measured 8 eps here, 6-18 over six initial states); the
    # compensated sum leaves the increments' round-off, eps |dW| with |dW| ~ 0.1 |W| at
    # h = 0.25 hbar (0.3-1.1 eps): 10-47 times less, measured; a factor 4 is a margin
    assert 4 * compensated < plain, (plain / EPS, compensated / EPS)


def test_the_benchmark_skips_quflow_cleanly_without_it(tmp_path):
    quflow, why = load_quflow(tmp_path / "nowhere")
    assert quflow is None
    assert "quflow not found" in why and "QUFLOW_PATH" in why and "\n" not in why


def test_the_benchmark_starts_from_quflows_matrix():
    z = lp.systems.Zeitlin(16)
    W = np.asarray(z.algebra.matrix(initial_state(z)))
    quflow, why = load_quflow()
    if quflow is None:
        pytest.skip(why)
    Wq = quflow.shr2mat(quflow.random_shr(lmax=10, seed=42), N=16)
    # the two codes build the quantized harmonics by their own eigen-solvers: they agree to
    # round-off amplified by N (21 eps measured at N = 16); a wrong seed, damping or index would be O(1)
    assert np.abs(W - Wq).max() < 1e-13 * np.abs(Wq).max()
