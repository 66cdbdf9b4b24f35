"""learn maps: LPNet, GLPNet and MLPBaseline as maps (no training): conservation, Poisson
defect, rollout shapes, input errors."""

import jax
import numpy as np
import pytest

import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
H = 0.1


@pytest.fixture(scope="module")
def rb():
    return lp.systems.RigidBody()


@pytest.fixture(scope="module")
def lpnet(rb):
    return learn.LPNet(rb, hidden=(8, 8), key=1, h=H)


@pytest.fixture(scope="module")
def glpnet(rb):
    return learn.GLPNet(rb, n_modules=6, key=1, h=H)


def test_parameter_counts(rb):
    net = learn.LPNet(rb, hidden=(16, 16, 16))
    # the paper's count for the rigid body: (3 + 1) 16 + 2 (16 + 1) 16 + (16 + 1) 3
    assert net.n_parameters == 659
    g = learn.GLPNet(rb, n_modules=6)
    assert g.terms.a.size + g.terms.c.size + g.terms.b.size == g.n_parameters == 18
    assert learn.GLPNet(rb, n_modules=6, full_vectors=True).terms.c.shape == (6, 3)


def test_lpnet_conserves_casimir_over_long_rollout(rb, lpnet):
    y = np.asarray(lpnet.rollout(np.array([0.7, -0.7, 1.0]), 10_000))
    C = np.sum(y**2, axis=-1)
    # each step is an exact rotation: round-off random walk, sqrt(1e4) * few eps
    assert np.max(np.abs(C - C[0])) / C[0] < 1e4 * EPS


def test_lpnet_conserves_casimirs_kirchhoff():
    k = lp.systems.Kirchhoff()
    net = learn.LPNet(k, hidden=(8,), key=0, h=H)
    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    y = np.asarray(net.rollout(y0, 1000))
    C = np.asarray(k.casimirs(y))
    assert np.max(np.abs(C - C[0])) < 1e4 * EPS * np.max(np.abs(C[0]))


@pytest.mark.slow
def test_glpnet_is_poisson_and_lpnet_is_not(rb, lpnet, glpnet):
    y = np.random.default_rng(0).uniform(-2, 2, size=(20, 3))
    d_glp = np.asarray(glpnet.poisson_defect(y))
    d_lp = np.asarray(lpnet.poisson_defect(y))
    assert d_glp.shape == d_lp.shape == (20,)
    assert np.max(d_glp) < 1e-12
    assert np.min(d_lp) > 1e-8  # alpha depends on the point: not a Poisson map


@pytest.mark.slow
def test_glpnet_full_vectors_is_poisson(rb):
    g = learn.GLPNet(rb, n_modules=4, full_vectors=True, key=3, h=H)
    y = np.random.default_rng(1).uniform(-2, 2, size=(10, 3))
    assert np.max(np.asarray(g.poisson_defect(y))) < 1e-12
    Y = np.asarray(g.rollout(y, 1000))
    C = np.sum(Y**2, axis=-1)
    assert np.max(np.abs(C - C[:, :1]) / C[:, :1]) < 1e4 * EPS


def test_glpnet_default_order_cycles(rb):
    g = learn.GLPNet(rb, n_modules=6)
    assert g.terms.order == (0, 1, 2, 0, 1, 2)
    V = np.asarray(g.module_vectors())
    assert np.all(V[np.arange(6), [0, 1, 2, 0, 1, 2]] == np.asarray(g.terms.c))


@pytest.mark.slow
def test_rollout_shapes(lpnet, glpnet, rb):
    base = learn.MLPBaseline(rb, hidden=(4,), h=H)
    for net in (lpnet, glpnet, base):
        assert net.rollout(np.ones(3), 5).shape == (6, 3)
        assert net.rollout(np.ones((4, 3)), 5).shape == (4, 6, 3)
        assert net.rollout(np.ones(3), 0).shape == (1, 3)
        # `step` takes one state; batches go through jax.vmap
        assert jax.vmap(jax.vmap(net.step))(np.ones((2, 4, 3))).shape == (2, 4, 3)
        with pytest.raises(ValueError, match="one state"):
            net.step(np.ones((2, 4, 3)))
        one = np.asarray(net.rollout(np.array([0.3, 0.2, 0.1]), 5))  # the program of the first rollout
        np.testing.assert_allclose(one[1], np.asarray(net.step(one[0])), rtol=4 * EPS, atol=0)


def test_baseline_does_not_conserve_casimir(rb):
    base = learn.MLPBaseline(rb, hidden=(8,), key=0, h=H)
    y = np.asarray(base.rollout(np.array([0.7, -0.7, 1.0]), 100))
    C = np.sum(y**2, axis=-1)
    assert np.max(np.abs(C - C[0])) > 1e-6


def test_bad_inputs_name_the_argument(rb, lpnet):
    with pytest.raises(ValueError, match="h"):
        learn.LPNet(rb, h=-1.0)
    with pytest.raises(ValueError, match="hidden"):
        learn.LPNet(rb, hidden=(16, 0))
    with pytest.raises(ValueError, match="activation"):
        learn.LPNet(rb, activation="cosine")
    with pytest.raises(TypeError, match="system"):
        learn.LPNet("rigid body")
    with pytest.raises(ValueError, match="y0"):
        lpnet.rollout(np.ones(4), 3)
    with pytest.raises(ValueError, match="n_steps"):
        lpnet.rollout(np.ones(3), -1)
    with pytest.raises(ValueError, match="y"):
        lpnet.step(np.array([np.nan, 0.0, 1.0]))
    with pytest.raises(ValueError, match="no step size h"):
        learn.LPNet(rb).rollout(np.ones(3), 2)
    with pytest.raises(ValueError, match="n_modules"):
        learn.GLPNet(rb, n_modules=0)
    with pytest.raises(ValueError, match="order"):
        learn.GLPNet(rb, n_modules=2, order=(0, 3))
    with pytest.raises(TypeError, match="parametrisation"):
        learn.LPNet(rb, parametrisation=3)
    with pytest.raises(ValueError, match="parametrisation 'so3'"):
        learn.LPNet(rb, parametrisation="so3")
