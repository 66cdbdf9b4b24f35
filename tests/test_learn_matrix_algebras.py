"""LPNets and G-LPNets on matrix algebras (the coadjoint flow a conjugation by exp(h alpha)):
the generalized rigid body on so(4) and Zeitlin's model on u(4). The geometry must hold by
construction whatever the weights: Casimirs (so(4)'s Pfaffian, the traces tr (iW)^k) to
round-off over long rollouts, a G-LPNet step exactly Poisson; and training must lower the loss."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps


def _states(system, n, seed=0):
    if isinstance(system, lp.systems.Zeitlin):
        return np.stack([system.random_state(seed + i) for i in range(n)])
    return np.random.default_rng(seed).normal(size=(n, system.dim))


def _pairs(system, h, n):
    """Pairs an LPNet can represent exactly: the test flow of grad H(y0) (Lie-Euler)."""
    y0 = _states(system, n)
    return y0, np.asarray(system.test_flow(system.hamiltonian_gradient(y0), h, y0))


def _casimir_drift(system, ys):
    """Largest change of the spectrum of the state's matrix (every Casimir is a function of it)
    over rollouts `(n, steps + 1, dim)`, relative to the spectral radius."""
    spectra = np.asarray(system.algebra.spectrum(ys))
    return np.max(np.abs(spectra - spectra[:, :1])) / np.max(np.abs(spectra[:, 0]))


SYSTEMS = [
    pytest.param(lambda: lp.systems.GeneralizedRigidBody(), id="so4-manakov", marks=pytest.mark.slow),
    pytest.param(lambda: lp.systems.Zeitlin(4), id="u4-zeitlin"),
]


@pytest.mark.slow  # the default run's time (7 s); the LPNet's training step on u(4) by default below
@pytest.mark.parametrize("make", SYSTEMS)
def test_lpnet_keeps_every_casimir_and_training_lowers_the_loss(make):
    system = make()
    h = 0.1
    y0, y1 = _pairs(system, h, 24)
    net = learn.LPNet(system, hidden=(8,), h=h, key=1)
    fitted, record = learn.fit(net, (y0, y1), h=h, epochs=150, normalise=True, progress=False)
    before = float(np.mean((np.asarray(net.normalised(y0, y1, h).rollout(y0, 1))[:, -1] - y1) ** 2))
    assert record.train_loss < 0.7 * before  # a gradient that did not reach the weights would leave it
    ys = np.asarray(fitted.rollout(y0[:4], 1000))
    # one conjugation a step, its Casimirs changed by round-off of the size of the state: a
    # random walk of 1000 steps (~32 eps), with margin
    assert _casimir_drift(system, ys) < 512 * EPS


@pytest.mark.parametrize("make", SYSTEMS)
def test_glpnet_is_a_poisson_map_and_keeps_every_casimir(make):
    system = make()
    gnet = learn.GLPNet(system, n_modules=4, h=0.1, key=2)
    y = _states(system, 3)
    # J B J^T - B(Phi(y)) for a composition of exact flows: round-off of entries of size |y|
    scale = float(np.abs(y).max())
    assert float(np.max(np.asarray(gnet.poisson_defect(y)))) < 256 * EPS * scale
    ys = np.asarray(gnet.rollout(y, 1000))
    assert _casimir_drift(system, ys) < 512 * EPS


def test_lpnet_step_in_training_is_the_eager_step():
    # Under vmap_samples (the loss) the matrix flows take exp(A) by a Taylor polynomial; the
    # step must be the eager one (jax.scipy's expm) to round-off.
    from liepoisson import vmap_samples

    system = lp.systems.Zeitlin(5)
    net = learn.LPNet(system, hidden=(8,), h=0.1, key=3)
    y = jnp.asarray(_states(system, 6))
    eager = np.stack([np.asarray(net.step(v)) for v in y])
    traced = np.asarray(jax.jit(vmap_samples(net.step))(y))
    np.testing.assert_allclose(traced, eager, rtol=0, atol=64 * EPS * np.abs(eager).max())
