"""Exact coadjoint flows: Poisson maps, Casimirs to round-off, closed forms == expm, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    ALGEBRAS,
    EPS,
    algebra,
    algebra_names,
    poisson_defect,
    reference_coadjoint_flow,
    slow_except,
    states,
    times,
    vectors,
)
from hypothesis import given
from hypothesis import strategies as st

import liepoisson as lp


def _generic(g: lp.LieAlgebra) -> lp.LieAlgebra:
    """The same algebra without closed forms: matrix exponential of its constants."""
    return lp.LieAlgebra(
        g.structure_constants, casimirs=g.casimir_polynomials, sign=g.sign,
        coadjoint_flow=lp.MatrixExponentialFlow(),
    )


# By default a flow of each kind: se(3)'s closed form, so(3)'s inside the direct sum and the flow of
# an algebra given by its constants alone (generic_so3; sl(2)'s is the same); the rest with -m slow.
FLOW_PATHS = pytest.mark.parametrize("name", slow_except(ALGEBRAS, {"se3", "so3+heisenberg", "generic_so3"}))
# Poisson maps by default: se(3)'s closed form and the generic path (so(3)'s closed form is the rigid
# body's test flow, a Poisson map by default in test_systems.py)
POISSON_PATHS = pytest.mark.parametrize("name", slow_except(ALGEBRAS, {"se3", "generic_so3"}))


# -- Poisson maps -----------------------------------------------------------------------------
@POISSON_PATHS
@given(data=st.data())
def test_coadjoint_flow_is_poisson(name, data):
    g = algebra(name)
    alpha = data.draw(vectors(g.dim), label="alpha")
    mu = data.draw(states(name, g.dim), label="mu")
    t = data.draw(times, label="t")
    # Entries of B are O(|mu|) <= ~10 here; the map's Jacobian is O(exp(|t||alpha|)) for
    # non-compact algebras; 1e-10 leaves room for that growth times round-off.
    defect, size = poisson_defect(("algebra", name), g.coadjoint_flow, g.poisson_tensor, alpha, t, mu)
    assert defect <= 1e-10 * max(1.0, size)


@FLOW_PATHS
@given(data=st.data())
def test_coadjoint_flow_matches_reference_expm(name, data):
    """Every algebra's flow (fast path or not) == scipy expm of t M(alpha) built by loops."""
    g = algebra(name)
    alpha = data.draw(vectors(g.dim), label="alpha")
    mu = data.draw(vectors(g.dim), label="mu")
    t = data.draw(times, label="t")
    ref = reference_coadjoint_flow(g.structure_constants, alpha, t, mu, g.sign)
    got = np.asarray(g.coadjoint_flow(alpha, t, mu))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(ref))))


@algebra_names
def test_flow_generates_the_lie_poisson_vector_field(name):
    """d/dt at t=0 of the flow is B(mu) alpha (central differences, error O(h^2))."""
    g = algebra(name)
    rng = np.random.default_rng(1)
    alpha, mu = rng.standard_normal((2, g.dim))
    h = 1e-5
    fd = (np.asarray(g.coadjoint_flow(alpha, h, mu)) - np.asarray(g.coadjoint_flow(alpha, -h, mu))) / (2 * h)
    np.testing.assert_allclose(fd, np.asarray(g.poisson_tensor(mu)) @ alpha, atol=1e-8)


# -- Casimirs over 10^4 composed flows --------------------------------------------------------
N_COMPOSED = 10_000


def _compose(flow, alphas, t, y0):
    def step(y, a):
        y = flow(a, t, y)
        return y, y

    _, ys = jax.lax.scan(step, jnp.asarray(y0), jnp.asarray(alphas))
    return np.asarray(ys)


