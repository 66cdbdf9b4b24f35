"""Double-bracket dissipation (`liepoisson.systems.DoubleBracket`): the vector field against
closed forms written here, energy decay and Casimirs on every algebra of the test list, heyoka's
ground truth of the damped rigid body, files, and bad input."""

from __future__ import annotations

import functools
import zlib

import numpy as np
import pytest
from helpers import ALGEBRAS, EPS, algebra, algebra_names, slow_except, system, vectors
from hypothesis import given, settings
from hypothesis import strategies as st

import integrators as it
import liepoisson as lp
from liepoisson.systems import DoubleBracket, LiePoissonSystem


@functools.cache  # one system per algebra: its compiled functions serve every example
def _quadratic_system(name: str) -> LiePoissonSystem:
    """H = 1/2 mu^T A mu + b.mu with A positive definite (seeded), on algebra `name`."""
    g = algebra(name)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    M = rng.normal(size=(g.dim, g.dim))
    A = M @ M.T / g.dim + np.eye(g.dim)
    b = rng.normal(size=g.dim)

    def hamiltonian(m, xp):
        quad = sum(0.5 * float(A[i, j]) * m[i] * m[j] for i in range(g.dim) for j in range(g.dim))
        return quad + sum(float(b[i]) * m[i] for i in range(g.dim))

    return LiePoissonSystem(g, hamiltonian, name=f"quadratic_{name}")


@pytest.mark.slow  # the vector field by default in test_metric_enters_between_the_brackets; the rigid body's relaxation below
def test_rigid_body_vector_field_is_euler_plus_double_bracket():
    # closed form: Pi x Omega + gamma Pi x (Pi x Omega), Omega = I^-1 Pi (numpy only)
    inertia, gamma = np.array([2.0, 1.0, 2.0 / 3.0]), 0.3
    damped = lp.systems.damped_rigid_body(inertia, gamma)
    Pi = np.random.default_rng(0).normal(size=(20, 3))
    Om = Pi / inertia
    expected = np.cross(Pi, Om) + gamma * np.cross(Pi, np.cross(Pi, Om))
    # a few roundings of |Pi|^3 per component
    np.testing.assert_allclose(np.asarray(damped.vector_field(Pi)), expected, rtol=0, atol=64 * EPS * 10)
    rate = -gamma * np.sum(np.cross(Pi, Om) ** 2, axis=-1)
    np.testing.assert_allclose(np.asarray(damped.energy_rate(Pi)), rate, rtol=64 * EPS, atol=0)


