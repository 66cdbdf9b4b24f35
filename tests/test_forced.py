"""Forced Lie-Poisson systems (`liepoisson.systems.Forced`: linear and quadratic drag, constant
torques in the body frame) and their splitting (`integrators.ForcedSplitting`): heyoka's ground
truth against SciPy's DOP853, the energy rate against closed forms, the forces' flow against an
independent integrator, orders 2 and 4 against heyoka, the energy never increasing, degenerate
states and bad input."""

from __future__ import annotations

import functools

import jax
import numpy as np
import pytest
from helpers import EPS
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import integrators as it
import liepoisson as lp
from integrators.splitting import Strang, TripleJump
from liepoisson.systems import (
    ConstantTorque,
    Forced,
    FreeRigidBodyTerm,
    Kirchhoff,
    LiePoissonSystem,
    LinearDrag,
    QuadraticDrag,
    RigidBody,
)

INERTIA = (1.0, 1.9, 2.1)  # a racquet: the two larger moments close
D_ANY_AXES = [[0.02, 0.005, 0.0], [0.005, 0.03, 0.0], [0.0, 0.0, 0.01]]


@functools.cache
def _forced_body() -> Forced:
    return Forced(RigidBody(INERTIA), [QuadraticDrag(D_ANY_AXES), LinearDrag(0.01), ConstantTorque([0.0, 0.01, 0.0])])


@functools.cache
def _forced_vehicle() -> Forced:
    return Forced(Kirchhoff(), [QuadraticDrag(0.05, indices=(0, 1, 2)),
                                QuadraticDrag([0.1, 0.2, 0.3], indices=(3, 4, 5))])


def _dop853(system, y0, t):
    """SciPy's DOP853 at its tightest practical tolerances on the system's JAX vector field."""
    field = jax.jit(system.vector_field)
    sol = solve_ivp(lambda _, y: np.asarray(field(y)), (0.0, t[-1]), y0, method="DOP853", rtol=1e-13,
                    atol=1e-14, t_eval=t)
    assert sol.success
    return sol.y.T


@pytest.mark.parametrize("make, y0", [(_forced_body, [0.3, 10.0, 0.2]),
                                      (_forced_vehicle, [0.3, 1.0, 0.2, 0.5, -0.2, 1.0])])
def test_ground_truth_against_dop853(make, y0):
    # two independent integrators of the same ODE (heyoka from the symbolic Hamiltonian and the
    # forces' expressions; DOP853 on the JAX vector field): 1e-10, the issue's figure, is
    # ~10^3 roundings of the states' size accumulated over 40 outputs
    system, y0 = make(), np.array(y0)
    traj = it.ground_truth(system, y0[None], h=0.05, n_steps=40, progress=False)
    reference = _dop853(system, y0, np.arange(41) * 0.05)
    np.testing.assert_allclose(np.asarray(traj.states[0]), reference, rtol=0, atol=1e-10 * np.abs(y0).max())
    # what the forces change: the energy and |Pi|^2 decrease, at the rates the system states
    H = np.asarray(system.hamiltonian(traj.states[0]))
    assert H[-1] < H[0]


def test_vector_field_and_rates_against_closed_forms():
    body = RigidBody(INERTIA)
    D = np.array(D_ANY_AXES)
    system = Forced(body, [QuadraticDrag(D), LinearDrag(0.01), ConstantTorque([0.0, 0.01, 0.0])])
    Pi = np.array([0.3, -1.1, 0.8])
    Omega = Pi / np.array(INERTIA)
    F = -np.linalg.norm(Omega) * D @ Omega - 0.01 * Omega + np.array([0.0, 0.01, 0.0])
    # closed forms evaluated in numpy: a few roundings of the largest term
    np.testing.assert_allclose(np.asarray(system.vector_field(Pi)), np.cross(Pi, Omega) + F, atol=16 * EPS)
    np.testing.assert_allclose(float(system.energy_rate(Pi)), Omega @ F, atol=16 * EPS)
    # Casimir |Pi|^2 (up to the algebra's normalisation): its rate by a central difference
    v = np.asarray(system.vector_field(Pi))
    eps = 1e-6
    fd = (np.asarray(system.casimirs(Pi + eps * v)) - np.asarray(system.casimirs(Pi - eps * v))) / (2 * eps)
    np.testing.assert_allclose(np.asarray(system.casimir_rates(Pi)), fd, rtol=1e-8)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_dissipative_forces_never_raise_the_energy(seed):
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(3, 3))
    D = M @ M.T * rng.uniform(0.0, 2.0)
    system = Forced(RigidBody(rng.uniform(0.5, 3.0, size=3)), [QuadraticDrag(D), LinearDrag(np.diag(np.diag(D)))])
    Pi = rng.normal(size=(16, 3)) * rng.uniform(0.01, 30.0)
    assert np.all(np.asarray(system.energy_rate(Pi)) <= 0.0)