# Casimir conservation by 10^4 random flows composed. Each step commits O(eps) relative
# round-off in mu and hence ~ deg * eps * |mu|^deg in a Casimir of degree deg; the errors
# add like a random walk (~ sqrt(N)) but we bound the worst case, linear in N: tolerance
# 4 * N * eps * max_t |mu_t|^deg. A flow that is not exactly isospectral (e.g. a Taylor
# series of too low order, or a sign error in one block) fails by orders of magnitude.
@algebra_names
def test_composed_flows_conserve_casimirs(name):
    g = algebra(name)
    rng = np.random.default_rng(2)
    alphas = rng.uniform(-1, 1, (N_COMPOSED, g.dim))
    mu0 = rng.uniform(-1, 1, g.dim)
    t = 0.05  # keeps sl(2)'s hyperbolic growth moderate over 10^4 steps
    ys = _compose(jax.jit(g.coadjoint_flow), alphas, t, mu0)
    assert np.all(np.isfinite(ys))
    c0 = np.asarray(g.casimirs(mu0))
    cs = np.asarray(g.casimirs(ys))
    assert cs.shape == (N_COMPOSED, g.n_casimirs) and g.n_casimirs >= 1
    degrees = np.array([p.degree for p in g.casimir_polynomials])
    size = np.max(np.abs(ys), axis=-1).max()
    tol = 4 * N_COMPOSED * EPS * np.maximum(size, 1.0) ** degrees
    drift = np.max(np.abs(cs - c0), axis=0)
    assert np.all(drift <= tol), (drift, tol)
    # and the flows did move mu around (not a trivial pass)
    assert np.max(np.abs(ys[-1] - mu0)) > 0.1


# -- closed forms == generic matrix exponential -----------------------------------------------
ANGLES = [0.0, 1e-12, 1e-9, 1e-6, 1e-4, 9.99e-4, 1e-3, 1.001e-3, 0.1, 1.0, np.pi, 3.0, 10.0, 31.0]


# by default zero, both sides of the switch at 1e-3, a half-turn and a large angle; the others
# with -m slow
@pytest.mark.parametrize("fast", ["so3", "so3_spatial", "se3", "so3+heisenberg"])
@pytest.mark.parametrize("angle", slow_except(ANGLES, {0.0, 9.99e-4, 1.001e-3, np.pi, 31.0}))
def test_closed_form_equals_expm(fast, angle):
    """Rodrigues / se(3) formulas against expm on the same constants, to 1e-13 relative,
    across the switch to the Taylor series at angle 1e-3, tiny, zero and large angles."""
    g = algebra(fast)
    gen = _generic(g)
    rng = np.random.default_rng(int(angle * 1e6) % 2**32)
    for _ in range(4):
        alpha = rng.standard_normal(g.dim)
        axis = alpha[:3] / np.linalg.norm(alpha[:3])
        alpha[:3] = angle * axis  # rotation angle |alpha_rot t| with t = 1
        mu = rng.standard_normal(g.dim)
        got = np.asarray(g.coadjoint_flow(alpha, 1.0, mu))
        generic = np.asarray(gen.coadjoint_flow(alpha, 1.0, mu))
        ref = reference_coadjoint_flow(g.structure_constants, alpha, 1.0, mu, g.sign)
        scale = np.max(np.abs(ref))
        # 1e-13: both are backward stable to O(10 eps |angle|); expm of a norm-31 matrix
        # loses about log2(31) squarings' worth of eps.
        np.testing.assert_allclose(got, generic, rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-13 * scale)


def test_zero_rotation_and_zero_time_are_identity():
    for name in ALGEBRAS:
        g = algebra(name)
        mu = np.linspace(-1, 2, g.dim)
        np.testing.assert_array_equal(np.asarray(g.coadjoint_flow(np.zeros(g.dim), 2.0, mu)), mu)
        np.testing.assert_array_equal(np.asarray(g.coadjoint_flow(np.ones(g.dim), 0.0, mu)), mu)


def test_so3_rotation_is_the_literature_rodrigues():
    """so(3) body flow dPi/dt = -alpha x Pi: rotation by angle -|alpha| t about alpha, written
    out with the textbook Rodrigues formula; Pi parallel to alpha is fixed."""
    g = algebra("so3")
    alpha, t = np.array([0.3, -1.2, 0.5]), 0.7
    theta = np.linalg.norm(alpha) * t
    n = alpha / np.linalg.norm(alpha)
    K = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    R = np.eye(3) - np.sin(theta) * K + (1 - np.cos(theta)) * K @ K
    mu = np.array([1.0, 2.0, -0.5])
    np.testing.assert_allclose(np.asarray(g.coadjoint_flow(alpha, t, mu)), R @ mu, atol=10 * EPS * 3)
    np.testing.assert_allclose(
        np.asarray(g.coadjoint_flow(alpha, t, 2.5 * alpha)), 2.5 * alpha, rtol=4 * EPS
    )
    # spatial convention reverses time
    np.testing.assert_allclose(
        np.asarray(algebra("so3_spatial").coadjoint_flow(alpha, t, mu)), R.T @ mu, atol=10 * EPS * 3
    )


