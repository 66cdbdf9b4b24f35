"""Inverse flows: the parameters alpha carrying mu0 to mu1 (closed forms and Gauss-Newton),
for every algebra and every system, and the se(3) rotation-then-shear step."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    ALGEBRAS,
    EPS,
    algebra,
    algebra_names,
    slow_except,
    system,
    system_names,
    vectors,
)
from hypothesis import assume, given
from hypothesis import strategies as st

import liepoisson as lp

# One batch size for every Gauss-Newton call: each algebra or system compiles it once.
N = 8
T = 0.7
# Gauss-Newton stops at the round-off floor of one flow evaluation: a few ulps of |mu1| (at
# most 6 observed over 60 seeds for every algebra and system, with |t alpha| up to
# 0.7 sqrt(n) and sl(2) stretching mu up to 6x).
RESIDUAL = 32 * EPS
# alpha . grad C = 0 up to the round-off of an orthonormal basis of the complement (SVD) and
# of one matrix-vector product: a few ulps of |alpha| |grad C| (at most 2.5 observed).
ORTHOGONAL = 16 * EPS


def _project(alpha, grads):
    """Remove the span of the rows of `grads` from `alpha` (numpy QR, not liepoisson's SVD)."""
    if grads.shape[0] == 0:
        return alpha
    q, _ = np.linalg.qr(grads.T)
    return alpha - q @ (q.T @ alpha)


def _states(name, dim, rng, n=N):
    y = rng.uniform(-2.0, 2.0, (n, dim))
    # |x| >= 0.2 for the particle: its field |x| and potential 1/|x| are not smooth at 0
    if name == "ChargedParticle":
        r, phi = rng.uniform(0.2, 2.0, n), rng.uniform(0.0, 2 * np.pi, n)
        y[:, 2:] = np.stack([r * np.cos(phi), r * np.sin(phi)], -1)
    return y


def _parameters(rng, grads, dim, n=N):
    """Casimir-projected alpha with |alpha| <= sqrt(dim): |t alpha| stays within the reach of
    Gauss-Newton started at alpha = 0 (rotation angles well below pi)."""
    return np.stack([_project(a, g) for a, g in zip(rng.uniform(-1, 1, (n, dim)), grads)])


def _check_round_trip(flow, grads, found, t, mu0, mu1):
    assert found.shape == mu0.shape and np.all(np.isfinite(found))
    again = np.asarray(flow(found, t, mu0))
    scale = np.max(np.abs(mu1), axis=-1, keepdims=True)
    assert np.all(np.abs(again - mu1) <= RESIDUAL * scale), (
        np.max(np.abs(again - mu1) / scale) / EPS
    )
    if grads.shape[-2]:
        dots = np.abs(np.einsum("ikn,in->ik", grads, found))
        bound = (
            ORTHOGONAL * np.linalg.norm(grads, axis=-1) * np.linalg.norm(found, axis=-1)[:, None]
        )
        assert np.all(dots <= bound), np.max(dots / np.maximum(bound, 1e-300)) * ORTHOGONAL / EPS


@functools.cache
def _generic_so3(sign):
    """so(3) with the same Casimir, solved by the generic path (expm + Gauss-Newton)."""
    g = lp.so3(sign)
    return lp.LieAlgebra(g.structure_constants, casimirs=g.casimir_polynomials, sign=sign)


@functools.cache
def _generic_direct_sum():
    g = algebra("so3+heisenberg")
    return lp.LieAlgebra(g.structure_constants, casimirs=g.casimir_polynomials, sign=g.sign)


# -- round trips: every algebra, every system ------------------------------------------------
def _round_trips(name, owner, flow, inverse, seed):
    """For t = T and -T: random states of `name`, moved by `flow` (a method of `owner`, an
    algebra or a system) with random Casimir-projected parameters, and `inverse` finds them."""
    rng = np.random.default_rng(seed)
    for t in (T, -T):
        y0 = _states(name, owner.dim, rng)
        grads = np.asarray(owner.casimir_gradients(y0))
        y1 = np.asarray(flow(_parameters(rng, grads, owner.dim), t, y0))
        found = inverse(y0, y1, t)
        assert isinstance(found, np.ndarray)
        _check_round_trip(flow, grads, found, t, y0, y1)


@algebra_names
def test_coadjoint_flow_parameters_round_trip(name):
    g = algebra(name)
    _round_trips(name, g, g.coadjoint_flow, g.coadjoint_flow_parameters, seed=0)


@algebra_names
def test_coadjoint_flow_parameters_on_a_basis_axis(name):
    """mu0 parallel to the last basis vector (a regular point of every algebra listed): many
    exact zeros in the cross products and Casimir gradients."""
    g = algebra(name)
    rng = np.random.default_rng(1)
    mu0 = np.zeros((N, g.dim))
    mu0[:, -1] = 1.5
    grads = np.asarray(g.casimir_gradients(mu0))
    mu1 = np.asarray(g.coadjoint_flow(_parameters(rng, grads, g.dim), T, mu0))
    _check_round_trip(
        g.coadjoint_flow, grads, g.coadjoint_flow_parameters(mu0, mu1, T), T, mu0, mu1
    )


@system_names
def test_test_flow_parameters_round_trip(name):
    s = system(name)
    _round_trips(name, s, s.test_flow, s.test_flow_parameters, seed=2)


@pytest.mark.parametrize("name", ["RigidBody", "Kirchhoff"])
def test_lie_poisson_systems_use_their_algebra(name):
    s = system(name)
    rng = np.random.default_rng(3)
    y0 = _states(name, s.dim, rng)
    y1 = np.asarray(
        s.test_flow(_parameters(rng, np.asarray(s.casimir_gradients(y0)), s.dim), T, y0)
    )
    np.testing.assert_array_equal(
        s.test_flow_parameters(y0, y1, T), s.algebra.coadjoint_flow_parameters(y0, y1, T)
    )


# -- the so(3) closed form ------------------------------------------------------------------
@pytest.mark.parametrize("sign", [-1, 1])
def test_rodrigues_closed_form_recovers_alpha_and_matches_gauss_newton(sign):
    g, generic = lp.so3(sign), _generic_so3(sign)
    assert isinstance(g.exact_flow, lp.RodriguesFlow)
    assert isinstance(generic.exact_flow, lp.MatrixExponentialFlow)
    rng = np.random.default_rng(4)
    for t in (T, -T):
        mu0 = _states("so3", 3, rng)
        alpha = _parameters(rng, np.asarray(g.casimir_gradients(mu0)), 3)
        mu1 = np.asarray(g.coadjoint_flow(alpha, t, mu0))
        closed = g.coadjoint_flow_parameters(mu0, mu1, t)
        newton = generic.coadjoint_flow_parameters(mu0, mu1, t)
        # alpha _|_ mu0 with angle |t alpha| < pi is the shortest rotation, hence the unique
        # answer; both paths reach it to a few ulps of |alpha| (at most 3 observed).
        scale = np.max(np.abs(alpha))
        np.testing.assert_allclose(closed, alpha, rtol=0, atol=16 * EPS * scale)
        np.testing.assert_allclose(newton, closed, rtol=0, atol=16 * EPS * scale)


@given(
    mu0=vectors(3), direction=vectors(3), angle=st.floats(0.0, 3.0), sign=st.sampled_from([-1, 1])
)
def test_rodrigues_closed_form_property(mu0, direction, angle, sign):
    """Any rotation of angle < pi about an axis _|_ mu0 is recovered (single pairs)."""
    axis = _project(direction, mu0[None])
    assume(np.linalg.norm(mu0) > 1e-3 and np.linalg.norm(axis) > 1e-3)
    alpha = angle / T * axis / np.linalg.norm(axis)
    g = lp.so3(sign)
    mu1 = np.asarray(g.coadjoint_flow(alpha, T, mu0))
    found = g.coadjoint_flow_parameters(mu0, mu1, T)
    # the angle comes from atan2 of O(|mu|^2) quantities carrying O(eps |mu|^2) round-off:
    # absolute error a few eps / t in alpha, relative to |mu| = 1 (at most 10 eps observed).
    np.testing.assert_allclose(
        found, alpha, rtol=0, atol=64 * EPS / T * max(1.0, np.max(np.abs(alpha)))
    )


@pytest.mark.parametrize("sign", [-1, 1])
def test_zero_rotation_gives_exactly_zero(sign):
    mu = np.array([[1.0, -2.0, 0.5], [0.0, 0.0, 0.0], [0.0, 0.0, 3.0], [1e-200, 0.0, 0.0]])
    found = lp.so3(sign).coadjoint_flow_parameters(mu, mu, T)
    assert np.all(np.isfinite(found)) and np.all(found == 0.0)
    direct = lp.RodriguesFlow().parameters(lp.levi_civita(), mu, mu, T, np.zeros((4, 1, 3)))
    assert np.all(np.asarray(direct) == 0.0)


@pytest.mark.parametrize("sign", [-1, 1])
def test_tiny_rotations(sign):
    g, generic = lp.so3(sign), _generic_so3(sign)
    rng = np.random.default_rng(5)
    mu0 = _states("so3", 3, rng)
    alpha = 1e-9 * _parameters(rng, np.asarray(g.casimir_gradients(mu0)), 3)
    mu1 = np.asarray(g.coadjoint_flow(alpha, T, mu0))
    assert np.all(mu1 != mu0)
    # mu1 carries round-off eps |mu|; over the displacement |t alpha| |mu| that is an absolute
    # error ~ eps / t in alpha, whatever its size (the series branch adds none).
    tol = 4 * EPS / T
    np.testing.assert_allclose(g.coadjoint_flow_parameters(mu0, mu1, T), alpha, rtol=0, atol=tol)
    np.testing.assert_allclose(
        generic.coadjoint_flow_parameters(mu0, mu1, T), alpha, rtol=0, atol=tol
    )


def test_quarter_turn_between_axes_is_exact():
    """e1 -> e2: the body flow exp(-t hat alpha) needs t alpha = -(pi/2) e3."""
    e = np.eye(3)
    found = lp.so3().coadjoint_flow_parameters(e[0], e[1], 2.0)
    np.testing.assert_allclose(found, [0.0, 0.0, -np.pi / 4], rtol=0, atol=EPS)
    found = lp.so3(sign=+1).coadjoint_flow_parameters(e[0], e[1], 2.0)
    np.testing.assert_allclose(found, [0.0, 0.0, np.pi / 4], rtol=0, atol=EPS)


def test_closed_form_gradient_at_zero_rotation():
    """d alpha / d mu1 at mu1 = mu0 is -hat(mu0) / (t |mu0|^2) (from alpha ~ -(mu0 x mu1) /
    (t |mu0|^2)), and d alpha / d mu0 is +hat(mu0) / (t |mu0|^2); both finite."""
    flow, C = lp.RodriguesFlow(), lp.levi_civita()
    mu0 = jnp.array([0.3, -1.2, 0.7])
    grads = 2.0 * mu0[None, None, :]

    def alpha(m0, m1):
        return flow.parameters(C, m0[None], m1[None], T, grads)[0]

    hat = np.array([[0.0, -mu0[2], mu0[1]], [mu0[2], 0.0, -mu0[0]], [-mu0[1], mu0[0], 0.0]])
    expected = -hat / (T * float(mu0 @ mu0))
    # forward and reverse mode, in mu1 and in mu0: one compiled program (not op by op)
    both = jax.jit(lambda m: [(jac(alpha, argnums=1)(m, m), jac(alpha, argnums=0)(m, m))
                              for jac in (jax.jacfwd, jax.jacrev)])
    for d1, d0 in both(mu0):
        d1, d0 = np.asarray(d1), np.asarray(d0)
        # exact up to the rounding of 1/(t |mu0|^2): a few ulps
        np.testing.assert_allclose(d1, expected, rtol=0, atol=8 * EPS * np.max(np.abs(expected)))
        np.testing.assert_allclose(d0, -expected, rtol=0, atol=8 * EPS * np.max(np.abs(expected)))


@pytest.mark.slow
def test_direct_sum_blockwise_equals_gauss_newton_on_the_sum():
    g, generic = algebra("so3+heisenberg"), _generic_direct_sum()
    rng = np.random.default_rng(6)
    mu0 = _states("so3+heisenberg", g.dim, rng)
    alpha = _parameters(rng, np.asarray(g.casimir_gradients(mu0)), g.dim)
    mu1 = np.asarray(g.coadjoint_flow(alpha, T, mu0))
    # alpha in the Casimir complement is unique here (so(3) angle < pi, Heisenberg linear)
    np.testing.assert_allclose(
        g.coadjoint_flow_parameters(mu0, mu1, T),
        generic.coadjoint_flow_parameters(mu0, mu1, T),
        rtol=0,
        atol=16 * EPS * np.max(np.abs(alpha)),
    )


def test_gauss_newton_backtracks_on_a_strongly_stretching_flow():
    """sl(2), |t alpha| ~ 2: the flow stretches mu by 40x; undamped Gauss-Newton from
    alpha = 0 diverged on this pair (residual 7e6)."""
    g = algebra("sl2")
    # tiled to the shared batch size N, so the compiled solver is reused
    mu0 = np.tile([-0.3820022921434805, 2.552424025371081, -0.3244718562854392], (N, 1))
    alpha = np.tile([2.673780639178687, 0.9018962440337173, 0.31473419264232605], (N, 1))
    mu1 = np.asarray(g.coadjoint_flow(alpha, T, mu0))
    assert np.max(np.abs(mu1)) > 40 * np.max(np.abs(mu0))
    found = g.coadjoint_flow_parameters(mu0, mu1, T)
    np.testing.assert_allclose(found, alpha, rtol=0, atol=1e-12)


def test_gauss_newton_parameters_with_any_flow():
    """The generic function on a plain callable (no Casimirs)."""
    s = system("ChargedParticle")
    rng = np.random.default_rng(7)
    y0 = _states("ChargedParticle", 4, rng)
    alpha = rng.uniform(-1, 1, (N, 4))
    y1 = np.asarray(s.test_flow(alpha, T, y0))
    found = lp.gauss_newton_parameters(s.test_flow, y0, y1, T, np.zeros((N, 0, 4)))
    np.testing.assert_allclose(np.asarray(found), alpha, rtol=0, atol=1e-12)


# -- rejected pairs and input checks --------------------------------------------------------
# so(3)'s by default (the check is the same for every algebra); the others with -m slow
@pytest.mark.parametrize("name", slow_except(ALGEBRAS, {"so3"}))
def test_different_casimir_levels_are_rejected(name):
    g = algebra(name)
    rng = np.random.default_rng(8)
    mu0 = _states(name, g.dim, rng, n=3)
    alpha = _parameters(rng, np.asarray(g.casimir_gradients(mu0)), g.dim, 3)
    mu1 = np.array(g.coadjoint_flow(alpha, T, mu0))
    grad = np.asarray(g.casimir_gradients(mu1[1]))[-1]  # moves the last Casimir, maybe others
    mu1[1] += 1e-6 * np.linalg.norm(mu1[1]) * grad / np.linalg.norm(grad)
    with pytest.raises(ValueError, match=r"pair 1: Casimir \d differs.*no Poisson map"):
        g.coadjoint_flow_parameters(mu0, mu1, T)


def test_different_casimir_levels_are_rejected_for_systems():
    s = system("ExtendedPendulum")
    y0 = np.array([[0.0, 1.0, 1.0], [0.0, 1.5, 2.35]])
    y1 = y0.copy()
    y1[1, 2] += 1e-6
    with pytest.raises(ValueError, match="pair 1: Casimir 0 differs between y0 and y1"):
        s.test_flow_parameters(y0, y1, T)


@pytest.mark.parametrize("sign", [-1, 1])
def test_antiparallel_so3_pair_is_rejected(sign):
    mu0 = np.array([[1.0, 0.0, 0.0], [0.3, -0.4, 1.2]])
    mu1 = np.array([[0.0, 1.0, 0.0], -mu0[1]])
    with pytest.raises(ValueError, match="pair 1: .*antiparallel"):
        lp.so3(sign).coadjoint_flow_parameters(mu0, mu1, T)


def test_failed_gauss_newton_names_the_pair():
    """Heisenberg: mu_z = 0 makes the orbit a point, although the Casimir mu_z agrees."""
    g = algebra("heisenberg")
    mu0 = np.tile([1.0, 0.0, 2.0], (N, 1))
    mu1 = mu0.copy()
    mu0[1], mu1[1] = [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]
    with pytest.raises(ValueError, match="pair 1: found no parameters"):
        g.coadjoint_flow_parameters(mu0, mu1, T)


def test_input_checks_and_shapes():
    g = lp.so3()
    mu = np.array([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="t must be finite and non-zero"):
        g.coadjoint_flow_parameters(mu, mu, 0.0)
    with pytest.raises(ValueError, match="t must be finite"):
        g.coadjoint_flow_parameters(mu, mu, np.nan)
    with pytest.raises(TypeError, match="t must be a real scalar"):
        g.coadjoint_flow_parameters(mu, mu, np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="mu0 and mu1 must have the same shape"):
        g.coadjoint_flow_parameters(mu, np.stack([mu, mu]), T)
    with pytest.raises(ValueError, match="mu1 must have shape"):
        g.coadjoint_flow_parameters(mu, mu[:2], T)
    with pytest.raises(ValueError, match="mu0 must be finite"):
        g.coadjoint_flow_parameters(np.array([np.inf, 0.0, 0.0]), mu, T)
    with pytest.raises(ValueError, match="rtol"):
        g.coadjoint_flow_parameters(mu, mu, T, rtol=-1.0)
    with pytest.raises(ValueError, match="y1 must have shape"):
        system("ExtendedPendulum").test_flow_parameters(mu, mu[:2], T)
    # leading axes are kept; a pair is named by its index over the flattened leading axes
    rng = np.random.default_rng(9)
    mu0 = rng.uniform(-1, 1, (2, 2, 3))
    mu1 = np.array(g.coadjoint_flow(np.cross(mu0, [0.1, 0.2, 0.3]), T, mu0))
    assert g.coadjoint_flow_parameters(mu0, mu1, T).shape == (2, 2, 3)
    assert g.coadjoint_flow_parameters(mu0[0, 0], mu1[0, 0], T).shape == (3,)
    mu1[1, 0] *= 1.1
    with pytest.raises(ValueError, match="pair 2: Casimir 0"):
        g.coadjoint_flow_parameters(mu0, mu1, T)


# -- se(3): rotation, then shear --------------------------------------------------------------
def _rotation_shear_pairs(sign, rng, n=N):
    mu0 = rng.uniform(-2, 2, (n, 6))
    alpha = rng.uniform(-1, 1, (n, 6))
    return mu0, alpha, np.asarray(lp.se3_rotation_shear(alpha, T, mu0, sign=sign))


@pytest.mark.parametrize("sign", [-1, 1])
def test_rotation_shear_is_two_exact_flows(sign):
    g = lp.se3(sign)
    rng = np.random.default_rng(10)
    mu0, alpha, mu1 = _rotation_shear_pairs(sign, rng)
    zero = np.zeros((N, 3))
    rotation, shear = (
        np.concatenate([alpha[:, :3], zero], -1),
        np.concatenate([zero, alpha[:, 3:]], -1),
    )
    twice = g.coadjoint_flow(shear, T, g.coadjoint_flow(rotation, T, mu0))
    np.testing.assert_array_equal(mu1, np.asarray(twice))
    # the shear alone, from docs/conventions.md: H = b.p gives dPi/dt = p x b in the body convention
    # (sign -1); the spatial one reverses time
    sheared = np.asarray(lp.se3_rotation_shear(shear, T, mu0, sign=sign))
    expected = mu0[:, :3] + sign * T * np.cross(alpha[:, 3:], mu0[:, 3:])
    # one cross product and one addition: a few ulps
    np.testing.assert_allclose(
        sheared[:, :3], expected, rtol=0, atol=8 * EPS * np.max(np.abs(expected))
    )
    np.testing.assert_array_equal(sheared[:, 3:], mu0[:, 3:])
    # both factors are Poisson maps: |p|^2 and Pi . p conserved to a few ulps of |mu|^2
    size = np.max(np.abs(np.concatenate([mu0, mu1]))) ** 2
    np.testing.assert_allclose(
        np.asarray(g.casimirs(mu1)), np.asarray(g.casimirs(mu0)), rtol=0, atol=64 * EPS * size
    )


@pytest.mark.parametrize("sign", [-1, 1])
def test_rotation_shear_round_trip(sign):
    rng = np.random.default_rng(11)
    for t in (T, -T):
        mu0 = rng.uniform(-2, 2, (N, 6))
        alpha = rng.uniform(-1, 1, (N, 6))
        mu1 = np.asarray(lp.se3_rotation_shear(alpha, t, mu0, sign=sign))
        found = lp.se3_rotation_shear_parameters(mu0, mu1, t, sign=sign)
        again = np.asarray(lp.se3_rotation_shear(found, t, mu0, sign=sign))
        # closed form: atan2, cross products and one division by |p|^2: a few tens of ulps
        np.testing.assert_allclose(again, mu1, rtol=0, atol=64 * EPS * np.max(np.abs(mu1)))
        # minimum norm: A _|_ p0, b _|_ p1, to a few ulps of |A| |p0| and |b| |p1|
        for v, p in ((found[:, :3], mu0[:, 3:]), (found[:, 3:], mu1[:, 3:])):
            dots = np.abs(np.einsum("ia,ia->i", v, p))
            assert np.all(
                dots <= 16 * EPS * np.linalg.norm(v, axis=-1) * np.linalg.norm(p, axis=-1)
            )


@pytest.mark.parametrize("sign", [-1, 1])
def test_rotation_shear_recovers_minimal_parameters(sign):
    """(A, b) with A _|_ p0 (angle < pi) and b _|_ p1 is the unique minimal answer."""
    rng = np.random.default_rng(12)
    mu0 = rng.uniform(-2, 2, (N, 6))
    A = np.stack([_project(a, p[None]) for a, p in zip(rng.uniform(-1, 1, (N, 3)), mu0[:, 3:])])
    zero = np.zeros((N, 3))
    p1 = np.asarray(lp.se3_rotation_shear(np.concatenate([A, zero], -1), T, mu0, sign=sign))[:, 3:]
    b = np.stack([_project(v, p[None]) for v, p in zip(rng.uniform(-1, 1, (N, 3)), p1)])
    alpha = np.concatenate([A, b], -1)
    mu1 = np.asarray(lp.se3_rotation_shear(alpha, T, mu0, sign=sign))
    found = lp.se3_rotation_shear_parameters(mu0, mu1, T, sign=sign)
    # errors of eps |mu| in mu1, over a displacement t |alpha| |mu|, divided by |p|^2 >= 0.1
    np.testing.assert_allclose(found, alpha, rtol=0, atol=1e3 * EPS)


def test_rotation_shear_rejects_pairs():
    rng = np.random.default_rng(13)
    mu0, _, mu1 = _rotation_shear_pairs(-1, rng, n=3)
    bad = mu1.copy()
    bad[1, :3] += 1e-5 * mu1[1, 3:]  # changes Pi . p only
    with pytest.raises(ValueError, match="pair 1: Casimir 1 differs"):
        lp.se3_rotation_shear_parameters(mu0, bad, T)
    bad = mu1.copy()
    bad[2, 3:] *= 1.0 + 1e-6  # changes |p|^2 (and Pi . p)
    with pytest.raises(ValueError, match="pair 2: Casimir 0 differs"):
        lp.se3_rotation_shear_parameters(mu0, bad, T)
    zero_p = np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="pair 0: p = 0"):
        lp.se3_rotation_shear_parameters(zero_p, zero_p, T)
    mu = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    with pytest.raises(ValueError, match="pair 0: p0 .* antiparallel"):
        lp.se3_rotation_shear_parameters(mu, np.array([-1.0, 0.0, 0.0, 0.0, 0.0, -2.0]), T)
    with pytest.raises(ValueError, match="sign"):
        lp.se3_rotation_shear_parameters(mu, mu, T, sign=0)
    with pytest.raises(ValueError, match="sign"):
        lp.se3_rotation_shear(mu, T, mu, sign=True)
    with pytest.raises(ValueError, match="t must be finite and non-zero"):
        lp.se3_rotation_shear_parameters(mu, mu, 0.0)
    assert np.all(lp.se3_rotation_shear_parameters(mu, mu, T) == 0.0)


def test_stateless_flows_compare_by_type():
    """Equal flows share the compiled Gauss-Newton (structure constants are an argument);
    a direct sum's flow has state and compares by identity."""
    assert lp.SE3Flow() == lp.SE3Flow() and hash(lp.SE3Flow()) == hash(lp.SE3Flow())
    assert lp.MatrixExponentialFlow() != lp.SE3Flow()
    flows = [algebra("so3+heisenberg").exact_flow] * 2
    assert flows[0] == flows[1] and hash(flows[0]) == hash(flows[1])
    assert flows[0] != lp.direct_sum(lp.so3(), lp.heisenberg()).exact_flow
