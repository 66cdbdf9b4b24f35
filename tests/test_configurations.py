"""Configurations beside momenta: the groups (SO(3) as unit quaternions, SE(3) as poses, matrix
groups), heyoka's ground truth of (g, mu), and the exact reconstruction of splitting and
G-LPNet steps."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

import integrators as it
import learn
import liepoisson as lp
from integrators.splitting import Strang, TripleJump

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody((2.0, 1.0, 2.0 / 3.0))
VEHICLE = lp.systems.Kirchhoff()

vectors = st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3).map(np.array)


def homogeneous(q, x):
    H = np.eye(4)
    H[:3, :3] = Rotation.from_quat(q).as_matrix()
    H[:3, 3] = x
    return H


@settings(max_examples=30, deadline=None)
@given(vectors, vectors, st.sampled_from([1.0, 1e-3, 1e-6, 0.0]))
def test_group_exponentials_agree_with_the_matrix_exponential(phi, v, scale):
    # scale takes the rotation through the series branches (theta^2 < 1e-6 and 1e-4) and 0
    phi = phi * scale
    q0 = Rotation.from_rotvec([0.3, -1.2, 0.4]).as_quat()
    R = lp.Rotations()
    q1 = np.asarray(R.right_exp(q0, phi))
    want = Rotation.from_quat(q0).as_matrix() @ expm(np.einsum("a,aij->ij", phi, R.matrix_basis()))
    # a few roundings of products of O(1) numbers
    np.testing.assert_allclose(Rotation.from_quat(q1).as_matrix(), want, atol=20 * EPS)
    assert abs(np.linalg.norm(q1) - 1.0) <= 2 * EPS
    P = lp.Poses()
    x0 = np.array([1.0, -2.0, 0.5])
    g1 = np.asarray(P.right_exp(np.r_[q0, x0], np.r_[phi, v]))
    H1 = homogeneous(q0, x0) @ expm(np.einsum("a,aij->ij", np.r_[phi, v], P.matrix_basis()))
    np.testing.assert_allclose(Rotation.from_quat(g1[:4]).as_matrix(), H1[:3, :3], atol=20 * EPS)
    np.testing.assert_allclose(g1[4:], H1[:3, 3], atol=50 * EPS * (1 + np.abs(v).max()))
    assert np.all(np.isfinite(g1))


@pytest.mark.slow  # a matrix group reconstructs like the quaternions by default below
def test_matrix_group_of_se3_agrees_with_poses():
    P = lp.Poses()
    M = lp.MatrixGroup(P.matrix_basis())
    rng = np.random.default_rng(1)
    q, x, xi, mu = Rotation.random(random_state=2).as_quat(), rng.normal(size=3), rng.normal(size=6), rng.normal(size=6)
    g = homogeneous(q, x).reshape(-1)
    np.testing.assert_allclose(np.asarray(M.right_exp(g, xi)).reshape(4, 4),
                               homogeneous(*np.split(np.asarray(P.right_exp(np.r_[q, x], xi)), [4])), atol=50 * EPS)
    # J = Ad*_{g^-1} mu: a solve and a projection (general) against the closed form of SE(3)
    np.testing.assert_allclose(M.spatial_momentum(g, mu), P.spatial_momentum(np.r_[q, x], mu), atol=50 * EPS)


def test_the_catalogue_algebras_have_their_groups_and_others_none():
    assert BODY.group == lp.Rotations() and VEHICLE.group == lp.Poses()
    assert lp.systems.LiePoissonSystem(lp.sl2(), lambda m, xp: m[0] ** 2 + m[1] * m[2]).group is None
    with pytest.raises(ValueError, match="no configuration group"):
        lp.systems.LiePoissonSystem(lp.sl2(), lambda m, xp: m[0] ** 2 + m[1] * m[2]).require_group()


@pytest.mark.parametrize("system", [BODY, VEHICLE], ids=["rigid body", "Kirchhoff"])
def test_heyoka_reconstruction_keeps_the_spatial_momentum_and_the_unit_quaternion(system):
    rng = np.random.default_rng(3)
    y0 = rng.normal(size=(2, system.dim))
    q0 = Rotation.random(2, random_state=4).as_quat()
    g0 = q0 if system.group.size == 4 else np.concatenate([q0, rng.normal(size=(2, 3))], axis=1)
    truth = it.ground_truth(system, y0, 0.5, 40, g0=g0)
    assert truth.configurations.shape == (2, 41, system.group.size)
    np.testing.assert_array_equal(truth.configurations[:, 0], g0 / np.linalg.norm(g0[:, :4], axis=1, keepdims=True)
                                  if system.group.size == 4 else truth.configurations[:, 0])
    J = np.asarray(system.spatial_momentum(truth.configurations, truth.states))
    scale = np.abs(J).max()
    # heyoka at tolerance eps: a random walk of roundings over ~10^3 Taylor steps
    assert np.abs(J - J[:, :1]).max() <= 1e3 * EPS * scale
    assert np.abs(np.linalg.norm(truth.configurations[..., :4], axis=-1) - 1.0).max() <= 1e3 * EPS
    # the momenta are those of the ground truth without configurations
    np.testing.assert_allclose(truth.states, it.ground_truth(system, y0, 0.5, 40).states, atol=1e3 * EPS * scale)


# Kirchhoff's poses (SE(3)) under -m slow (~10 s each); by default the rigid body's rotations, by
# Strang (TripleJump composes the same lifted steps: -m slow)
@pytest.mark.parametrize("system", [BODY, pytest.param(VEHICLE, marks=pytest.mark.slow)], ids=["rigid body", "Kirchhoff"])
@pytest.mark.parametrize(("method", "order"), [(Strang(), 2), pytest.param(TripleJump(), 4, marks=pytest.mark.slow)])
def test_lifted_splitting_has_the_methods_order_on_configuration_and_momentum(system, method, order):
    rng = np.random.default_rng(5)
    y0 = rng.normal(size=(3, system.dim))
    q0 = Rotation.random(3, random_state=6).as_quat()
    g0 = q0 if system.group.size == 4 else np.concatenate([q0, rng.normal(size=(3, 3))], axis=1)
    truth = it.ground_truth(system, y0, 1.0, 1, g0=g0)
    errors = []
    for n in (10, 20, 40):
        gs, ys = it.Splitting(system, 1.0 / n, method).lifted_rollout(g0, y0, n)
        errors.append(max(np.abs(gs[:, -1] - truth.configurations[:, -1]).max(),
                          np.abs(ys[:, -1] - truth.states[:, -1]).max()))
    observed = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(observed - order) < 0.1), observed


@pytest.mark.slow
def test_a_million_steps_keep_the_unit_quaternion_and_the_spatial_momentum():
    g0 = Rotation.from_rotvec([0.4, -0.7, 0.5]).as_quat()
    y0 = np.array([0.6, -0.5, 0.62])
    n = 10**6
    gs, ys = it.Splitting(BODY, 0.1, Strang()).lifted_rollout(g0, y0, n, save_every=10**4)
    # each step renormalises the quaternion: within a rounding, not a random walk
    assert np.abs(np.linalg.norm(gs, axis=-1) - 1.0).max() <= 2 * EPS
    J = np.asarray(BODY.spatial_momentum(gs, ys))
    # a random walk of a few roundings per step: ~ eps sqrt(n) (measured 6e-12 relative)
    assert np.abs(J - J[:1]).max() <= 100 * EPS * np.sqrt(n) * np.linalg.norm(y0)


def test_glpnet_steps_carry_the_configuration_exactly():
    net = learn.GLPNet(BODY, key=3, method=Strang, h=0.1)
    rng = np.random.default_rng(7)
    y0 = rng.normal(size=(4, 3))
    g0 = Rotation.random(4, random_state=8).as_quat()
    gs, ys = net.lifted_rollout(g0, y0, 200)
    np.testing.assert_array_equal(ys, net.rollout(y0, 200))  # the momentum part is the step
    J = np.asarray(BODY.spatial_momentum(gs, ys))
    assert np.abs(J - J[:, :1]).max() <= 200 * 10 * EPS * np.abs(J).max()  # ~10 roundings a step at most
    # second order in (g, mu) for the learned H: Strang at h against TripleJump at h/16
    T = 0.8
    ref_g, ref_y = learn.GLPNet(BODY, key=3, method=TripleJump, h=T / 64).lifted_rollout(g0, y0, 64)
    errors = []
    for n in (8, 16):
        g, y = net.with_h(T / n).lifted_rollout(g0, y0, n)
        errors.append(max(np.abs(g[:, -1] - ref_g[:, -1]).max(), np.abs(y[:, -1] - ref_y[:, -1]).max()))
    assert abs(np.log2(errors[0] / errors[1]) - 2.0) < 0.15, errors


# -- bad input ------------------------------------------------------------------------------
def test_quaternions_off_the_unit_sphere_are_refused_and_near_ones_normalised():
    q = np.array([0.0, 0.0, 0.6, 0.8])
    np.testing.assert_allclose(np.linalg.norm(lp.Rotations().check(q * (1 + 5e-7))), 1.0, atol=EPS)
    with pytest.raises(ValueError, match=r"g0\[1\] must hold a unit quaternion .* norm is 1\.01"):
        it.Splitting(BODY, 0.1, Strang()).lifted_rollout(np.stack([q, 1.01 * q]), np.ones((2, 3)), 3)
    with pytest.raises(ValueError, match="must be finite"):
        lp.Rotations().check([0.0, np.nan, 0.0, 1.0])
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 4\)"):
        lp.Rotations().check([0.0, 0.0, 1.0])


def test_rotation_matrices_that_are_not_rotations_are_refused():
    R = Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix()
    np.testing.assert_allclose(lp.Rotations.from_matrix(R), Rotation.from_matrix(R).as_quat())
    with pytest.raises(ValueError, match="reflection"):
        lp.Rotations.from_matrix(-R)
    with pytest.raises(ValueError, match=r"R\[1\] is not a rotation matrix: max \|R\^T R - 1\|"):
        lp.Rotations.from_matrix(np.stack([R, 1.01 * R]))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3, 3\)"):
        lp.Rotations.from_matrix(np.eye(4))
    with pytest.raises(TypeError, match="scipy.spatial.transform.Rotation"):
        lp.Rotations.from_scipy(R)
    assert lp.Rotations.to_scipy(lp.Rotations.from_scipy(Rotation.from_matrix(R))).approx_equal(Rotation.from_matrix(R))


def test_mismatched_configurations_and_states_are_refused():
    split = it.Splitting(BODY, 0.1, Strang())
    q = Rotation.random(3, random_state=1).as_quat()
    with pytest.raises(ValueError, match="as many initial conditions"):
        split.lifted_rollout(q, np.ones((2, 3)), 3)
    with pytest.raises(ValueError, match=r"g0 must have shape \(4,\) or \(2, 4\)"):
        it.ground_truth(BODY, np.ones((2, 3)), 0.1, 3, g0=q)
    with pytest.raises(ValueError, match=r"configurations must have shape \(1, 4, 4\)"):
        it.Trajectories(np.ones((1, 4, 3)), 0.1, BODY, configurations=np.tile([0, 0, 0, 1.0], (1, 3, 1)))


def test_a_matrix_basis_that_does_not_represent_the_algebra_is_refused():
    basis = lp.Rotations().matrix_basis()
    with pytest.raises(ValueError, match=r"does not represent the algebra.*\[E_0, E_1\]"):
        lp.systems.LiePoissonSystem(lp.so3(), lambda m, xp: m[0] ** 2, group=lp.MatrixGroup(basis[[1, 0, 2]]))
    with pytest.raises(ValueError, match="linearly dependent"):
        lp.systems.LiePoissonSystem(lp.so3(), lambda m, xp: m[0] ** 2, group=lp.MatrixGroup(basis[[0, 0, 2]]))
    with pytest.raises(TypeError, match="group must be a liepoisson.AbstractLieGroup"):
        lp.systems.LiePoissonSystem(lp.so3(), lambda m, xp: m[0] ** 2, group="SO(3)")


def test_a_user_system_with_a_matrix_group_reconstructs_like_the_quaternions(tmp_path):
    inertia = np.array([2.0, 1.0, 2.0 / 3.0])
    user = lp.systems.LiePoissonSystem(
        lp.so3(), lambda m, xp: 0.5 * (m[0] ** 2 / 2.0 + m[1] ** 2 / 1.0 + m[2] ** 2 / (2.0 / 3.0)),
        group=lp.MatrixGroup(lp.Rotations().matrix_basis(), name="SO(3) as matrices"))
    y0 = np.array([0.3, -0.8, 0.5])
    q0 = Rotation.from_rotvec([0.2, 0.1, -0.3])
    mats = it.ground_truth(user, y0, 0.5, 20, g0=q0.as_matrix().reshape(-1))
    quats = it.ground_truth(BODY, y0, 0.5, 20, g0=q0.as_quat())
    assert np.allclose(BODY.inertia, inertia)
    np.testing.assert_allclose(mats.configurations[0].reshape(-1, 3, 3),
                               Rotation.from_quat(quats.configurations[0]).as_matrix(), atol=1e3 * EPS)
    # saved and read back with the configurations
    quats.save(tmp_path / "truth.h5")
    back = it.Trajectories.load(tmp_path / "truth.h5")
    np.testing.assert_array_equal(back.configurations, quats.configurations)
    assert back.select([0]).configurations.shape == (1, 21, 4)


def test_rotation_angle_has_a_finite_gradient_at_equal_attitudes():
    import jax

    q = np.asarray(Rotation.from_rotvec([0.3, 0.1, -0.2]).as_quat())
    grad = np.asarray(jax.grad(lambda p: lp.rotation_angle(p, q))(q))
    assert np.all(np.isfinite(grad))


def test_a_half_turn_between_matrix_configurations_is_refused():
    M = lp.MatrixGroup(lp.Rotations().matrix_basis())
    half = Rotation.from_rotvec([np.pi, 0.0, 0.0]).as_matrix().reshape(-1)
    with pytest.raises(ValueError, match="no real logarithm"):
        M.log_between(np.eye(3).reshape(-1), half)
    with pytest.raises(ValueError, match="g1 and g2 must have shapes that broadcast"):
        lp.Rotations().log_between(np.tile([0, 0, 0, 1.0], (2, 1)), np.tile([0, 0, 0, 1.0], (3, 1)))