@pytest.mark.slow  # se(3)'s closed form equals expm of its constants by default (test_closed_form_equals_expm)
def test_se3_special_cases():
    """H = b.p: dPi/dt = p x b, dp/dt = 0 (docs/conventions.md); H = A.Pi rotates Pi and p together."""
    g = algebra("se3")
    Pi, p = np.array([0.4, -1.0, 2.0]), np.array([1.5, 0.2, -0.7])
    b, t = np.array([0.3, 0.9, -0.4]), 1.7
    out = np.asarray(g.coadjoint_flow(np.concatenate([np.zeros(3), b]), t, np.concatenate([Pi, p])))
    np.testing.assert_allclose(out, np.concatenate([Pi + t * np.cross(p, b), p]), atol=20 * EPS)
    A = np.array([0.2, -0.5, 0.8])
    out = np.asarray(g.coadjoint_flow(np.concatenate([A, np.zeros(3)]), t, np.concatenate([Pi, p])))
    rot = np.asarray(algebra("so3").coadjoint_flow(A, t, np.stack([Pi, p])))
    np.testing.assert_allclose(out, rot.reshape(-1), atol=20 * EPS)


# -- gradients ---------------------------------------------------------------------------------
# se(3)'s derivative at zero rotation by default in test_gradient_matches_finite_differences
@pytest.mark.parametrize("name", slow_except(["so3", "se3", "sl2", "generic_so3"], {"generic_so3"}))
def test_jacobian_in_alpha_at_zero_is_t_times_B(name):
    """d/d alpha exp(t M(alpha)) mu at alpha = 0 is t dM/dalpha mu = t B(mu) exactly."""
    g = algebra(name)
    mu = np.linspace(-1.0, 1.5, g.dim)
    t = 0.8
    zero = jnp.zeros(g.dim)
    flow = lambda a: g.coadjoint_flow(a, t, mu)
    # forward and reverse mode in one compiled program
    J, Jr = (np.asarray(x) for x in jax.jit(lambda a: (jax.jacfwd(flow)(a), jax.jacrev(flow)(a)))(zero))
    B = np.asarray(g.poisson_tensor(mu))
    np.testing.assert_allclose(J, t * B, atol=8 * EPS)
    np.testing.assert_allclose(Jr, t * B, atol=8 * EPS)
    # second derivative at 0: d^2/dalpha^2 <w, exp(tM)mu> = t^2/2 (M_a M_b + M_b M_a) terms;
    # only finiteness is the point here (the Taylor branch must be differentiable twice)
    if name == "so3":  # the Taylor branch is twice differentiable; rotations keep |mu|^2
        H = np.asarray(jax.jit(jax.hessian(lambda a: jnp.sum(g.coadjoint_flow(a, t, mu) ** 2)))(zero))
        np.testing.assert_allclose(H, 0.0, atol=16 * EPS)


_VALUE_AND_GRAD = {}


def _value_and_grad(name):
    """(a, t, mu, w) -> (<w, flow>, (d/da, d/dt)), jitted once per algebra."""
    if name not in _VALUE_AND_GRAD:
        g = algebra(name)
        _VALUE_AND_GRAD[name] = jax.jit(
            jax.value_and_grad(lambda a, t, mu, w: jnp.dot(w, g.coadjoint_flow(a, t, mu)), argnums=(0, 1))
        )
    return _VALUE_AND_GRAD[name]