@pytest.mark.slow  # the default run's time; the affine flow also enters the order tests
def test_linear_drag_flow_is_exact():
    # the forces alone, mu' = -D (A mu + b): the affine exponential against DOP853
    system = Forced(lp.systems.HeavyTop(), LinearDrag(np.diag([0.3, 0.2, 0.5]), indices=(0, 1, 2)))
    A, b = system.quadratic_hamiltonian()
    D = LinearDrag(np.diag([0.3, 0.2, 0.5]), indices=(0, 1, 2)).embedded(6)
    y0 = np.array([0.3, -1.0, 2.0, 0.1, 0.2, 0.9])
    sol = solve_ivp(lambda _, y: -D @ (A @ y + b), (0.0, 1.7), y0, method="DOP853", rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(np.asarray(system.force_flow(1.7, y0)), sol.y[:, -1], atol=1e-12)


@pytest.mark.parametrize("method, order", [(Strang, 2), pytest.param(TripleJump, 4, marks=pytest.mark.slow)])
def test_orders_against_heyoka(method, order):
    system = _forced_body()
    y0, T = np.array([0.3, 10.0, 0.2]), 2.0
    reference = np.asarray(it.ground_truth(system, y0[None], h=T, n_steps=1, progress=False).states[0, -1])
    errors = [np.abs(np.asarray(it.ForcedSplitting(system, T / n, method).rollout(y0, n))[-1] - reference).max()
              for n in (100, 200)]
    # halving h divides the error by 2^order: measured 3.99 / 15.99 (the asymptotic regime)
    assert abs(np.log2(errors[0] / errors[1]) - order) < 0.1


@pytest.mark.slow  # 10 s; the orders on so(3) by default above
def test_lifted_orders_on_a_vehicle_against_heyoka():
    # se(3): drag on rotation and on translation, each with its own |xi|; the pose reconstructed
    system = _forced_vehicle()
    y0, g0, T = np.array([0.3, 1.0, 0.2, 0.5, -0.2, 1.0]), np.array([0, 0, 0, 1.0, 0, 0, 0]), 1.0
    truth = it.ground_truth(system, y0[None], h=T, n_steps=1, progress=False, g0=g0)
    for method, order in ((Strang, 2), (TripleJump, 4)):
        errors = []
        for n in (20, 40):
            g, y = it.ForcedSplitting(system, T / n, method).lifted_rollout(g0, y0, n)
            errors.append(max(np.abs(np.asarray(y)[-1] - np.asarray(truth.states[0, -1])).max(),
                              np.abs(np.asarray(g)[-1] - np.asarray(truth.configurations[0, -1])).max()))
        assert abs(np.log2(errors[0] / errors[1]) - order) < 0.1


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(1e-3, 50.0))
def test_forces_flow_never_raises_the_energy_for_any_step(seed, t):
    # the midpoint discrete gradient: H(mu1) - H(mu0) = -t xi_bar^T D_bar xi_bar exactly for a
    # quadratic H, whatever the step and the weights; round-off allowed: 64 eps of H's size
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(3, 3))
    body = RigidBody(rng.uniform(0.2, 3.0, size=3))
    system = Forced(body, [QuadraticDrag(M @ M.T), LinearDrag(rng.uniform(0.0, 1.0, size=3))])
    Pi = rng.normal(size=(8, 3)) * rng.uniform(0.1, 30.0)
    H0 = np.asarray(body.hamiltonian(Pi))
    H1 = np.asarray(body.hamiltonian(system.force_flow(t, Pi)))
    assert np.all(H1 <= H0 + 64 * EPS * np.abs(H0))


