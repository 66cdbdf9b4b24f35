"""A gyroscope bias per group of trajectories (`learn.BodyLoss(bias=True)`, `Fitted.shared`):
the structured Jacobian with shared unknowns against the dense one, and the biases of two
recording sessions found from their flights."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS

import integrators as it
import learn
from integrators.splitting import Strang, TripleJump
from liepoisson.systems import RigidBody

BODY = RigidBody((1.0, 1.9, 2.1))
BETA = {"a": np.array([0.05, -0.03, 0.04]), "b": np.array([-0.02, 0.01, 0.06])}


def _sessions(n_steps: int = 41):
    """Four flights about the intermediate axis in two sessions, their rates read with the
    session's bias (exact otherwise)."""
    omega = np.array([[0.1, 8.0, 0.2], [0.3, -9.0, 0.1], [-0.2, 10.0, 0.3], [0.2, 7.0, -0.3]])
    exact = it.observe_body(BODY, omega * BODY.inertia, np.tile([0, 0, 0, 1.0], (4, 1)), np.arange(n_steps) * 0.01,
                            measure="velocities")
    groups = ["a", "b", "a", "b"]
    return it.BodyObservations(BODY, exact.times, velocities=[v + BETA[g] for v, g in zip(exact.velocities, groups)],
                               groups=groups)


def _net(method=TripleJump):
    terms = learn.RidgeTerms(3, 3, activation="identity", full_vectors=False, linear_term=False, bias=False)
    terms = eqx.tree_at(lambda t: (t.a, t.c), terms, (jnp.asarray(1.0 / BODY.inertia), jnp.ones(3)))
    return learn.GLPNet(BODY, terms=terms, method=method)


def _problem():
    data = _sessions(4)
    return learn.BodyLoss(bias=True).problem(_net(Strang), data, h=None, validation_fraction=0.0, seed=0,
                                             normalise=False)


def _at_a_bias(problem):
    """The start of `problem` with biases of half the true ones, and the dense Jacobian there
    (`jax.jacfwd` of the residuals over every unknown, in `Fitted`'s order)."""
    y = problem.y0
    assert y.shared.shape == (2, 3)  # one bias per session, not per flight
    y = eqx.tree_at(lambda f: f.shared, y, jnp.asarray([BETA["a"], BETA["b"]]) * 0.5)
    objective = problem.objective
    r, J = eqx.filter_jit(lambda y, a: learn.AbstractLeastSquares.jacobian(objective, y, a))(y, problem.train)
    assert float(jnp.max(jnp.abs(J[:, -6:]))) > 0.1  # the bias columns are there, last
    return y, r, J, float(jnp.max(jnp.abs(J)))


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_the_normal_equations_with_a_shared_bias_are_the_dense_ones():
    problem = _problem()
    y, r_dense, J_dense, scale = _at_a_bias(problem)
    r, A, g = eqx.filter_jit(problem.objective.normal_equations)(y, problem.train)
    np.testing.assert_array_equal(np.asarray(r), np.asarray(r_dense))
    # the same derivatives by two automatic-differentiation paths, summed in other orders:
    # agreement to round-off of the rollout (a few hundred flops per entry), 1e3 eps
    np.testing.assert_allclose(np.asarray(A), np.asarray(J_dense.T @ J_dense), rtol=0, atol=1e3 * EPS * scale**2)
    np.testing.assert_allclose(np.asarray(g), np.asarray(J_dense.T @ r_dense), rtol=0,
                               atol=1e3 * EPS * scale * float(jnp.linalg.norm(r_dense)))


@pytest.mark.slow  # ~20 s: two Jacobians compiled
def test_the_structured_jacobian_with_a_shared_bias_is_the_dense_one():
    problem = _problem()
    y, r_dense, J_dense, scale = _at_a_bias(problem)
    r, J = eqx.filter_jit(problem.objective.jacobian)(y, problem.train)
    np.testing.assert_array_equal(np.asarray(r), np.asarray(r_dense))
    np.testing.assert_allclose(np.asarray(J), np.asarray(J_dense), rtol=0, atol=1e3 * EPS * scale)


@pytest.mark.slow  # ~20 s: one Levenberg-Marquardt fit over 4 flights
def test_each_sessions_gyroscope_bias_is_found_and_saved(tmp_path):
    data = _sessions()
    _, record = learn.fit(_net(), data, loss=learn.BodyLoss(max_step=0.005, bias=True),
                          optimiser=learn.LevenbergMarquardt(60), progress=False)
    # exact rates but for the biases: the misfit falls to the fit's tolerance and each
    # session's bias is found (the y-component, along the spin, least well: 1e-4 rad/s)
    assert record.train_loss < 1e-14
    np.testing.assert_allclose(record.gyro_bias, [BETA["a"], BETA["b"]], rtol=0, atol=1e-4)
    record.save(tmp_path / "record.h5")
    np.testing.assert_array_equal(learn.TrainingRecord.load(tmp_path / "record.h5").gyro_bias, record.gyro_bias)
    # without groups, one bias per flight: four of them
    flights = it.BodyObservations(BODY, data.times, velocities=data.velocities)
    problem = learn.BodyLoss(max_step=0.005, bias=True).problem(_net(), flights, h=None, validation_fraction=0.0,
                                                                 seed=0, normalise=False)
    assert problem.y0.shared.shape == (4, 3)
