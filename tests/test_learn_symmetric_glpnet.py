"""The G-LPNet as a data-driven splitting method: the symmetric network is the Strang splitting
of its learned Hamiltonian, runs at other step sizes and inside higher-order compositions."""

import equinox as eqx
import jax
import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
Y = np.random.default_rng(0).normal(size=(6, 3))


def net(symmetric=True, activation="sigmoid", **kw):
    return learn.GLPNet(lp.systems.RigidBody(), 6, key=3, h=0.1, symmetric=symmetric, activation=activation, **kw)


@pytest.mark.parametrize("activation", ["sigmoid", "tanh", "identity"])
def test_symmetric_network_is_strang_of_its_learned_hamiltonian(activation):
    g = net(activation=activation)
    ours = np.asarray(jax.vmap(g.step)(Y))
    strang = np.asarray(it.splitting.Strang(g.learned_system(), 0.1).rollout(Y, 1))[:, -1]
    # The same 11 flows in the same order: equal up to a few roundings.
    assert np.allclose(ours, strang, rtol=0, atol=16 * EPS * np.abs(Y).max())
    assert g.exact_flows_per_step == 11
    # And the paper's network is Lie-Trotter of H/M.
    p = net(symmetric=False, activation=activation)
    lt = np.asarray(it.splitting.LieTrotter(p.learned_system(), 0.1).rollout(Y, 1))[:, -1]
    assert np.allclose(np.asarray(jax.vmap(p.step)(Y)), lt, rtol=0, atol=16 * EPS * np.abs(Y).max())


def test_learned_hamiltonian_is_the_sum_of_the_module_potentials():
    g = net(full_vectors=True)
    # Independent: finite differences of H~ along the flow's generator. Each module flow is
    # the test flow with rate a_s sigma(<alpha_s, y>) + b_s = d/dx of its potential.
    H = lambda y: np.asarray(g.hamiltonian(y))
    y = Y[0]
    grad_fd = np.array([(H(y + 1e-6 * e) - H(y - 1e-6 * e)) / 2e-6 for e in np.eye(3)])
    vectors = np.asarray(g.module_vectors())
    rates = np.asarray(g.a) * jax.nn.sigmoid(vectors @ y) + np.asarray(g.b)
    # Central differences: error O(1e-12 * H''') + round-off eps|H|/1e-6 ~ 1e-9.
    assert np.allclose(grad_fd, vectors.T @ rates, rtol=0, atol=1e-8)
    assert np.allclose(np.asarray(g.learned_system().hamiltonian(Y)), H(Y), rtol=0, atol=8 * EPS * np.abs(H(Y)).max())


def test_symmetric_network_is_time_symmetric_and_poisson():
    g = net()
    back = eqx.tree_at(lambda m: m.h, g, -0.1)  # with_h refuses h < 0 on purpose
    y1 = jax.vmap(g.step)(Y)
    # Phi_{-h} o Phi_h = id: the palindrome of exact flows.
    assert np.allclose(np.asarray(jax.vmap(back.step)(y1)), Y, rtol=0, atol=64 * EPS * np.abs(Y).max())
    assert float(np.max(np.asarray(g.poisson_defect(Y)))) < 1e-13


@pytest.mark.parametrize("symmetric, order", [(True, 2), (False, 1)])
def test_order_against_heyoka_on_the_learned_hamiltonian(symmetric, order):
    # The step map is a splitting of H~, so against H~'s exact flow (heyoka on the learned
    # system) it converges with the splitting's order as h -> 0.
    g = net(symmetric=symmetric)
    system = g.learned_system()
    y0, T = Y[0], 2.0
    ref = np.asarray(it.ground_truth(system, y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([20, 40, 80, 160])
    errors = [np.linalg.norm(np.asarray(g.with_h(T / n).rollout(y0, int(n)))[-1] - ref) for n in steps]
    observed = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(observed - order) < 0.1, (errors, observed)


def test_compositions_of_the_learned_splitting_raise_the_order():
    g = net()
    system = g.learned_system()
    y0, T = Y[1], 2.0
    ref = np.asarray(it.ground_truth(system, y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([10, 20, 40])
    errors = [
        np.linalg.norm(np.asarray(it.splitting.TripleJump(system, T / n).rollout(y0, int(n)))[-1] - ref) for n in steps
    ]
    observed = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(observed - 4) < 0.15, (errors, observed)


def test_symmetric_survives_save_and_load(tmp_path):
    g = net()
    g.save(tmp_path / "g.h5")
    back = learn.GLPNet.load(tmp_path / "g.h5", lp.systems.RigidBody())
    assert back.symmetric and np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(g.step)(Y)))


def test_arguments():
    with pytest.raises(TypeError, match="symmetric"):
        net(symmetric="yes")
    with pytest.raises(ValueError, match="antiderivative"):
        net(activation="relu").hamiltonian(Y)
    with pytest.raises(ValueError, match="h"):
        net().with_h(0.0)


@pytest.mark.slow  # 23 s
def test_compiled_losses_are_shared_across_step_sizes_without_mixing_them():
    """Quasi-Newton losses are compiled once per model structure with h as an argument: a fit
    at h = 0.2 after one at h = 0.1 (cache warm) equals a fit at h = 0.2 from a cold cache."""
    import learn._fit as fit_module
    import learn._quasi_newton as qn_module

    body = lp.systems.RigidBody()
    y0 = np.random.default_rng(0).uniform(-1.0, 1.0, size=(6, 3))
    opt = learn.QuasiNewton(15, "bfgs")

    def fitted(h):
        data = it.ground_truth(body, y0, h=h, n_steps=5, seed=0)
        model, _ = learn.fit(learn.GLPNet(body, key=0, symmetric=True), data, optimiser=opt,
                             validation_fraction=0.0, progress=False)
        return model

    fitted(0.1)
    warm = fitted(0.2)
    fit_module._CACHE.clear()
    qn_module._VALUE_AND_GRAD.clear()
    cold = fitted(0.2)
    for name in ("a", "b", "c"):
        np.testing.assert_array_equal(np.asarray(getattr(warm, name)), np.asarray(getattr(cold, name)))
    assert warm.h == cold.h == 0.2