@pytest.mark.parametrize("name", ["so3", "se3", "generic_so3"])
@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 9.99e-4, 1.001e-3, 0.5, 3.0])
def test_gradient_matches_finite_differences(name, angle):
    g = algebra(name)
    vg = _value_and_grad(name)
    rng = np.random.default_rng(3)
    alpha = rng.standard_normal(g.dim)
    alpha[:3] *= angle / np.linalg.norm(alpha[:3])
    mu, w = rng.standard_normal((2, g.dim))
    t = 1.0

    def f(a, s=t):
        return float(vg(jnp.asarray(a), s, mu, w)[0])

    _, (grad, gt) = vg(jnp.asarray(alpha), t, mu, w)
    grad = np.asarray(grad)
    assert np.all(np.isfinite(grad))
    h = 1e-6  # central differences: error h^2 |f^(3)| + eps |f| / h ~ 1e-10
    fd = np.array([(f(alpha + h * e) - f(alpha - h * e)) / (2 * h) for e in np.eye(g.dim)])
    np.testing.assert_allclose(grad, fd, atol=1e-8)
    fdt = (f(alpha, t + h) - f(alpha, t - h)) / (2 * h)
    assert abs(float(gt) - fdt) < 1e-8


@pytest.mark.slow  # by default through the closed forms against expm and their gradients at zero angle
def test_rotation_coefficients_against_closed_forms():
    th = np.array([0.0, 1e-8, 1e-5, 9.9e-4, 1.01e-3, 0.3, 2.0, 10.0])
    sinc, c1, c2 = (np.asarray(c) for c in lp.rotation_coefficients(jnp.asarray(th**2)))
    with np.errstate(divide="ignore", invalid="ignore"):
        ref_sinc = np.where(th > 0, np.sin(th) / np.where(th > 0, th, 1), 1.0)
        # series to high order where the closed form cancels
        ref_c1 = np.where(th > 1e-2, (1 - np.cos(th)) / np.where(th > 0, th, 1) ** 2,
                          0.5 - th**2 / 24 + th**4 / 720 - th**6 / 40320)
        ref_c2 = np.where(th > 1e-1, (th - np.sin(th)) / np.where(th > 0, th, 1) ** 3,
                          1 / 6 - th**2 / 120 + th**4 / 5040 - th**6 / 362880 + th**8 / 39916800)
    np.testing.assert_allclose(sinc, ref_sinc, rtol=4 * EPS)
    np.testing.assert_allclose(c1, ref_c1, rtol=8 * EPS)
    # (th - sin th)/th^3 cancels to a relative error ~6 eps/th^2 just above the switch at 1e-3;
    # it only enters multiplied by th^2 (the k x (k x b) term of V), where that is O(eps).
    np.testing.assert_allclose(c2 * th**2, ref_c2 * th**2, rtol=0, atol=8 * EPS)
    rel = np.abs(c2 - ref_c2) / ref_c2
    assert np.all(rel <= 8 * EPS / np.clip(th, 1e-3, 1.0) ** 2), rel
    g = jax.grad(lambda s: sum(lp.rotation_coefficients(s)))(0.0)
    assert np.isfinite(g) and abs(g - (-1 / 6 - 1 / 24 - 1 / 120)) < 1e-15


# -- batching and transformations ------------------------------------------------------------
# the generic path by default; the closed forms are batched in every rollout of many states
@pytest.mark.parametrize("name", slow_except(ALGEBRAS, {"generic_so3"}))
def test_batching_jit_vmap(name):
    g = algebra(name)
    rng = np.random.default_rng(4)
    alpha = rng.standard_normal((2, 3, g.dim))
    mu = rng.standard_normal((2, 3, g.dim))
    t = rng.uniform(-1, 1, (2, 3))
    out = np.asarray(g.coadjoint_flow(alpha, t, mu))
    assert out.shape == (2, 3, g.dim)
    loop = np.array([[np.asarray(g.coadjoint_flow(alpha[i, j], t[i, j], mu[i, j])) for j in range(3)] for i in range(2)])
    np.testing.assert_allclose(out, loop, atol=10 * EPS * np.max(np.abs(loop)))
    # broadcasting a single alpha and scalar t against a batch of mu
    out_b = np.asarray(g.coadjoint_flow(alpha[0, 0], 0.3, mu))
    loop_b = np.array([[np.asarray(g.coadjoint_flow(alpha[0, 0], 0.3, mu[i, j])) for j in range(3)] for i in range(2)])
    np.testing.assert_allclose(out_b, loop_b, atol=10 * EPS * np.max(np.abs(loop_b)))
    jitted = np.asarray(jax.jit(g.coadjoint_flow)(alpha, t, mu))
    np.testing.assert_allclose(jitted, out, atol=10 * EPS * np.max(np.abs(out)))
    vm = np.asarray(jax.vmap(jax.vmap(g.coadjoint_flow))(alpha, t, mu))
    np.testing.assert_allclose(vm, out, atol=10 * EPS * np.max(np.abs(out)))


