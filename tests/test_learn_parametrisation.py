"""learn parametrisations: closed-form and Gauss-Newton inverse of one exact step."""

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


def test_so3_rotation_round_trip():
    rb = lp.systems.RigidBody()
    alpha, found = _round_trip(rb, learn.SO3Rotation(rb), np.random.default_rng(0), scale=3.0)
    # the closed form: a few ulps of |alpha| (atan2, cross products)
    np.testing.assert_allclose(found, alpha, rtol=0, atol=100 * EPS * np.max(np.abs(alpha)))


def test_so3_rotation_spatial_sign():
    sys_ = lp.systems.LiePoissonSystem(lp.so3(sign=+1), lambda m, xp: m[0] ** 2)
    alpha, found = _round_trip(sys_, learn.SO3Rotation(sys_), np.random.default_rng(1))
    np.testing.assert_allclose(found, alpha, rtol=0, atol=1e-13)


def test_so3_rotation_zero_rotation_is_zero_without_nan():
    rb = lp.systems.RigidBody()
    p = learn.SO3Rotation(rb)
    y = np.array([[1.0, -2.0, 0.5], [0.0, 0.0, 0.0]])
    A = p.params_from_pair(y, y, H)
    assert np.all(np.isfinite(A)) and np.all(A == 0.0)
    # a tiny rotation: series branch, still exact to round-off
    A0 = np.array([1e-9, -2e-9, 0.0])
    A0 = _project(A0, y[:1])
    y1 = np.asarray(rb.test_flow(A0, H, y[0]))
    np.testing.assert_allclose(p.params_from_pair(y[0], y1, H), A0, atol=1e-15)


def test_so3_rotation_rejects_mismatched_casimirs_and_antiparallel():
    p = learn.SO3Rotation(lp.systems.RigidBody())
    y0 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    y1 = np.array([[0.0, 1.0, 0.0], [0.0, 1.0 + 1e-6, 0.0]])
    with pytest.raises(ValueError, match="pair 1"):
        p.params_from_pair(y0, y1, H)
    with pytest.raises(ValueError, match="antiparallel"):
        p.params_from_pair(y0[0], -y0[0], H)
    with pytest.raises(ValueError, match="h"):
        p.params_from_pair(y0, y0, -0.1)
    with pytest.raises(ValueError, match="y1"):
        p.params_from_pair(y0, y0[:, :2], H)


def test_so3_rotation_needs_so3():
    with pytest.raises(ValueError, match="so\\(3\\)"):
        learn.SO3Rotation(lp.systems.Kirchhoff())


@pytest.mark.parametrize(
    "system",
    [lp.systems.RigidBody(), lp.systems.Kirchhoff(), lp.systems.HeavyTop(), lp.systems.ExtendedPendulum()],
    ids=lambda s: s.name,
)
def test_lie_algebra_parametrisation_round_trip(system):
    p = learn.LieAlgebraParametrisation(system)
    alpha, found = _round_trip(system, p, np.random.default_rng(2))
    # Gauss-Newton converges quadratically: round-off of the flow, amplified by the conditioning
    np.testing.assert_allclose(found, alpha, rtol=0, atol=1e-9)
    assert found.shape == alpha.shape


def test_lie_algebra_parametrisation_agrees_with_closed_form():
    rb = lp.systems.RigidBody()
    rng = np.random.default_rng(3)
    y0 = rng.normal(size=(5, 3))
    y1 = np.asarray(rb.test_flow(rng.normal(size=(5, 3)), H, y0))
    np.testing.assert_allclose(
        learn.LieAlgebraParametrisation(rb).params_from_pair(y0, y1, H),
        learn.SO3Rotation(rb).params_from_pair(y0, y1, H),
        atol=1e-10,
    )


def test_lie_algebra_parametrisation_rejects_mismatched_casimirs():
    k = lp.systems.Kirchhoff()
    y0 = np.array([[1.0, 0.5, -0.2, 0.3, 0.1, 0.9]] * 2)
    y1 = y0.copy()
    y1[1, 3] += 1e-5
    with pytest.raises(ValueError, match="pair 1: Casimir"):
        learn.LieAlgebraParametrisation(k).params_from_pair(y0, y1, H)


def test_default_parametrisation():
    assert isinstance(learn.default_parametrisation(lp.systems.RigidBody()), learn.SO3Rotation)
    assert isinstance(
        learn.default_parametrisation(lp.systems.Kirchhoff()), learn.LieAlgebraParametrisation
    )
    with pytest.raises(TypeError, match="LieAlgebraParametrisation"):
        learn.default_parametrisation(lp.systems.ExtendedPendulum())
    with pytest.raises(TypeError, match="system"):
        learn.default_parametrisation("rigid body")
