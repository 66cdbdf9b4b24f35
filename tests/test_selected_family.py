"""The quadratic family whose terms are selected by the criterion (`learn.select_quadratic`) and
the pieces it needs (`RidgeTerms(a_kept=..., b_kept=...)`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps


def _heavy_top_observations(noise, seed=0):
    # a Lagrange top: H = (Pi_1^2 + Pi_2^2)/4 + Pi_3^2/2 + 0.5 Gamma_3, so the diagonal
    # quadratic has a = (1/2, 1/2, 1, 0, 0, 0) and b = (0, 0, 0, 0, 0, 0.5)
    top = lp.systems.HeavyTop(inertia=(2.0, 2.0, 1.0), mgl=0.5, center_of_mass=(0.0, 0.0, 1.0))
    rng = np.random.default_rng(seed)
    pi = rng.normal(size=(30, 3))
    gamma = rng.normal(size=(30, 3))
    gamma /= np.linalg.norm(gamma, axis=1, keepdims=True)
    return top, it.observe(top, np.concatenate([pi, gamma], axis=1), 0.1 * np.arange(21), noise=noise, seed=seed)


def test_the_heavy_top_keeps_the_four_terms_it_has():
    """From noisy observations (noise 1e-3 of the states' size) the backward elimination keeps
    the three inverse moments of inertia and the gravity term, and drops the eight terms the
    top does not have (among them the Gamma_k^2 terms, which the Casimir |Gamma|^2 makes
    redundant)."""
    top, data = _heavy_top_observations(1e-3)
    A, b, a_kept, b_kept = learn.select_quadratic(top, data)
    assert a_kept == (True, True, True, False, False, False)
    assert b_kept == (False, False, False, False, False, True)
    # finite differences at dt = 0.1 and noise 1e-3: the estimate is good to ~1%
    np.testing.assert_allclose(np.diag(A)[:3], [0.5, 0.5, 1.0], rtol=2e-2)
    np.testing.assert_allclose(b[5], 0.5, rtol=2e-2)
    assert np.all(np.diag(A)[3:] == 0.0) and np.all(b[:5] == 0.0)


def test_terms_not_kept_are_zero_are_not_trained_and_are_saved(tmp_path):
    body = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))
    a_kept, b_kept = (True, True, False), (False, False, True)
    terms = learn.RidgeTerms(3, 3, activation="identity", bias=True, a_kept=a_kept, b_kept=b_kept, key=3)
    assert np.asarray(terms.a_values())[2] == 0.0
    assert np.array_equal(np.asarray(terms.bias_values())[:2], np.zeros(2))
    net = learn.GLPNet(body, terms=terms, method=it.splitting.Strang(), h=0.1)
    y = np.random.default_rng(1).normal(size=(3, 3))
    # a step's derivative in the weights not kept is zero: no solver moves them
    grad = eqx.filter_grad(lambda m: jnp.sum(jax.vmap(m.step)(jnp.asarray(y)) ** 2))(net)
    assert np.asarray(grad.terms.a)[2] == 0.0
    assert np.array_equal(np.asarray(grad.terms.b)[:2], np.zeros(2))
    assert np.all(np.asarray(grad.terms.a)[:2] != 0.0) and np.asarray(grad.terms.b)[2] != 0.0  # the kept do move
    # still an exact Poisson map (a piece b_s x alone is a test flow)
    assert float(jnp.max(net.poisson_defect(y))) < 1e3 * EPS
    net.save(tmp_path / "selected.h5")
    back = learn.GLPNet.load(tmp_path / "selected.h5", body)
    assert back.terms.a_kept == a_kept and back.terms.b_kept == b_kept
    np.testing.assert_array_equal(np.asarray(back.rollout(y, 10)), np.asarray(net.rollout(y, 10)))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"a_kept": (True, False)}, "a_kept must be 3 values"),
        ({"b_kept": "yes"}, "b_kept must be 3 values"),
        ({"a_kept": 3}, "a_kept must be a sequence"),
        ({"b_kept": (True, True, False), "bias": False}, "needs bias=True"),
    ],
)
def test_bad_kept_masks_are_refused(kwargs, match):
    with pytest.raises((TypeError, ValueError), match=match):
        learn.RidgeTerms(3, 3, **kwargs)


@pytest.mark.parametrize("any_axes", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_a_general_family_starts_at_the_fit_of_the_quadratic_it_extends(any_axes):
    """`Family.from_nested`: the sigmoid pieces at zero and the fitted quadratic as their linear
    term give the same learned Hamiltonian, so the same steps, bit for bit."""
    body = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))
    general = next(f for f in learn.FAMILIES if f.activation == "sigmoid" and f.any_axes == any_axes)
    nested = next(f for f in learn.FAMILIES if f.name == general.nested)
    quadratic = learn.RidgeTerms(3, 3, activation="identity", bias=nested.bias, full_vectors=any_axes, key=1)
    terms = general.from_nested(learn.RidgeTerms(3, 3, activation="sigmoid", linear_term=True, bias=True,
                                                 full_vectors=any_axes, key=2), quadratic)
    y0 = np.random.default_rng(0).normal(size=(4, 3))
    one = learn.GLPNet(body, terms=quadratic, method=it.splitting.TripleJump(), h=0.1).rollout(y0, 20)
    two = learn.GLPNet(body, terms=terms, method=it.splitting.TripleJump(), h=0.1).rollout(y0, 20)
    np.testing.assert_array_equal(np.asarray(one), np.asarray(two))


def test_observations_at_rest_keep_no_term_and_give_no_nan():
    """A body spinning about a principal axis does not move in the body frame: no term is needed
    (every velocity is zero), none is kept, and nothing is NaN."""
    body = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))
    y0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -2.0]])
    data = it.observe(body, y0, 0.1 * np.arange(6), noise=0.0)
    A, b, a_kept, b_kept = learn.select_quadratic(body, data)
    assert not any(a_kept) and not any(b_kept)
    assert np.array_equal(A, np.zeros((3, 3))) and np.array_equal(b, np.zeros(3))