# -- expm_action: every path against scipy's expm ----------------------------------------------
# 1-norms of A in every band of expm_action's paths (degree 10 up to 1/8, degree 18 up to 1,
# 8 sub-steps up to 8, and beyond 8 the matrix exponential), and near the bounds.
_BAND_NORMS = (0.1, 0.124, 0.2, 0.45, 0.9, 1.8, 3.5, 7.0, 25.0)


_ACTION = jax.jit(lp.vmap_samples(lp.expm_action))
_MATRIX = jax.jit(lp.expm_action)  # not under vmap_samples: always the matrix exponential


@pytest.mark.parametrize("norm", _BAND_NORMS)
def test_expm_action_matches_scipy_on_every_path(norm):
    import scipy.linalg

    rng = np.random.default_rng(int(norm * 100))
    A = rng.normal(size=(10, 6, 6))
    A[:5] -= A[:5].transpose(0, 2, 1)  # rotations (compact algebras) and general matrices
    A *= norm / np.abs(A).sum(axis=-2).max()  # the batch's largest 1-norm is `norm`
    v = rng.normal(size=(10, 6))
    reference = np.stack([scipy.linalg.expm(a) @ x for a, x in zip(A, v)])
    scale = np.abs(reference).max() + np.abs(v).max()
    for fn in (_ACTION, _MATRIX):
        got = np.asarray(fn(jnp.asarray(A), jnp.asarray(v)))
        # Taylor terms bounded by e^|A/m|; at most 8 sub-steps of 18 terms, or 48 squarings for
        # the matrix path at norm 25 (each a few roundings of norm-sized numbers).
        np.testing.assert_allclose(got, reference, rtol=0, atol=256 * EPS * max(1.0, norm) * scale)


@pytest.mark.slow
def test_expm_action_gradients_agree_across_paths():
    # Under vmap_samples the paths differ by the batch's largest norm; derivatives of the
    # small-norm sample must not depend on which path its batch took.
    rng = np.random.default_rng(3)
    A = rng.normal(size=(2, 4, 4)) * 0.05
    big = A.copy()
    big[1] *= 300.0  # the second sample moves the batch onto the matrix path
    v = jnp.asarray(rng.normal(size=(2, 4)))
    w = jnp.asarray(rng.normal(size=4))

    def f(A):
        return lp.vmap_samples(lp.expm_action)(A, v)[0] @ w

    # reverse and forward mode in one compiled program, run on both batches
    both = jax.jit(lambda A: (jax.grad(f)(A), jax.jacfwd(f)(A)))
    (g_small, j_small), (g_big, _) = both(jnp.asarray(A)), both(jnp.asarray(big))
    np.testing.assert_allclose(g_small[0], g_big[0], rtol=0, atol=64 * EPS)
    np.testing.assert_allclose(j_small, g_small, rtol=0, atol=64 * EPS)
    # and both against a central difference of the exact map (truncation ~ eps^(2/3))
    import scipy.linalg

    def exact(a):
        return scipy.linalg.expm(a) @ np.asarray(v[0]) @ np.asarray(w)

    d = np.zeros((4, 4)); d[1, 2] = 1.0
    step = 1e-5
    fd = (exact(A[0] + step * d) - exact(A[0] - step * d)) / (2 * step)
    np.testing.assert_allclose(float(g_small[0][1, 2]), fd, rtol=1e-8)


