"""Ground truth (heyoka Taylor) against SciPy DOP853, the paper's end points, conservation,
caching and input validation."""

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import integrators as it
import liepoisson as lp

EPS = np.finfo(np.float64).eps

SYSTEMS_AND_Y0 = [
    (lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)), [1 / np.sqrt(2), -1 / np.sqrt(2), 1.0]),
    (lp.systems.HeavyTop(), [0.3, -0.2, 0.5, 0.1, 0.6, 0.79]),
    (lp.systems.Kirchhoff(inertia=(1, 2, 1), mass=(1, 2, 1)), [1.0, 1.0, 1.0, -1.0, 1.0, 2.0]),
    (lp.systems.ExtendedPendulum(), [0.0, 1.0, 1.0]),
    (lp.systems.ChargedParticle(), [1.0, 0.5, 0.5, 1.0]),
]


@pytest.mark.parametrize("system, y0", SYSTEMS_AND_Y0, ids=lambda v: type(v).__name__)
def test_against_dop853(system, y0):
    # Independent reference: SciPy's DOP853 on the JAX vector field (shares no code with the
    # heyoka ODE beyond the Hamiltonian and tensor definitions).
    h, n = 0.1, 50
    gt = it.ground_truth(system, y0, h=h, n_steps=n)
    jitted = jax.jit(system.vector_field)
    field = lambda t, y: np.asarray(jitted(y))
    ref = solve_ivp(field, (0, h * n), y0, method="DOP853", t_eval=gt.times, rtol=1e-13, atol=1e-13)
    assert ref.success
    # DOP853 at rtol 1e-13 accumulates ~1e-12 over 50 steps; heyoka is far tighter.
    np.testing.assert_allclose(gt.states[0], ref.y.T, rtol=0, atol=1e-10)


def test_rigid_body_end_point():
    gt = it.ground_truth(lp.systems.RigidBody(inertia=(1, 2, 3)), [1 / np.sqrt(2), -1 / np.sqrt(2), 1.0], 0.1, 999)
    assert gt.times[-1] == pytest.approx(99.9)
    np.testing.assert_allclose(gt.states[0, -1], [0.426, 1.332, -0.212], atol=5e-3)


def test_charged_particle_end_point():
    gt = it.ground_truth(lp.systems.ChargedParticle(), [1.0, 0.5, 0.5, 1.0], 0.1, 20_000)
    assert gt.times[-1] == pytest.approx(2000.0)
    np.testing.assert_allclose(gt.states[0, -1], [0.119, 1.112, -0.627, 0.985], atol=5e-3)


@pytest.mark.parametrize("system, y0", [SYSTEMS_AND_Y0[0], SYSTEMS_AND_Y0[2]], ids=["RigidBody", "Kirchhoff"])
def test_casimir_drift_over_t_1000(system, y0):
    gt = it.ground_truth(system, y0, h=1.0, n_steps=1000)
    C = np.asarray(system.casimirs(gt.states[0]))
    drift = np.max(np.abs(C - C[0]) / np.maximum(np.abs(C[0]), 1.0))
    assert drift < 1e-13


def test_shapes_and_metadata():
    body = lp.systems.RigidBody()
    one = it.ground_truth(body, [1.0, 0.0, 0.5], h=0.1, n_steps=3)
    assert one.states.shape == (1, 4, 3) and one.n_traj == 1 and one.n_steps == 3 and one.dim == 3
    many = it.ground_truth(body, np.eye(3) + 0.1, h=0.1, n_steps=3)
    assert many.states.shape == (3, 4, 3) and many.states.dtype == np.float64
    np.testing.assert_array_equal(many.times, 0.1 * np.arange(4))
    np.testing.assert_array_equal(many.states[:, 0], np.eye(3) + 0.1)
    assert many.metadata["integrator"] == "heyoka-taylor" and many.tolerance == EPS
    # integrator reused across calls and across equal systems
    assert it.taylor_integrator(body) is it.taylor_integrator(lp.systems.RigidBody())
    assert it.taylor_integrator(body) is not it.taylor_integrator(lp.systems.RigidBody((1, 1, 2)))


def test_progress_bar_forced(capsys):
    it.ground_truth(lp.systems.RigidBody(), np.ones((2, 3)), 0.1, 2, progress=True)
    assert "ground truth" in capsys.readouterr().err


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"h": 0.0}, ValueError, ["h", "> 0", "0.0"]),
        ({"h": -0.1}, ValueError, ["h", "-0.1"]),
        ({"h": "a"}, TypeError, ["h"]),
        ({"n_steps": 0}, ValueError, ["n_steps", ">= 1", "0"]),
        ({"n_steps": 2.5}, TypeError, ["n_steps", "integer", "2.5"]),
        ({"y0": [np.nan, 0.0, 1.0]}, ValueError, ["y0", "finite", "nan"]),
        ({"y0": [1.0, 0.0]}, ValueError, ["y0", "3", "(2,)"]),
        ({"y0": np.ones((2, 2, 3))}, ValueError, ["y0", "(2, 2, 3)"]),
        ({"tol": -1.0}, ValueError, ["tol"]),
    ],
)
def test_validation(kwargs, error, words):
    args = {"y0": [1.0, 0.0, 0.5], "h": 0.1, "n_steps": 2} | kwargs
    with pytest.raises(error) as info:
        it.ground_truth(lp.systems.RigidBody(), **args)
    for w in words:
        assert w in str(info.value)
