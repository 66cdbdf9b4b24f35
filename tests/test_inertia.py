"""`learn.inertia`: principal moments at the identifiable scale and principal axes of a learned
body map, against the inertia it was built from; the bootstrap spread; bad input."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import EPS
from scipy.spatial.transform import Rotation

import integrators as it
import learn
from integrators.splitting import Strang
from liepoisson.systems import RigidBody

INERTIA = np.array([1.0, 1.9, 2.1])


def _net(rotation: np.ndarray | None = None, scale: float = 1.0) -> learn.GLPNet:
    """H~ = 1/2 mu^T (R diag(1/I) R^T) mu / scale: the body of INERTIA (times `scale`, which the
    gyroscope cannot see) with its principal axes turned by R."""
    R = np.eye(3) if rotation is None else rotation
    terms = learn.RidgeTerms(3, 3, activation="identity", full_vectors=True, linear_term=False, bias=False)
    terms = eqx.tree_at(lambda t: (t.a, t.c), terms, (jnp.asarray(1.0 / (scale * INERTIA)), jnp.asarray(R.T)))
    return learn.GLPNet(RigidBody(INERTIA), terms=terms, method=Strang, h=0.01)


def test_moments_and_axes_of_a_known_body():
    R = Rotation.from_rotvec([0.4, -0.7, 0.5]).as_matrix()
    found = learn.inertia(_net(R, scale=3.7))
    # the moments over their sum, whatever the scale: a 3x3 inverse and eigh, a few roundings
    np.testing.assert_allclose(found.moments, INERTIA / INERTIA.sum(), rtol=64 * EPS)
    np.testing.assert_allclose(found.ratios(), INERTIA / INERTIA[1], rtol=64 * EPS)
    axes = learn.PrincipalAxes(found.moments, found.axes)
    # ascending moments: the columns of R in order; as lines, angles at round-off (sqrt(eps))
    assert np.all(axes.angles_to(R) < 1e-7)
    assert found.moments_spread is None and found.n_bootstrap == 0


def test_a_non_quadratic_hamiltonian_needs_the_data():
    net = learn.GLPNet(RigidBody(INERTIA), 3, activation="sigmoid", h=0.01, key=1)
    with pytest.raises(ValueError, match="not quadratic.*give data="):
        learn.inertia(net)
    with pytest.raises(TypeError, match="learned map of a body"):
        learn.inertia(learn.MLPBaseline(RigidBody(INERTIA)))


@pytest.mark.slow  # three refits
def test_bootstrap_spread():
    body = RigidBody(INERTIA)
    omega = np.array([[0.1, 8.0, 0.2], [0.3, -9.0, 0.1], [-0.2, 10.0, 0.3], [0.2, 7.0, -0.3]])
    data = it.observe_body(body, omega * INERTIA, np.tile([0, 0, 0, 1.0], (4, 1)), np.arange(41) * 0.01,
                           measure="velocities", noise=1e-2, seed=3)
    found = learn.inertia(_net(), data, n_bootstrap=3, loss=learn.BodyLoss(max_step=0.005), progress=False)
    assert found.n_bootstrap == 3
    assert np.all(np.isfinite(found.moments_spread)) and np.all(found.moments_spread > 0)
    # four 0.4-s flights about the middle axis, resampled: the outer moments are poorly fixed
    # (measured 0.04, 0.03, 0.01 against 0.2, 0.38, 0.42); still a spread, not a failed fit
    assert np.all(found.moments_spread < 0.5 * found.moments)
    assert np.all(np.isfinite(found.axes_spread)) and found.axes_spread[1] < 0.1  # the spin axis is well fixed
    with pytest.raises(ValueError, match="give data="):
        learn.inertia(_net(), n_bootstrap=2)