# common path (every Adam and quasi-Newton fit of the default run takes it) and beyond it (matrix
# path), both with -m slow: by default the first attempt beyond the bound is rejected and repeated
# on the matrix path in test_common_path_first_on_a_matrix_flow_beyond_the_taylor_bound
@pytest.mark.slow
@pytest.mark.parametrize("scale", (1.0, 300.0))
def test_common_path_first_equals_value_and_grad_of_every_path(scale):
    # The fast attempt must either be exact or be rejected (NaN) and repeated: the result is
    # that of jax.value_and_grad through the full expm_action, on either side of the bound.
    rng = np.random.default_rng(5)
    A = jnp.asarray(rng.normal(size=(3, 4, 4)) * 0.02 * scale)
    v = jnp.asarray(rng.normal(size=(3, 4)))

    def loss(A):
        return jnp.sum(jnp.sin(lp.vmap_samples(lp.expm_action)(A, v)))

    calls = []

    def ok(out):
        calls.append(bool(np.isfinite(out[0])))
        return calls[-1]

    fun = lp.common_path_first(jax.value_and_grad(loss), ok)
    value, grad = fun(A)
    ref_value, ref_grad = jax.jit(jax.value_and_grad(loss))(A)
    assert calls == [scale == 1.0]  # the first attempt was rejected exactly when beyond the bound
    again = fun(A)  # after a rejection the fast attempt is not tried again
    assert calls == [scale == 1.0] * (1 if scale != 1.0 else 2)
    np.testing.assert_array_equal(np.asarray(again[1]), np.asarray(grad))
    # the same arithmetic on the common path; beyond it, the same path as the reference
    np.testing.assert_allclose(float(value), float(ref_value), rtol=0, atol=16 * EPS)
    np.testing.assert_allclose(np.asarray(grad), np.asarray(ref_grad), rtol=0, atol=16 * EPS * scale)


@pytest.mark.slow  # expm_action's paths against scipy and 10^4 composed generic flows run by default
def test_casimir_drift_of_generic_flows_is_round_off_times_the_generator():
    """Issue 11's bound for large |alpha| on the generic path (compact algebra): the drift of a
    quadratic Casimir is at most 64 eps |t alpha| |mu|^2, on every path of `expm_action`
    (measured: at most 18 eps |t alpha| |mu|^2 for |t alpha| from 0.3 to 1e4)."""
    g = algebra("generic_so3")
    rng = np.random.default_rng(4)
    mu = jnp.asarray(rng.normal(size=(50, 3)))
    flows = (jax.jit(lp.vmap_samples(lambda a, m: g.coadjoint_flow(a, 1.0, m))),
             jax.jit(lambda a, m: g.coadjoint_flow(a, 1.0, m)))
    for size in (0.3, 5.0, 60.0, 1e3, 1e4):  # Taylor, sub-steps, matrix with up to 16 squarings
        alpha = jnp.asarray(rng.normal(size=(50, 3)) * size / np.sqrt(3.0))
        for flow in flows:
            out = np.asarray(flow(alpha, mu))
            drift = np.abs(np.asarray(g.casimirs(out)) - np.asarray(g.casimirs(mu)))[:, 0]
            bound = 64 * EPS * np.linalg.norm(np.asarray(alpha), axis=-1) * np.sum(np.asarray(mu) ** 2, axis=-1)
            assert np.all(drift <= np.maximum(bound, 4 * EPS * np.sum(np.asarray(mu) ** 2, axis=-1)))


@pytest.mark.slow  # zero generators by default in test_zero_rotation_and_zero_time_are_identity
def test_expm_action_degenerate_inputs():
    # zero generator (coinciding points of a pair, alpha = 0): the identity, exactly, on both paths
    v = jnp.asarray(np.random.default_rng(5).normal(size=(4, 5)))
    zero = jnp.zeros((4, 5, 5))
    np.testing.assert_array_equal(np.asarray(_ACTION(zero, v)), np.asarray(v))
    np.testing.assert_array_equal(np.asarray(_MATRIX(zero, v)), np.asarray(v))
    # a non-finite generator gives a non-finite result (rollouts then raise), never a finite guess
    bad = zero.at[1, 0, 0].set(jnp.nan)
    assert not np.all(np.isfinite(np.asarray(_ACTION(bad, v))))


