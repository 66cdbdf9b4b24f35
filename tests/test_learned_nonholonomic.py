"""learn.DAlembertMap: the constraint and the learned energy kept for any weights; a fit to the
Suslov problem's velocities recovers its energy metric and its motion."""

import equinox as eqx
import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import integrators as it
import learn
import liepoisson as lp
from learn._models._nonholonomic import constraint_basis

EPS = np.finfo(np.float64).eps
INERTIA = np.array([1.0, 2.0, 3.0])
SUSLOV = lp.systems.suslov(INERTIA, (1.0, 1.0, 1.0))
# a vehicle whose velocity keeps two constraints: k = 4 admissible directions (the expm path)
VEHICLE = lp.systems.LiePoissonDAlembert(lp.systems.Kirchhoff(), [[0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                                                                   [0.3, 0.0, 0.0, 0.0, 0.0, 1.0]])


@settings(max_examples=2, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from(["suslov", "sleigh", "vehicle"]))
def test_any_weights_keep_the_constraint_and_the_learned_energy(seed, which):
    system = {"suslov": SUSLOV, "sleigh": lp.systems.chaplygin_sleigh(), "vehicle": VEHICLE}[which]
    model = learn.DAlembertMap(system, key=seed, h=0.1)
    # random metric too: the invariants hold for any L
    keys = jax.random.split(jax.random.PRNGKey(seed))
    model = eqx.tree_at(lambda m: (m.log_diagonal, m.lower), model,
                        (0.5 * jax.random.normal(keys[0], model.log_diagonal.shape),
                         0.5 * jax.random.normal(keys[1], model.lower.shape)))
    xi0 = np.asarray(system.body_velocity(system.project(np.random.default_rng(seed).normal(size=system.dim))))
    states = np.asarray(model.rollout(xi0, 300))
    C = system.constraints
    # C N w: each product sums dim terms of size |xi|: a few eps of |xi|
    defect = np.abs(states @ C.T) / (np.linalg.norm(C, axis=1) * np.linalg.norm(states, axis=-1, keepdims=True))
    assert np.max(defect) <= 1e-13
    energy = np.asarray(model.energy(states))
    # an orthogonal rotation and a triangular solve a step: round-off, growing at most linearly
    assert np.max(np.abs(energy - energy[0])) <= 300 * 64 * EPS * energy[0]


def test_at_rest_nothing_moves_and_bad_input_is_refused():
    model = learn.DAlembertMap(SUSLOV, key=0, h=0.1)
    assert np.all(np.asarray(model.step(np.zeros(3))) == 0.0)
    with pytest.raises(TypeError, match="LiePoissonDAlembert"):
        learn.DAlembertMap(lp.systems.RigidBody(INERTIA))
    with pytest.raises(ValueError, match="k >= 2"):
        learn.DAlembertMap(lp.systems.LiePoissonDAlembert(lp.systems.RigidBody(INERTIA), [[1.0, 0, 0], [0, 1.0, 0]]))
    with pytest.raises(ValueError, match="not both"):
        learn.DAlembertMap(SUSLOV, hidden=(4,), network=model.network)


def test_the_constraint_basis_is_orthonormal_admissible_and_fixed():
    # the sleigh's is the first two basis vectors, whatever LAPACK returns: maps saved in it load anywhere
    np.testing.assert_array_equal(constraint_basis(lp.systems.chaplygin_sleigh()), np.eye(3)[:, :2])
    for system in (SUSLOV, VEHICLE):
        N = constraint_basis(system)
        assert N.shape == (system.dim, system.dim - system.constraints.shape[0])
        np.testing.assert_allclose(N.T @ N, np.eye(N.shape[1]), atol=8 * EPS)
        assert np.max(np.abs(system.constraints @ N)) <= 8 * EPS


@pytest.mark.slow  # one Levenberg-Marquardt fit: ~15 s
def test_a_fit_to_suslov_velocities_recovers_the_energy_and_the_motion(tmp_path):
    rng = np.random.default_rng(0)
    y0 = rng.normal(size=(40, 3))
    y0 = np.asarray(SUSLOV.project(y0 / np.linalg.norm(y0, axis=1, keepdims=True)))
    xi = np.asarray(SUSLOV.body_velocity(it.ground_truth(SUSLOV, y0, 0.1, 20).states))
    fitted, _ = learn.fit(learn.DAlembertMap(SUSLOV, key=0, h=0.1), it.Trajectories(xi, 0.1, SUSLOV),
                          optimiser=learn.LevenbergMarquardt(100), validation_fraction=0.0)
    # the energy metric on the constraint plane, det 1: N^T I N normalised
    N = constraint_basis(SUSLOV)
    true = N.T @ np.diag(INERTIA) @ N
    true /= np.sqrt(np.linalg.det(true))
    L = np.asarray(fitted.metric_factor())
    np.testing.assert_allclose(L @ L.T, true, atol=1e-5)
    # a held-out start to t = 50: the true energy kept and the motion followed
    z0 = np.asarray(SUSLOV.project(np.array([0.2, -0.9, 0.4])))
    truth = np.asarray(SUSLOV.body_velocity(it.ground_truth(SUSLOV, z0[None], 0.1, 500).states[0]))
    pred = np.asarray(fitted.rollout(truth[0], 500))
    energy = 0.5 * np.einsum("ta,a,ta->t", pred, INERTIA, pred)
    assert np.max(np.abs(energy / energy[0] - 1.0)) <= 1e-4
    assert np.max(np.linalg.norm(pred - truth, axis=-1)) <= 1e-3 * np.linalg.norm(truth[0])
    # saved and read back: the same steps
    fitted.save(tmp_path / "map.h5")
    again = learn.load(tmp_path / "map.h5", SUSLOV)
    np.testing.assert_array_equal(np.asarray(again.rollout(truth[0], 10)), np.asarray(fitted.rollout(truth[0], 10)))


@pytest.mark.slow  # ~4 s (a lifted rollout compiled); the default run keeps the constraint tests
def test_the_lifted_step_moves_the_sleigh_with_the_mean_admissible_velocity():
    sleigh = lp.systems.chaplygin_sleigh()
    model = learn.DAlembertMap(sleigh, key=3, h=0.1)
    xi0 = np.asarray(sleigh.body_velocity(sleigh.project(np.array([0.8, 0.5, 0.3]))))
    g, xi = model.lifted_rollout(np.eye(3).reshape(9), xi0, 200)
    g, xi = np.asarray(g).reshape(-1, 3, 3), np.asarray(xi)
    # on SE(2): a rotation block and the row (0, 0, 1), to round-off of 200 products
    R = g[:, :2, :2]
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", R, R), np.broadcast_to(np.eye(2), R.shape), atol=200 * EPS)
    np.testing.assert_array_equal(g[:, 2], np.broadcast_to([0.0, 0.0, 1.0], (201, 3)))
    # the heading advances by h times the mean turning rate of the step (exp of a twist)
    heading = np.unwrap(lp.systems.sleigh_pose(g.reshape(-1, 9))[:, 0])
    np.testing.assert_allclose(np.diff(heading), 0.05 * (xi[1:, 0] + xi[:-1, 0]), atol=1e-13)