@pytest.mark.slow  # 8 s (the elliptic flow's compilation); the forces' flow alone by default above
def test_strang_with_the_exact_body_never_raises_the_energy():
    # the conservative piece the rigid body's exact flow (keeps H), the forces' flow lowers it:
    # every step, at a step far beyond accuracy
    body = RigidBody(INERTIA)
    system = Forced(body, QuadraticDrag([[0.2, 0.05, 0.0], [0.05, 0.3, 0.0], [0.0, 0.0, 0.1]]))
    step = it.ForcedSplitting(system, 0.3, Strang, terms=[FreeRigidBodyTerm(body.inertia)])
    H = np.asarray(body.hamiltonian(step.rollout(np.array([0.3, 10.0, 0.2]), 200)))
    # the exact flow keeps H to ~10 roundings a step (elliptic functions)
    assert np.all(np.diff(H) <= 32 * EPS * H[:-1])
    assert H[-1] < 0.01 * H[0]


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_zero_velocity_no_nan():
    system = Forced(RigidBody(INERTIA), [QuadraticDrag(0.1), LinearDrag(0.1)])
    step = it.ForcedSplitting(system, 0.1)
    np.testing.assert_array_equal(np.asarray(step.rollout(np.zeros(3), 3)), np.zeros((4, 3)))
    jac = np.asarray(jax.jacfwd(step.step)(np.zeros(3)))
    assert np.all(np.isfinite(jac))
    assert np.all(np.isfinite(np.asarray(jax.jacfwd(system.vector_field)(np.zeros(3)))))


def test_heyoka_refuses_a_start_of_zero_velocity_under_quadratic_drag():
    with pytest.raises(ValueError, match=r"y0\[1\].*zero body velocity.*not differentiable"):
        it.ground_truth(_forced_body(), np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]), h=0.1, n_steps=2,
                        progress=False)


def test_files_and_names_round_trip(tmp_path):
    system = _forced_body()
    assert lp.systems.from_name(system.name, system.params) == system
    path = tmp_path / "forced.h5"
    it.save_ground_truth(str(path), system, np.array([[0.3, 10.0, 0.2]]), h=0.05, n_steps=4, progress=False)
    back = it.Trajectories.load(str(path))
    assert back.system == system
    np.testing.assert_allclose(np.asarray(back.states[0, 0]), [0.3, 10.0, 0.2])


@pytest.mark.parametrize("D, match", [
    ([[1.0, 0.5], [0.0, 1.0]], "symmetric"),
    ([[1.0, 0.0], [0.0, -1.0]], "positive semidefinite"),
    ([[1.0, np.nan], [np.nan, 1.0]], "finite"),
    (np.ones((2, 3)), "square"),
])
def test_bad_drag_matrices(D, match):
    with pytest.raises(ValueError, match=match):
        QuadraticDrag(D)


def test_bad_systems_and_forces():
    body = RigidBody(INERTIA)
    with pytest.raises(ValueError, match=r"forces\[0\].*\(2, 2\) drag acting on 3 components"):
        Forced(body, LinearDrag(np.eye(2)))
    with pytest.raises(ValueError, match=r"forces\[0\].*beyond the system's 3"):
        Forced(body, LinearDrag(np.eye(2), indices=(2, 3)))
    with pytest.raises(TypeError, match="forces must be"):
        Forced(body, ["drag"])
    with pytest.raises(TypeError, match="already forced"):
        Forced(Forced(body, LinearDrag(0.1)), LinearDrag(0.1))
    with pytest.raises(TypeError, match="Hamiltonian Lie-Poisson system"):
        Forced(lp.systems.damped_rigid_body(), LinearDrag(0.1))
    with pytest.raises(TypeError, match="indices"):
        LinearDrag(0.1, indices=(0.5, 1))
    with pytest.raises(ValueError, match="torque must be finite"):
        ConstantTorque([0.0, np.inf, 0.0])
    forced = Forced(body, LinearDrag(0.1))
    # what would silently drop the forces is refused
    with pytest.raises(ValueError, match="ForcedSplitting"):
        Strang(forced, 0.1)
    with pytest.raises(ValueError, match="forced"):
        it.LieEuler(forced, 0.1)
    with pytest.raises(ValueError, match="h must be"):
        it.ForcedSplitting(forced, -0.1)
    with pytest.raises(TypeError, match="liepoisson.systems.Forced"):
        it.ForcedSplitting(body, 0.1)


def test_non_quadratic_hamiltonian_refused_by_the_splitting():
    quartic = LiePoissonSystem(lp.so3(), lambda m, xp: 0.25 * (m[0] ** 4 + m[1] ** 2 + m[2] ** 2), name="quartic")
    with pytest.raises(ValueError, match="not quadratic.*ground_truth"):
        it.ForcedSplitting(Forced(quartic, QuadraticDrag(0.1)), 0.1)
