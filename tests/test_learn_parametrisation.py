"""learn parametrisations: closed-form and Gauss-Newton inverse of one exact step.

`TestFlowParametrisation` (the default for every system) inverts the test flow in closed form
on so(3)* (the shortest rotation) and by Gauss-Newton otherwise."""

import numpy as np
import pytest

import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
H = 0.1


def _project(alpha, grads):
    """Remove the span of the Casimir gradients (rows of `grads`) from `alpha`."""
    if grads.shape[0] == 0:
        return alpha
    q, _ = np.linalg.qr(grads.T)
    return alpha - q @ (q.T @ alpha)


def _round_trip(system, param, rng, n=8, scale=1.0):
    y0 = rng.normal(size=(n, system.dim))
    G = np.asarray(system.casimir_gradients(y0))
    alpha = np.stack([_project(a, g) for a, g in zip(scale * rng.normal(size=(n, system.dim)), G)])
    y1 = np.asarray(system.test_flow(alpha, H, y0))
    return alpha, param.params_from_pair(y0, y1, H)


def _generic_so3_body():
    """The rigid body on so(3) built from its structure constants only: matrix-exponential
    flow, so the inverse is Gauss-Newton (no closed form)."""
    C = np.zeros((3, 3, 3))
    for a, b, c in [(0, 1, 2), (1, 2, 0), (2, 0, 1)]:
        C[a, b, c], C[b, a, c] = 1.0, -1.0
    inertia = np.array([1.0, 2.0, 3.0])
    return lp.systems.LiePoissonSystem(
        lp.LieAlgebra(C, name="generic_so3"), lambda m, xp: 0.5 * sum(m[i] ** 2 / inertia[i] for i in range(3))
    )


def test_so3_rotation_round_trip():
    rb = lp.systems.RigidBody()
    alpha, found = _round_trip(rb, learn.TestFlowParametrisation(rb), np.random.default_rng(0), scale=3.0)
    # the closed form: a few ulps of |alpha| (atan2, cross products)
    np.testing.assert_allclose(found, alpha, rtol=0, atol=100 * EPS * np.max(np.abs(alpha)))


def test_so3_rotation_spatial_sign():
    sys_ = lp.systems.LiePoissonSystem(lp.so3(sign=+1), lambda m, xp: m[0] ** 2)
    alpha, found = _round_trip(sys_, learn.TestFlowParametrisation(sys_), np.random.default_rng(1))
    np.testing.assert_allclose(found, alpha, rtol=0, atol=1e-13)


@pytest.mark.slow  # the same inverse (so(3)'s closed form) by default in test_inverse_flows.py (zero and tiny rotations)
def test_so3_rotation_zero_rotation_is_zero_without_nan():
    rb = lp.systems.RigidBody()
    p = learn.TestFlowParametrisation(rb)
    y = np.array([[1.0, -2.0, 0.5], [0.0, 0.0, 0.0]])
    A = p.params_from_pair(y, y, H)
    assert np.all(np.isfinite(A)) and np.all(A == 0.0)
    # a tiny rotation: series branch, still exact to round-off
    A0 = np.array([1e-9, -2e-9, 0.0])
    A0 = _project(A0, y[:1])
    y1 = np.asarray(rb.test_flow(A0, H, y[0]))
    np.testing.assert_allclose(p.params_from_pair(y[0], y1, H), A0, atol=1e-15)


def test_so3_rotation_rejects_mismatched_casimirs_and_antiparallel():
    p = learn.TestFlowParametrisation(lp.systems.RigidBody())
    y0 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    y1 = np.array([[0.0, 1.0, 0.0], [0.0, 1.0 + 1e-6, 0.0]])
    with pytest.raises(ValueError, match="pair 1"):
        p.params_from_pair(y0, y1, H)
    with pytest.raises(ValueError, match="antiparallel"):
        p.params_from_pair(y0[0], -y0[0], H)
    with pytest.raises(ValueError, match="h"):
        p.params_from_pair(y0, y0, -0.1)
    with pytest.raises(ValueError, match="shape"):
        p.params_from_pair(y0, y0[:, :2], H)


def test_errors_name_the_arguments_y0_y1():
    p = learn.TestFlowParametrisation(lp.systems.RigidBody())
    y0 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    with pytest.raises(ValueError, match="y1"):
        p.params_from_pair(y0, y0[:, :2], H)


def test_parametrisations_check_their_system():
    # SO3Rotation (which rejected other algebras) is gone: the test-flow parametrisation serves
    # every system; it still needs one, and SE3RotationShear needs se(3)
    with pytest.raises(TypeError, match="system"):
        learn.TestFlowParametrisation("rigid body")
    with pytest.raises(ValueError, match="rtol"):
        learn.TestFlowParametrisation(lp.systems.RigidBody(), rtol=0.0)
    with pytest.raises(ValueError, match="se\\(3\\)"):
        learn.SE3RotationShear(lp.systems.RigidBody())


# se(3)'s (Kirchhoff, the heavy top) with -m slow: the parametrisation is the system's
# test_flow_parameters, round-tripped on se(3) and Kirchhoff by default in test_inverse_flows.py
@pytest.mark.parametrize(
    "system",
    [lp.systems.RigidBody(), pytest.param(lp.systems.Kirchhoff(), marks=pytest.mark.slow),
     pytest.param(lp.systems.HeavyTop(), marks=pytest.mark.slow), lp.systems.ExtendedPendulum()],
    ids=lambda s: s.name,
)
def test_lie_algebra_parametrisation_round_trip(system):
    p = learn.TestFlowParametrisation(system)
    alpha, found = _round_trip(system, p, np.random.default_rng(2))
    # Gauss-Newton converges quadratically: round-off of the flow, amplified by the conditioning
    np.testing.assert_allclose(found, alpha, rtol=0, atol=1e-9)
    assert found.shape == alpha.shape


@pytest.mark.slow
def test_lie_algebra_parametrisation_agrees_with_closed_form():
    rb, generic = lp.systems.RigidBody(), _generic_so3_body()
    rng = np.random.default_rng(3)
    y0 = rng.normal(size=(5, 3))
    y1 = np.asarray(rb.test_flow(rng.normal(size=(5, 3)), H, y0))
    np.testing.assert_allclose(
        learn.TestFlowParametrisation(generic).params_from_pair(y0, y1, H),  # Gauss-Newton
        learn.TestFlowParametrisation(rb).params_from_pair(y0, y1, H),  # closed form
        atol=1e-10,
    )


def test_lie_algebra_parametrisation_rejects_mismatched_casimirs():
    k = lp.systems.Kirchhoff()
    y0 = np.array([[1.0, 0.5, -0.2, 0.3, 0.1, 0.9]] * 2)
    y1 = y0.copy()
    y1[1, 3] += 1e-5
    with pytest.raises(ValueError, match="pair 1: Casimir"):
        learn.TestFlowParametrisation(k).params_from_pair(y0, y1, H)


def test_default_parametrisation():
    # every system of the library has exact test flows, so one default serves them all
    for system in (lp.systems.RigidBody(), lp.systems.Kirchhoff(), lp.systems.ExtendedPendulum()):
        p = learn.default_parametrisation(system)
        assert isinstance(p, learn.TestFlowParametrisation) and p.system is system
    with pytest.raises(TypeError, match="system"):
        learn.default_parametrisation("rigid body")
