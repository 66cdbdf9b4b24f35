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
    np.testing.assert_array_equal(lp.systems.chaplygin_sleigh().admissible_basis(), np.eye(3)[:, :2])
    for system in (SUSLOV, VEHICLE):
        N = system.admissible_basis()
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
    N = SUSLOV.admissible_basis()
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


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(1e-3, 2.0))
def test_the_quadratic_family_steps_by_the_exact_flow_of_its_field(seed, h):
    """`advance` against an independent integration of du/dt = (c . u) J u (DOP853 at 1e-13)."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(seed)
    c, u = 2.0 * rng.normal(size=2), rng.normal(size=2)
    model = eqx.tree_at(lambda m: m.rate, learn.QuadraticDAlembertMap(SUSLOV, h=h), jax.numpy.asarray(c))
    J = np.array([[0.0, -1.0], [1.0, 0.0]])
    reference = solve_ivp(lambda t, y: (c @ y) * (J @ y), (0.0, h), u, method="DOP853", rtol=1e-13,
                          atol=1e-15).y[:, -1]
    got = np.asarray(model.advance(jax.numpy.asarray(u), None))
    # the reference's tolerance 1e-13, times the growth of |c||u|h up to ~10 over the step
    np.testing.assert_allclose(got, reference, rtol=0, atol=1e-11 * np.linalg.norm(u))
    # a rotation: |u| kept to a few roundings
    assert abs(np.linalg.norm(got) - np.linalg.norm(u)) <= 8 * EPS * np.linalg.norm(u)


@pytest.mark.slow  # ~2.5 s; the family's step against DOP853 by default above
def test_the_quadratic_family_is_smooth_where_it_does_not_move():
    model = eqx.tree_at(lambda m: m.rate, learn.QuadraticDAlembertMap(SUSLOV, h=0.1), jax.numpy.asarray([0.3, -0.2]))
    u = jax.numpy.asarray([0.4, 0.6])  # c . u = 0: an equilibrium of du/dt = (c . u) J u
    np.testing.assert_allclose(np.asarray(model.advance(u, None)), np.asarray(u), rtol=0, atol=4 * EPS)
    for point in (jax.numpy.zeros(2), u, 1e-9 * u + jax.numpy.asarray([1e-9, 0.0])):  # at rest, near the series
        grad = jax.jacfwd(lambda m, point=point: m.advance(point, None))(model)
        assert np.all(np.isfinite(np.asarray(grad.rate))) and np.all(np.isfinite(np.asarray(model.advance(point, None))))
    # the series and the closed form agree across the switch x = h|c||u| = 1e-4
    c = jax.numpy.asarray([1.0, 0.5])
    near = eqx.tree_at(lambda m: m.rate, model, c)
    for scale in (0.999e-4, 1.001e-4):
        v = scale / (0.1 * np.linalg.norm(c)) * jax.numpy.asarray([0.6, 0.8])  # x = scale
        step = np.asarray(near.advance(v, None))
        # the angle turned, against the angle psi of u from c in closed form:
        # sin psi(h) = tanh(x + artanh sin psi_0) (c . v > 0: psi stays in (-pi/2, pi/2))
        angle = np.arctan2(v[0] * step[1] - v[1] * step[0], v @ step)
        s0 = float(c[0] * v[1] - c[1] * v[0]) / (np.linalg.norm(c) * np.linalg.norm(v))
        expected = np.arcsin(np.tanh(scale + np.arctanh(s0))) - np.arcsin(s0)
        # an angle of ~1e-4 from differences of O(1) numbers: ~1e-16 absolute, 1e-11 relative
        assert angle == pytest.approx(expected, rel=1e-9)


# the Suslov problem (~3 s, heyoka's compilation) under -m slow; its exact flow's figures are
# W6's (python -m paper run W6), the sleigh's by default
@pytest.mark.parametrize("which", [pytest.param("suslov", marks=pytest.mark.slow), "sleigh"])
def test_from_system_is_the_exact_flow_of_the_suslov_problem_and_the_sleigh(which):
    system = {"suslov": SUSLOV, "sleigh": lp.systems.chaplygin_sleigh(1.0, 1.0, 0.5)}[which]
    exact = learn.QuadraticDAlembertMap.from_system(system, h=0.1)
    mu0 = np.asarray(system.project(np.random.default_rng(4).normal(size=(3, 3))))
    truth = it.ground_truth(system, mu0, 0.1, 500)
    xi = np.asarray(system.body_velocity(truth.states))
    predicted = np.asarray(exact.rollout(xi[:, 0], 500))
    # heyoka at eps and a closed-form step: round-off over 500 steps, amplified by the transient
    # (the Suslov body leaves an unstable rotation): 1e-12 of the velocities' size
    np.testing.assert_allclose(predicted, xi, rtol=0, atol=1e-12 * np.max(np.abs(xi)))


def test_the_quadratic_family_refuses_what_it_cannot_hold():
    with pytest.raises(ValueError, match="k = 2"):
        learn.QuadraticDAlembertMap(VEHICLE)
    quartic = lp.systems.LiePoissonDAlembert(
        lp.systems.LiePoissonSystem(lp.so3(), lambda y, xp: 0.5 * (y[0] ** 2 + y[1] ** 2 + y[2] ** 2) + 0.1 * y[0] ** 4),
        (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="not quadratic"):
        learn.QuadraticDAlembertMap.from_system(quartic, h=0.1)
    with pytest.raises(ValueError, match="not quadratic"):
        quartic.kinetic_metric()
    with pytest.raises(TypeError, match="LiePoissonDAlembert"):
        learn.QuadraticDAlembertMap(lp.systems.RigidBody((1.0, 2.0, 3.0)))


@pytest.mark.slow  # a fit: 5 s; from_system's exact flow is tested in the default run
def test_a_fit_of_the_quadratic_family_to_exact_velocities_is_the_exact_flow(tmp_path):
    rng = np.random.default_rng(0)
    mu0 = np.asarray(SUSLOV.project(rng.normal(size=(8, 3))))
    xi = np.asarray(SUSLOV.body_velocity(it.ground_truth(SUSLOV, mu0, 0.1, 10).states))
    data = it.Observations(SUSLOV, 0.1 * np.arange(11), list(xi))
    fitted, _ = learn.fit(learn.QuadraticDAlembertMap(SUSLOV, h=0.1), data, optimiser=learn.LevenbergMarquardt(40),
                          validation_fraction=0.0, progress=False)
    exact = learn.QuadraticDAlembertMap.from_system(SUSLOV, h=0.1)
    # four identifiable parameters from 80 exact pairs: the system's, to the data's round-off
    # amplified by the fit's conditioning
    for name in ("rate", "log_diagonal", "lower"):
        np.testing.assert_allclose(np.asarray(getattr(fitted, name)), np.asarray(getattr(exact, name)), atol=1e-9)
    fitted.save(tmp_path / "q.h5")
    again = learn.load(tmp_path / "q.h5", SUSLOV)
    assert isinstance(again, learn.QuadraticDAlembertMap)
    np.testing.assert_array_equal(np.asarray(again.rate), np.asarray(fitted.rate))


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0, 1]))
def test_a_mirror_symmetric_family_commutes_with_its_reflection_for_any_weights(seed, i):
    sleigh = lp.systems.chaplygin_sleigh()
    rng = np.random.default_rng(seed)

    def randomised(model):
        return eqx.tree_at(lambda m: (m.rate, m.log_diagonal, m.lower), model,
                           tuple(jax.numpy.asarray(rng.normal(size=n)) for n in (2, 2, 1)))

    mirror = randomised(learn.QuadraticDAlembertMap(sleigh, h=0.3, reflection=i))
    n = mirror.basis[:, i]
    S = np.eye(3) - 2.0 * np.outer(n, n)  # flips the i-th admissible direction
    xi = np.asarray(sleigh.body_velocity(sleigh.project(rng.normal(size=3))))
    # a closed-form step of a few roundings on either side
    np.testing.assert_allclose(np.asarray(mirror.step(S @ xi)), S @ np.asarray(mirror.step(xi)), rtol=0,
                               atol=64 * EPS * np.linalg.norm(xi))
    # the unrestricted family with the same weights is not symmetric (the test can fail)
    free = eqx.tree_at(lambda m: (m.rate, m.log_diagonal, m.lower), learn.QuadraticDAlembertMap(sleigh, h=0.3),
                       (mirror.rate, mirror.log_diagonal, mirror.lower))
    assert np.max(np.abs(np.asarray(free.step(S @ xi)) - S @ np.asarray(free.step(xi)))) > 1e-6 * np.linalg.norm(xi)


def test_the_mirror_family_is_saved_with_its_reflection_and_bad_ones_are_refused(tmp_path):
    sleigh = lp.systems.chaplygin_sleigh()
    model = learn.QuadraticDAlembertMap(sleigh, h=0.1, reflection=0)
    model.save(tmp_path / "m.h5")
    again = learn.load(tmp_path / "m.h5", sleigh)
    assert isinstance(again, learn.QuadraticDAlembertMap) and again.reflection == 0
    # without system=: the sleigh rebuilt from the file, its SE(2) too, so the pose still moves
    alone = learn.load(tmp_path / "m.h5")
    g, xi = np.eye(3).reshape(9), np.array([0.3, 1.0, 0.0])
    np.testing.assert_allclose(np.asarray(alone.lifted_step(g, xi)[0]), np.asarray(model.lifted_step(g, xi)[0]),
                               rtol=0, atol=0)
    for bad in (2, -1, True, "0", 0.0):
        with pytest.raises(ValueError, match="reflection must be None or the index 0 or 1"):
            learn.QuadraticDAlembertMap(sleigh, reflection=bad)