# -- matrix_exponential (matrix algebras' flows): both paths against scipy's expm -------------
@pytest.mark.parametrize("norm", (0.1, 0.49, 0.51, 3.0))
def test_matrix_exponential_matches_scipy_on_both_paths(norm):
    import scipy.linalg

    rng = np.random.default_rng(int(norm * 100))
    A = rng.normal(size=(6, 5, 5)) + 1j * rng.normal(size=(6, 5, 5))
    A[:3] -= np.conj(A[:3].transpose(0, 2, 1))  # anti-Hermitian (u(N)) and general matrices
    A *= norm / np.abs(A).sum(axis=-2).max()  # the batch's largest 1-norm is `norm`
    reference = np.stack([scipy.linalg.expm(a) for a in A])
    for fn in (jax.jit(lp.vmap_samples(lp.matrix_exponential)), jax.jit(lp.matrix_exponential)):
        got = np.asarray(fn(jnp.asarray(A)))
        # Taylor terms bounded by e^{1/2} (14 of them), or Pade and squarings: a few roundings
        # of entries of size e^|A|
        np.testing.assert_allclose(got, reference, rtol=0, atol=64 * EPS * np.exp(norm))
    # under common_path_first's first attempt, beyond the bound: NaN (so that it is repeated)
    from liepoisson._samples import COMMON_PATH_ONLY

    token = COMMON_PATH_ONLY.set(True)
    try:
        first = np.asarray(jax.jit(lp.vmap_samples(lp.matrix_exponential))(jnp.asarray(A)))
    finally:
        COMMON_PATH_ONLY.reset(token)
    assert np.all(np.isnan(first)) == (norm > 0.5)
    if norm <= 0.5:
        np.testing.assert_allclose(first, reference, rtol=0, atol=64 * EPS * np.exp(norm))


@pytest.mark.slow  # the default run's time (7 s); the Taylor path's values and bound by default above
def test_matrix_flow_under_training_keeps_the_spectrum_and_matches_the_eager_flow():
    # An LPNet's step on u(N) inside a compiled, differentiated loss takes the Taylor path; its
    # values and gradients must be the eager flow's (jax.scipy expm, a plain vmap) to round-off,
    # and it keeps the spectrum of iW.
    g = lp.u(6)
    rng = np.random.default_rng(2)
    mu = jnp.asarray(rng.normal(size=(8, g.dim)))
    w = jnp.asarray(rng.normal(size=(8, g.dim)))
    alpha = jnp.asarray(rng.normal(size=(8, g.dim)))
    alpha = alpha * 0.3 / np.abs(np.asarray(g.matrix(alpha))).sum(axis=-2).max()

    def loss(a, vmap):
        return jnp.sum(w * vmap(lambda a, m: g.coadjoint_flow(a, 1.0, m))(a, mu))

    traced = np.asarray(jax.jit(lp.vmap_samples(lambda a, m: g.coadjoint_flow(a, 1.0, m)))(alpha, mu))
    eager = np.asarray(g.coadjoint_flow(alpha, 1.0, mu))
    np.testing.assert_allclose(traced, eager, rtol=0, atol=64 * EPS * np.abs(eager).max())
    np.testing.assert_allclose(np.asarray(g.spectrum(traced)), np.asarray(g.spectrum(mu)), rtol=0,
                               atol=64 * EPS * np.abs(np.asarray(mu)).max())
    taylor = np.asarray(jax.jit(jax.grad(lambda a: loss(a, lp.vmap_samples)))(alpha))
    reference = np.asarray(jax.jit(jax.grad(lambda a: loss(a, jax.vmap)))(alpha))
    assert np.abs(reference).max() > 1.0  # a loss that the flow's parameters move
    np.testing.assert_allclose(taylor, reference, rtol=0, atol=256 * EPS * np.abs(reference).max())


def test_common_path_first_on_a_matrix_flow_beyond_the_taylor_bound():
    # The matrix flow is compiled once per policy: the first attempt (Taylor only, NaN beyond
    # |A|_1 = 1/2) must not be reused by the repeat, which then returns the finite value.
    g = lp.u(3)
    rng = np.random.default_rng(6)
    mu = jnp.asarray(rng.normal(size=(4, g.dim)))
    alpha = jnp.asarray(rng.normal(size=(4, g.dim)))
    alpha = alpha * 3.0 / np.abs(np.asarray(g.matrix(alpha))).sum(axis=-2).max()  # beyond 1/2

    def loss(a):
        return jnp.sum(jnp.sin(lp.vmap_samples(lambda a, m: g.coadjoint_flow(a, 1.0, m))(a, mu)))

    calls = []

    def ok(out):
        calls.append(bool(np.isfinite(out[0])))
        return calls[-1]

    value, grad = lp.common_path_first(jax.value_and_grad(loss), ok)(alpha)
    assert calls == [False]  # the first attempt was beyond the bound, and rejected
    assert np.isfinite(float(value)) and np.all(np.isfinite(np.asarray(grad)))
    eager = float(jnp.sum(jnp.sin(g.coadjoint_flow(alpha, 1.0, mu))))
    np.testing.assert_allclose(float(value), eager, rtol=0, atol=64 * EPS * np.abs(np.asarray(mu)).size)


