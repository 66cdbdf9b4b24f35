"""G-LPNet warm start: the identity-activation network mapped onto sigma's linear regime."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import learn
import liepoisson as lp
from learn._models._glpnet import linear_to_activation


# the default network (sigmoid, axis vectors) by default; tanh and full vectors with -m slow
@pytest.mark.parametrize("activation", ["sigmoid", pytest.param("tanh", marks=pytest.mark.slow)])
@pytest.mark.parametrize("full_vectors", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_linear_to_activation_reproduces_linear_net(activation, full_vectors):
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    X = jnp.asarray(np.random.default_rng(0).uniform(-2, 2, size=(64, 3)))
    lin = learn.GLPNet(system, 6, key=3, activation="identity", full_vectors=full_vectors, h=0.1)
    net = learn.GLPNet(system, 6, key=0, activation=activation, full_vectors=full_vectors, h=0.1)
    ref = jax.vmap(lin.step)(X)
    errors = []
    for width in (0.04, 0.02, 0.01):
        mapped = linear_to_activation(net, lin, X, width=width)
        errors.append(float(jnp.max(jnp.abs(jax.vmap(mapped.step)(X) - ref))))
    # The neglected curvature of sigma is O(width^2) relative (sigmoid: sigma''(0) = 0, so
    # O(width^2) from the cubic term; tanh likewise): halving the width quarters the error.
    assert errors[-1] < 1e-4
    assert errors[0] / errors[1] > 3.0 and errors[1] / errors[2] > 3.0


@pytest.mark.slow  # 10 s; every default G-LPNet fit in the suite runs the warm start
def test_warm_start_beats_cold_start_on_rigid_body():
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    rng = np.random.default_rng(6)
    y0 = rng.uniform(-2, 2, size=(40, 3))
    # Exact pairs from the classical flow would share code; use the G-LPNet-independent
    # heyoka ground truth instead.
    import integrators as it

    data = it.ground_truth(system, y0, h=0.1, n_steps=5)
    net = learn.GLPNet(system, 6, key=0)
    # as the paper: BFGS on all pairs (no validation set)
    settings = {"validation_fraction": 0.0, "progress": False}
    _, warm = learn.fit(net, data, optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(400))), **settings)
    _, cold = learn.fit(net, data, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(400)), **settings)
    assert warm.train_loss < 1e-8
    assert warm.train_loss < 0.1 * cold.train_loss


def test_warm_start_rejects_flat_activation():
    system = lp.systems.RigidBody()
    X = jnp.ones((4, 3))
    lin = learn.GLPNet(system, 3, activation="identity", h=0.1)
    net = learn.GLPNet(system, 3, activation="relu", h=0.1)
    with pytest.raises(ValueError, match="sigma'\\(0\\)"):
        linear_to_activation(net, lin, X)
