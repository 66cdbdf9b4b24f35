"""The exact free-rigid-body flow by Jacobi elliptic functions: `ellipj` against mpmath, the
flow against heyoka, its degenerate cases, and its use as a splitting sub-step."""

import functools

import hypothesis.strategies as st
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings

import integrators as it
import liepoisson as lp
from liepoisson.systems import CollectiveTerm, FreeRigidBodyTerm, RigidBody, free_rigid_body_flow

EPS = np.finfo(np.float64).eps
# Every ordering class of the moments: sorted, and both cyclic shifts (an even and an odd
# sorting permutation), plus the two kinds of symmetric body.
INERTIAS = [
    (1.0, 2.0, 3.0),
    (3.0, 1.0, 2.0),
    (2.0, 3.0, 1.0),
    (1.0, 3.0, 2.0),
    (1.0, 1.0, 2.0),
    (1.0, 2.0, 2.0),
]


def mp_ellipj(u, m):
    mpmath.mp.dps = 40
    return [float(mpmath.ellipfun(f, mpmath.mpf(u), m=mpmath.mpf(m))) for f in ("sn", "cn", "dn")]


@pytest.mark.parametrize(
    "m", [0.0, 1e-300, 1e-17, 1e-9, 0.3, 0.5, 0.9, 0.999, 1 - 1e-6, 1 - 1e-12, 1 - 2**-52, 1.0]
)
def test_ellipj_against_mpmath(m):
    u = np.array([0.0, 1e-8, 0.3, -1.7, 5.0, 20.0, -60.0, 150.0])
    ours = np.stack([np.asarray(v) for v in lp.ellipj(u, m)], -1)
    ref = np.array([mp_ellipj(x, m) for x in u])
    # The argument phi = 2^N a_N u carries a relative eps, so the error grows like eps |u|;
    # 100 eps (1 + |u|) covers the ~14 AGM roundings (measured at most 40 eps (1 + |u|)).
    assert np.all(np.abs(ours - ref) <= 100 * EPS * (1 + np.abs(u))[:, None])


def test_ellipj_complementary_parameter_near_one():
    # m rounds to 1 but 1 - m = 1e-18 still sets the period 4K ~ 88: tanh would be wrong.
    ours = np.asarray(lp.ellipj(40.0, 1.0, 1e-18))
    mpmath.mp.dps = 50
    ref = [float(mpmath.ellipfun(f, 40, m=1 - mpmath.mpf("1e-18"))) for f in ("sn", "cn", "dn")]
    assert np.allclose(ours, ref, rtol=0, atol=1e3 * EPS * 40)
    assert abs(ours[1] - 1 / np.cosh(40.0)) > 1e-3  # not the separatrix value


@functools.cache
def heyoka_reference(inertia):
    y0 = np.random.default_rng(7).normal(size=(12, 3))
    # Away from the separatrix (|M^2 - 2H I_2| > 1% of M^2): next to it the period grows like
    # log(1/(1 - m)) and every method's (heyoka's too) round-off is amplified; one drawn state
    # at 0.2% differs from heyoka by 1.1e-12 at t = 100. The separatrix has its own test below.
    I = np.asarray(inertia)
    y0 = y0[np.abs(np.sum(y0**2 * (1 - np.median(I) / I), axis=1)) > 0.01 * np.sum(y0**2, axis=1)]
    # heyoka at tolerance eps over t = 100 (sampled at every unit time): its own error is
    # ~1e-14 relative, two orders below the tolerance tested.
    return y0, np.asarray(
        it.ground_truth(RigidBody(inertia), y0, h=1.0, n_steps=100, progress=False).states
    )


# by default a generic body; every ordering of the axes and the symmetric bodies with -m slow (the
# symmetric ones keep their invariants by default in test_invariants_and_group_property)
@pytest.mark.parametrize(
    "inertia", [i if i == INERTIAS[0] else pytest.param(i, marks=pytest.mark.slow) for i in INERTIAS]
)
def test_flow_matches_heyoka_over_t_100(inertia):
    y0, ref = heyoka_reference(inertia)
    t = np.arange(101.0)
    # every (state, time) pair in one batched call (the flow is elementwise in the batch)
    states = np.broadcast_to(y0[:, None, :], (y0.shape[0], t.size, 3))
    ours = np.asarray(free_rigid_body_flow(inertia, np.broadcast_to(t, states.shape[:-1]), states))
    rel = np.max(np.abs(ours - ref), axis=(1, 2)) / np.linalg.norm(y0, axis=1)
    assert rel.max() < 1e-12, rel