# -- increments (what a compensated composition adds) -------------------------------------------
def _reference_increment(g, alpha, t, mu):
    """(exp(t M(alpha)) - I) mu at 40 digits (mpmath's expm; M_ad = sign C_abd alpha_b, as
    `reference_coadjoint_flow`), rounded once: independent of the library's closed forms."""
    import mpmath

    with mpmath.workdps(40):
        C = g.structure_constants
        n = g.dim
        M = mpmath.matrix(n, n)
        for a in range(n):
            for d in range(n):
                M[a, d] = g.sign * mpmath.fsum(mpmath.mpf(float(C[a, b, d])) * mpmath.mpf(float(alpha[b]))
                                               for b in range(n))
        E = mpmath.expm(mpmath.mpf(float(t)) * M)
        m = mpmath.matrix([mpmath.mpf(float(x)) for x in mu])
        d = (E - mpmath.eye(n)) * m
        size = mpmath.mnorm(mpmath.mpf(float(t)) * M, "f")
        return np.array([float(x) for x in d]), float(size)


def _parallel_or_zero(dim):
    """alpha = 0, or mu parallel to alpha (the rotation leaves it fixed), or generic pairs."""
    v = vectors(dim)
    return st.one_of(
        st.tuples(st.just(np.zeros(dim)), v),
        st.tuples(v, st.floats(-3.0, 3.0, allow_nan=False)).map(lambda p: (p[0], p[1] * p[0])),
        st.tuples(v, v),
    )


@pytest.mark.parametrize("name", ["so3", "so3_spatial", "se3", "so3+heisenberg", "generic_so3"])
@given(data=st.data())
def test_coadjoint_increment_is_the_flow_minus_the_state_without_its_rounding(name, data):
    g = algebra(name)
    alpha, mu = data.draw(_parallel_or_zero(g.dim), label="alpha, mu")
    t = data.draw(times, label="t")
    increment = np.asarray(g.coadjoint_increment(alpha, t, mu))
    difference = np.asarray(g.coadjoint_flow(alpha, t, mu)) - mu
    reference, size = _reference_increment(g, alpha, t, mu)
    assert np.all(np.isfinite(increment))
    norm = np.linalg.norm(mu)
    # The plain difference carries the rounding of the flow's last sum, eps |mu| a component
    # (and the flow's own few eps |t M| |mu|): 8 eps |mu| (1 + |tM|) holds both.
    assert np.max(np.abs(increment - difference)) <= 8 * EPS * norm * (1 + size)
    # The increment itself: the closed forms (so(3), se(3), a direct sum of them with Heisenberg's)
    # lose a few roundings of terms of size |tM| |mu| and |tM|^2 |mu| (the rotation's second-order
    # part; Heisenberg's flow is the generic difference, exact here: its M^2 = 0 and the sum
    # mu + t M mu is exact to eps |mu|, so it gets the plain bound); generic_so3 is the plain
    # difference, eps |mu|.
    closed_form = name in ("so3", "so3_spatial", "se3")
    bound = 8 * EPS * norm * (size + size**2) if closed_form else 8 * EPS * norm * (1 + size + size**2)
    assert np.max(np.abs(increment - reference)) <= bound
    if not np.any(alpha) or t == 0.0:
        assert not np.any(increment)  # the identity flow adds exactly nothing


def test_coadjoint_increment_refuses_what_coadjoint_flow_refuses():
    g = lp.so3()
    with pytest.raises(ValueError, match="alpha"):
        g.coadjoint_increment(np.ones(2), 0.1, np.ones(3))
    with pytest.raises(ValueError, match="mu"):
        g.coadjoint_increment(np.ones(3), 0.1, np.ones(4))
    with pytest.raises(FloatingPointError, match="coadjoint_increment overflowed"):
        lp.sl2().coadjoint_increment(np.array([1e3, 0.0, 0.0]), 1.0, np.ones(3))