def test_metric_enters_between_the_brackets():
    # B K B grad H with a given metric K, by numpy from the Poisson tensor
    body = system("HeavyTop")
    rng = np.random.default_rng(1)
    M = rng.normal(size=(6, 6))
    K = M @ M.T + 0.5 * np.eye(6)
    damped = DoubleBracket(body, 0.2, metric=K)
    y = rng.normal(size=(5, 6))
    B = np.asarray(body.poisson_tensor(y))
    g = np.asarray(body.hamiltonian_gradient(y))
    v = np.einsum("nab,nb->na", B, g)
    expected = v + 0.2 * np.einsum("nab,bc,nc->na", B, K, v)
    np.testing.assert_allclose(np.asarray(damped.vector_field(y)), expected, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(np.asarray(damped.energy_rate(y)), -0.2 * np.einsum("na,ab,nb->n", v, K, v),
                               rtol=1e-13)


@pytest.mark.slow  # the vector field's formula (undamped plus gamma B K B grad H) by default above
def test_gamma_zero_is_the_undamped_system():
    body = system("Kirchhoff")
    y = np.random.default_rng(2).normal(size=(7, 6))
    assert np.array_equal(np.asarray(DoubleBracket(body, 0.0).vector_field(y)), np.asarray(body.vector_field(y)))


# Each example checks a batch of 4 states in one call of each method (eager dispatch costs per
# call, not per state): 6 examples check 24 states and 6 dissipation strengths per algebra. By
# default so(3); every algebra's Casimirs and energy loss along heyoka's trajectories by default below.
@pytest.mark.parametrize("name", slow_except(ALGEBRAS, {"so3"}))
@settings(max_examples=6, deadline=None)
@given(ys=st.lists(vectors(8, 2.0), min_size=4, max_size=4), gamma=st.floats(0.0, 3.0))
def test_casimirs_kept_and_energy_decays_on_every_algebra(name, ys, gamma):
    damped = DoubleBracket(_quadratic_system(name), gamma)
    y = np.stack(ys)[:, : damped.dim]
    f = np.asarray(damped.vector_field(y))
    grad_h = np.asarray(damped.hamiltonian_gradient(y))
    grad_cs = np.asarray(damped.casimir_gradients(y))  # (4, n_casimirs, dim)
    rates = np.asarray(damped.energy_rate(y))
    assert f.shape == grad_h.shape == y.shape and rates.shape == (4,) and grad_cs.shape[0] == 4
    for k in range(4):
        scale = max(1.0, float(np.linalg.norm(f[k])) * max(1.0, float(np.linalg.norm(y[k]))))
        # dC/dt = grad C . f vanishes: B is antisymmetric and grad C^T B = 0 (to a few roundings)
        for grad_c in grad_cs[k]:
            assert abs(grad_c @ f[k]) <= 1e3 * EPS * scale * max(1.0, float(np.linalg.norm(grad_c)))
        # dH/dt = grad H . f = -gamma |B grad H|^2 <= 0
        rate = float(rates[k])
        assert rate <= 0.0
        assert abs(grad_h[k] @ f[k] - rate) <= 1e3 * EPS * max(1.0, float(np.linalg.norm(grad_h[k]))) * scale


@algebra_names
def test_heyoka_trajectory_keeps_casimirs_and_loses_energy_on_every_algebra(name):
    damped = DoubleBracket(_quadratic_system(name), 0.5)
    y0 = np.random.default_rng(3).normal(size=damped.dim)
    y = np.asarray(it.ground_truth(damped, y0, h=0.05, n_steps=100).states[0])
    H = np.asarray(damped.hamiltonian(y))
    # tol = eps: each output carries a few hundred roundings at most
    assert np.all(np.diff(H) <= 1e3 * EPS * np.abs(H[:-1]).max())
    C = np.asarray(damped.casimirs(y))
    if C.shape[-1]:
        assert np.max(np.abs(C - C[0])) <= 1e3 * EPS * max(1.0, float(np.max(np.abs(C))))


def test_damped_rigid_body_relaxes_from_the_minor_to_the_major_axis():
    # Explorer 1: near the minor axis (I3 = 2/3, the highest energy at fixed |Pi|) to the major
    # axis (I1 = 2, the lowest). heyoka at tol = eps over the whole relaxation.
    damped = lp.systems.damped_rigid_body(gamma=0.1)
    y0 = np.array([0.05, 0.05, 1.0]) / np.linalg.norm([0.05, 0.05, 1.0])
    y = np.asarray(it.ground_truth(damped, y0, h=0.1, n_steps=1500).states[0])
    C = np.asarray(damped.casimirs(y))[:, 0]
    assert np.max(np.abs(C - C[0])) <= 1e-13  # the figure; the drift is ~1e-15
    H = np.asarray(damped.hamiltonian(y))
    assert np.all(np.diff(H) < 0.0)  # strictly decreasing at every output up to t = 150
    assert H[0] > 0.5 / 1.0 > H[-1]  # crosses the separatrix energy |Pi|^2 / (2 I2)
    assert abs(H[-1] - 0.5 / 2.0) < 1e-6  # ends spinning about the major axis: |Pi|^2 / (2 I1)
    assert abs(abs(y[-1, 0]) - 1.0) < 1e-6


def test_files_rebuild_the_damped_system(tmp_path):
    damped = lp.systems.damped_heavy_top(gamma=0.2)
    assert lp.systems.from_name(damped.name, damped.params) == damped
    data = it.ground_truth(damped, np.array([0.3, 0.2, 1.0, 0.1, 0.2, 0.97]), h=0.1, n_steps=5)
    data.save(tmp_path / "damped.h5")
    loaded = it.Trajectories.load(tmp_path / "damped.h5")
    assert loaded.system == damped
    assert np.array_equal(loaded.states, data.states)
    # a user algebra inside: rebuilt from its definition
    user = DoubleBracket(_quadratic_system("sl2"), 0.4, metric=np.diag([1.0, 2.0, 3.0]))
    again = lp.systems.from_name(user.name, user.params)
    y = np.random.default_rng(4).normal(size=(3, 3))
    np.testing.assert_array_equal(np.asarray(again.vector_field(y)), np.asarray(user.vector_field(y)))


def test_bad_input_is_refused_with_the_argument_named():
    body = system("RigidBody")
    for gamma in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="gamma must be finite and >= 0"):
            DoubleBracket(body, gamma)
    with pytest.raises(TypeError, match="gamma must be a real number"):
        DoubleBracket(body, "0.1")
    with pytest.raises(ValueError, match=r"metric must be symmetric"):
        DoubleBracket(body, 0.1, metric=[[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="metric must be positive definite"):
        DoubleBracket(body, 0.1, metric=np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match=r"metric must have shape \(3, 3\)"):
        DoubleBracket(body, 0.1, metric=np.eye(6))
    with pytest.raises(ValueError, match="metric must be finite"):
        DoubleBracket(body, 0.1, metric=np.diag([1.0, np.nan, 1.0]))
    with pytest.raises(TypeError, match="must be a Lie-Poisson system.*ExtendedPendulum"):
        DoubleBracket(system("ExtendedPendulum"), 0.1)
    with pytest.raises(TypeError, match="already damped"):
        DoubleBracket(DoubleBracket(body, 0.1), 0.1)
    damped = DoubleBracket(body, 0.1)
    with pytest.raises(ValueError, match="dissipative.*DampedSplitting"):
        it.splitting.Strang(damped, 0.1)
    # the undamped pieces given explicitly would integrate the undamped system: refused too
    with pytest.raises(ValueError, match="dissipative.*DampedSplitting"):
        it.splitting.Strang(damped, 0.1, terms=body.hamiltonian_splitting())
    with pytest.raises(ValueError, match="rebuilt from its params"):
        lp.systems.from_name("DoubleBracket")


def test_scalars_and_the_identity_metric():
    import jax.numpy as jnp

    body = system("RigidBody")
    assert DoubleBracket(body, jnp.asarray(0.2)) == DoubleBracket(body, np.float64(0.2)) == DoubleBracket(body, 0.2)
    # the identity given explicitly is the default metric: one system, one compiled code
    assert DoubleBracket(body, 0.2, metric=np.eye(3)) == DoubleBracket(body, 0.2)
    assert hash(DoubleBracket(body, 0.2, metric=np.eye(3))) == hash(DoubleBracket(body, 0.2))
    assert DoubleBracket(body, 0.2, metric=2 * np.eye(3)) != DoubleBracket(body, 0.2)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_a_learned_dissipative_map_keeps_casimirs_for_any_weights(seed):
    # An LPNet's step is an exact coadjoint flow whatever its weights, so whatever it learned
    # from damped data: random networks stand for every training. On the damped heavy top they
    # keep |Gamma|^2 and Pi.Gamma over 500 steps.
    import learn

    damped = lp.systems.damped_heavy_top(gamma=0.5)
    model = learn.LPNet(damped, hidden=(8, 8), key=seed, h=0.1)
    y0 = np.array([0.2, 0.1, 1.0, 0.1, 0.2, 0.97])
    y = np.asarray(model.rollout(y0, 500))
    C = np.asarray(damped.casimirs(y))
    # each step is rounding only: a random walk of 500 steps of a few eps times |y|^2
    assert np.max(np.abs(C - C[0])) <= 1e-13 * max(1.0, float(np.max(np.abs(y))) ** 2)