@pytest.mark.slow
def test_exact_flow_step_map_composes_to_the_solution():
    body = RigidBody((1.0, 2.0, 3.0))
    y0, ref = heyoka_reference((1.0, 2.0, 3.0))
    ys = np.asarray(it.ExactFlow(body, h=0.1).rollout(y0, 1000, save_every=10))
    rel = np.max(np.abs(ys - ref), axis=(1, 2)) / np.linalg.norm(y0, axis=1)
    # 1000 compositions: round-off accumulates like a random walk, measured 2e-12 relative.
    assert rel.max() < 1e-11
    assert it.ExactFlow(body, 0.1).cost().exact_flows == 1


@pytest.mark.parametrize("inertia", INERTIAS[:3])
def test_equilibria_and_zero_do_not_move(inertia):
    axes = np.vstack([np.eye(3), -2.0 * np.eye(3), np.zeros((1, 3))])
    for t in (0.0, 1.0, 1e3):
        out = np.asarray(free_rigid_body_flow(inertia, t, axes))
        assert np.all(np.isfinite(out))
        # Rotations about a principal axis (even the unstable middle one) are fixed points.
        assert np.allclose(out, axes, rtol=0, atol=4 * EPS * 2), (t, out)


@pytest.mark.parametrize(
    "y0",
    [
        [1e-9, 1.0, 1e-9],
        [1e-9, 1.0, -1e-9],
        [1e-12, 1.0, 0.0],
        [1.0, 1e-12, 1.0],
        [0.5, 0.0, 0.5],
        [1.0, 0.0, np.sqrt(3.0)],
    ],
)
def test_near_the_separatrix_the_invariants_stay_at_round_off(y0):
    # Next to the saddles cn and dn are tiny; |Pi|^2 and H must still be kept to round-off.
    body = RigidBody((1.0, 2.0, 3.0))
    y0 = np.asarray(y0, float)
    ys = np.asarray(body.exact_flow(np.linspace(0, 1000, 2001)[:, None], y0))
    assert np.all(np.isfinite(ys))
    C = np.sum(ys**2, -1)
    H = np.asarray(body.hamiltonian(ys))
    # A few roundings per evaluation, no accumulation (each time is one evaluation).
    assert np.max(np.abs(C - C[0])) <= 8 * EPS * C[0]
    assert np.max(np.abs(H - H[0])) <= 8 * EPS * H[0]


def test_spherical_body_is_the_identity():
    y = np.array([[0.3, -0.4, 2.0]])
    assert np.array_equal(np.asarray(free_rigid_body_flow((2.0, 2.0, 2.0), 5.0, y)), y)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-3, 3), min_size=3, max_size=3),
    st.floats(-50, 50),
    st.sampled_from(INERTIAS),
)
def test_invariants_and_group_property(y, t, inertia):
    y = np.asarray(y)
    out = np.asarray(free_rigid_body_flow(inertia, t, y))
    scale = max(np.sum(y**2), 1e-300)
    assert abs(np.sum(out**2) - np.sum(y**2)) <= 16 * EPS * scale
    E = lambda z: np.sum(z**2 / np.asarray(inertia))
    assert abs(E(out) - E(y)) <= 16 * EPS * scale / min(inertia)
    # phi_t then phi_{-t} is the identity: up to the conditioning of the flow, which for
    # |t| <= 50 away from the separatrix is modest (1e-10 covers the worst drawn case).
    back = np.asarray(free_rigid_body_flow(inertia, -t, out))
    assert np.allclose(back, y, rtol=0, atol=1e-10 * (1 + np.linalg.norm(y)))


