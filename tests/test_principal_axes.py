"""learn.QuadraticPart.principal_axes: a body's principal axes read off its Hamiltonian in the
axes of the data, whatever the Casimir part."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import learn
from liepoisson.systems import RigidBody

EPS = np.finfo(float).eps
BODY = RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0))  # only its bracket and Casimir |Pi|^2 are used


def rotated(rotvec, inverse_inertia=(0.5, 1.0, 1.5), casimir=0.0):
    R = Rotation.from_rotvec(rotvec).as_matrix()
    A = R @ np.diag(inverse_inertia) @ R.T + casimir * np.eye(3)
    return R, lambda y: 0.5 * np.einsum("ni,ij,nj->n", y, A, y)


SAMPLES = np.random.default_rng(0).normal(size=(40, 3))


@pytest.mark.parametrize("casimir", [0.0, 3.0])
def test_principal_axes_of_a_rotated_body_are_its_axes_and_its_inverse_inertias(casimir):
    R, H = rotated((0.4, -0.7, 0.5), casimir=casimir)
    axes = learn.quadratic_part(H, BODY, SAMPLES).principal_axes()
    # an exact quadratic fitted by least squares in 10 features of O(1): a few hundred ulps
    np.testing.assert_allclose(axes.angles_to(R), 0.0, atol=1e-6)  # arccos near 1: sqrt of ~1e-13
    np.testing.assert_allclose(axes.values, np.array([0.5, 1.0, 1.5]) - 1.0, atol=300 * EPS)
    # the least rotation onto the axes as lines is the body's own (0.95 rad): its columns are the
    # axes up to sign
    np.testing.assert_allclose(axes.rotation_vector(), [0.4, -0.7, 0.5], atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(Rotation.from_rotvec(axes.rotation_vector()).as_matrix() * axes.axes, axis=0)),
                               1.0, atol=100 * EPS)
    assert np.linalg.det(axes.axes) == pytest.approx(1.0, abs=100 * EPS)


def test_the_rotation_vector_does_not_depend_on_the_signs_of_the_axes():
    R, _ = rotated((0.4, -0.7, 0.5))
    for signs in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1), (-1, -1, -1)):
        axes = learn.PrincipalAxes(np.array([0.5, 1.0, 1.5]), R * np.asarray(signs, dtype=float))
        np.testing.assert_allclose(axes.rotation_vector(), [0.4, -0.7, 0.5], atol=100 * EPS)


def test_angles_to_another_frame_are_the_angles_between_its_lines():
    _, H = rotated((0.0, 0.0, 0.0))
    axes = learn.quadratic_part(H, BODY, SAMPLES).principal_axes()
    turned = Rotation.from_rotvec((0.1, 0.0, 0.0)).as_matrix()  # turns e2 and e3 by 0.1 rad, not e1
    np.testing.assert_allclose(axes.angles_to(turned), [0.0, 0.1, 0.1], atol=1e-6)
    np.testing.assert_allclose(axes.angles_to(-np.eye(3)), 0.0, atol=1e-6)  # a line's sign is no error
    with pytest.raises(ValueError, match="axes must have shape"):
        axes.angles_to(np.eye(2))


def test_a_spherical_body_has_no_axes_to_find_and_no_nan():
    _, H = rotated((0.3, 0.2, 0.1), inverse_inertia=(1.0, 1.0, 1.0))
    axes = learn.quadratic_part(H, BODY, SAMPLES).principal_axes()
    np.testing.assert_allclose(axes.values, 0.0, atol=300 * EPS)  # all of it is the Casimir
    assert np.all(np.isfinite(axes.axes)) and np.all(np.isfinite(axes.rotation_vector()))