@pytest.mark.slow  # the flow matches heyoka to 1e-12 by default (the exact flow of H is a Poisson map)
def test_exact_flow_is_a_poisson_map():
    body = RigidBody((1.0, 2.0, 3.0))
    y = np.random.default_rng(3).normal(size=(20, 3))
    # J B(y) J^T = B(phi(y)) by forward-mode autodiff through the elliptic functions.
    assert np.max(np.asarray(it.ExactFlow(body, h=0.7).poisson_defect(y))) < 1e-13


def perturbed_body():
    """H = T + 0.3 cos(Pi_1 + Pi_2): not integrable; T by ellipj, the cosine collective."""
    inertia = (1.0, 2.0, 3.0)

    def hamiltonian(mu, xp):
        return 0.5 * (mu[0] ** 2 / 1.0 + mu[1] ** 2 / 2.0 + mu[2] ** 2 / 3.0) + 0.3 * xp.cos(
            mu[0] + mu[1]
        )

    import jax.numpy as jnp

    pieces = [
        FreeRigidBodyTerm(inertia),
        CollectiveTerm([1.0, 1.0, 0.0], lambda s: 0.3 * jnp.cos(s[0]), "V"),
    ]
    return lp.systems.LiePoissonSystem(lp.so3(), hamiltonian, name="perturbed_body"), pieces


# ~5 s each (heyoka and rollouts of the perturbed body) with -m slow: FreeRigidBodyTerm's flow is
# free_rigid_body_flow, checked against heyoka by default, and splittings compose exact terms by
# default in test_integrators_splitting.py
@pytest.mark.parametrize("method", [pytest.param(it.splitting.Strang, marks=pytest.mark.slow),
                                    pytest.param(it.splitting.TripleJump, marks=pytest.mark.slow)])
def test_elliptic_flow_as_a_splitting_sub_step_has_the_method_order(method):
    system, pieces = perturbed_body()
    y0 = np.array([0.8, -0.5, 1.1])
    T = 4.0
    ref = np.asarray(it.ground_truth(system, y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([20, 40, 80, 160])
    # save_every=n: only the state at T, by one compiled program for every n (n is traced)
    errors = [
        np.linalg.norm(
            np.asarray(method(system, T / n, terms=pieces).rollout(y0, int(n), save_every=int(n)))[-1] - ref
        )
        for n in steps
    ]
    order = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(order - method.order) < 0.1, (errors, order)
    # The sub-steps are exact, so |Pi|^2 is conserved to round-off by the composition: a
    # random walk over 500 steps x up to 9 flows of a few roundings each (measured 2e2 eps).
    ys = np.asarray(method(system, 0.1, terms=pieces).rollout(y0, 500))
    assert np.max(np.abs(np.sum(ys**2, -1) - y0 @ y0)) < 2e3 * EPS * (y0 @ y0)


def test_pieces_that_do_not_sum_to_h_are_refused():
    body = RigidBody((1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="terms must sum to the Hamiltonian"):
        it.splitting.Strang(body, 0.1, terms=[FreeRigidBodyTerm((1.0, 2.0, 4.0))])
    # A constant offset is harmless and accepted.
    offset = CollectiveTerm([1.0, 0.0, 0.0], lambda s: 0.0 * s[0] + 5.0, "const")
    it.splitting.Strang(body, 0.1, terms=[FreeRigidBodyTerm((1.0, 2.0, 3.0)), offset])


def test_wrong_system_and_inputs_are_named():
    with pytest.raises(ValueError, match="so\\(3\\)"):
        it.splitting.Strang(lp.systems.Kirchhoff(), 0.1, terms=[FreeRigidBodyTerm((1.0, 2.0, 3.0))])
    with pytest.raises(TypeError, match="exact_flow"):
        it.ExactFlow(lp.systems.Kirchhoff(), 0.1)
    with pytest.raises(ValueError, match="inertia"):
        FreeRigidBodyTerm((1.0, -2.0, 3.0))
    with pytest.raises(ValueError, match="y"):
        free_rigid_body_flow((1.0, 2.0, 3.0), 1.0, np.ones(4))
    with pytest.raises(ValueError, match="h"):
        it.ExactFlow(RigidBody(), 0.0)
    with pytest.raises(TypeError, match="terms"):
        it.splitting.Strang(RigidBody(), 0.1, terms=[object()])
