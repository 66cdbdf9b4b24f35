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


def with_linear_term(g, key=7):
    """`g` with random linear coefficients e_s (they start at zero)."""
    return eqx.tree_at(lambda m: m.e, g, 0.5 * jax.random.normal(jax.random.PRNGKey(key), (g.n_modules,)))


@pytest.mark.parametrize("linear_term", [False, True])
@pytest.mark.parametrize("activation", ["sigmoid", "tanh", "identity"])
def test_symmetric_network_is_strang_of_its_learned_hamiltonian(activation, linear_term):
    g = net(activation=activation, linear_term=linear_term)
    if linear_term:
        g = with_linear_term(g)
    ours = np.asarray(jax.vmap(g.step)(Y))
    strang = np.asarray(it.splitting.Strang(g.learned_system(), 0.1).rollout(Y, 1))[:, -1]
    # The same 11 flows in the same order: equal up to a few roundings.
    assert np.allclose(ours, strang, rtol=0, atol=16 * EPS * np.abs(Y).max())
    assert g.exact_flows_per_step == 11
    # And the paper's network is Lie-Trotter of H/M.
    p = net(symmetric=False, activation=activation)
    lt = np.asarray(it.splitting.LieTrotter(p.learned_system(), 0.1).rollout(Y, 1))[:, -1]
    assert np.allclose(np.asarray(jax.vmap(p.step)(Y)), lt, rtol=0, atol=16 * EPS * np.abs(Y).max())


@pytest.mark.parametrize("linear_term", [False, True])
def test_learned_hamiltonian_is_the_sum_of_the_module_potentials(linear_term):
    g = net(full_vectors=True, linear_term=linear_term)
    g = with_linear_term(g) if linear_term else g
    # Independent: finite differences of H~ along the flow's generator. Each module flow is
    # the test flow with rate a_s sigma(x) + e_s x + b_s, x = <alpha_s, y>: d/dx of its potential.
    H = lambda y: np.asarray(g.hamiltonian(y))
    y = Y[0]
    grad_fd = np.array([(H(y + 1e-6 * e) - H(y - 1e-6 * e)) / 2e-6 for e in np.eye(3)])
    vectors = np.asarray(g.module_vectors())
    rates = np.asarray(g.a) * jax.nn.sigmoid(vectors @ y) + np.asarray(g.b)
    if linear_term:
        rates = rates + np.asarray(g.e) * (vectors @ y)
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


@pytest.mark.parametrize(
    "method, n_modules",
    [(it.splitting.TripleJump, 1), (it.splitting.TripleJump, 3), (it.splitting.Suzuki, 2),
     pytest.param(it.splitting.Yoshida6, 2, marks=pytest.mark.slow)],
)
def test_composed_network_is_the_composition_of_its_strang_steps(method, n_modules):
    g = learn.GLPNet(lp.systems.RigidBody(), n_modules, key=3, h=0.1, symmetric=True, full_vectors=True)
    c = g.composed(method)
    r = len(method.coefficients)
    assert c.symmetric and c.n_modules == r * (n_modules - 1) + 1 and c.h == g.h
    # Independent: r Strang steps of g at gamma_j h in sequence (negative gammas included).
    expected = Y
    for gamma in method.coefficients:
        expected = jax.vmap(eqx.tree_at(lambda m: m.h, g, gamma * g.h).step)(expected)
    # The same flows with adjacent ones merged: a few roundings per flow, r (2M - 1) flows.
    tol = 8 * r * (2 * n_modules - 1) * EPS * np.abs(Y).max()
    assert np.allclose(np.asarray(jax.vmap(c.step)(Y)), np.asarray(expected), rtol=0, atol=tol)
    # A splitting of the same learned Hamiltonian: each module's weights sum to sum(gamma) = 1.
    H = np.asarray(g.hamiltonian(Y))
    assert np.allclose(np.asarray(c.hamiltonian(Y)), H, rtol=0, atol=64 * EPS * np.abs(H).max())
    assert float(np.max(np.asarray(c.poisson_defect(Y)))) < 1e-13


def test_composed_network_has_the_composition_order_at_other_steps():
    # TripleJump of the learned Strang step is order 4 in h when run at other step sizes
    # (with_h), against the exact flow of the learned Hamiltonian (heyoka).
    g = net()
    c = g.composed(it.splitting.TripleJump)
    y0, T = Y[2], 2.0
    ref = np.asarray(it.ground_truth(g.learned_system(), y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([10, 20, 40])
    errors = [np.linalg.norm(np.asarray(c.with_h(T / n).rollout(y0, int(n)))[-1] - ref) for n in steps]
    observed = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(observed - 4) < 0.15, (errors, observed)


@pytest.mark.slow  # 40 s
def test_refit_of_the_composed_network_beats_the_strang_fit():
    # The recipe of `GLPNet.composed`: a symmetric fit, composed, refitted from there. On the
    # rigid body the Strang fit is already good (H is two pieces up to a Casimir): 8x measured.
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0 = np.random.default_rng(1).uniform(-1.0, 1.0, size=(10, 3))
    data = it.ground_truth(system, y0, h=0.2, n_steps=10, progress=False)
    strang, r1 = learn.fit(learn.GLPNet(system, 3, key=0, symmetric=True), data, progress=False,
                           optimiser=learn.QuasiNewton(300, "bfgs", warm_start=True))
    _, r2 = learn.fit(strang.composed(it.splitting.TripleJump), data, progress=False,
                       optimiser=learn.QuasiNewton(300, "bfgs", warm_start=False))
    assert r2.stages[0].kept and r2.train_loss < 0.2 * r1.train_loss, (r1.train_loss, r2.train_loss)


def test_composed_arguments():
    with pytest.raises(ValueError, match="symmetric"):
        net(symmetric=False).composed(it.splitting.TripleJump)
    with pytest.raises(TypeError, match="composition"):
        net().composed(it.splitting.Strang)
    with pytest.raises(TypeError, match="composition"):
        net().composed("TripleJump")


@pytest.mark.parametrize("linear_term", [False, True])
def test_symmetric_survives_save_and_load(tmp_path, linear_term):
    g = net(linear_term=linear_term)
    g = with_linear_term(g) if linear_term else g
    g.save(tmp_path / "g.h5")
    back = learn.GLPNet.load(tmp_path / "g.h5", lp.systems.RigidBody())
    assert back.symmetric and back.linear_term == linear_term
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(g.step)(Y)))


def test_warm_start_of_a_linear_term_network_is_exact():
    # The identity-activation fit maps onto the sigmoid network with a_s = 0, e_s = a_s + e_s:
    # the same rates, so the same step up to rounding.
    g = with_linear_term(net(linear_term=True))
    lin = eqx.tree_at(lambda m: m.activation, g, "identity")
    mapped = learn.linear_to_activation(g, lin, Y)
    assert np.allclose(np.asarray(jax.vmap(mapped.step)(Y)), np.asarray(jax.vmap(lin.step)(Y)),
                       rtol=0, atol=64 * EPS * np.abs(Y).max())
    assert not np.allclose(np.asarray(jax.vmap(g.step)(Y)), np.asarray(jax.vmap(lin.step)(Y)))


@pytest.mark.slow  # 28 s
def test_linear_term_fits_a_quadratic_plus_cosine_piece_a_sigmoid_cannot():
    # The heavy-top-like piece Phi(x) = x^2/2 + 0.1 cos x: on the rigid body with that extra
    # term the one-sigmoid Strang network stays at the sigmoid's fitting error, the linear
    # term reaches the splitting's own level (measured: so(4) 1.6e-8 -> 3.0e-12).
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    system = lp.systems.LiePoissonSystem(
        system.algebra, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 / 2 + m[2] ** 2 / 3) + 0.1 * xp.cos(m[0]),
        name="rigid body with cos",
    )
    y0 = np.random.default_rng(2).uniform(-1.0, 1.0, size=(10, 3))
    data = it.ground_truth(system, y0, h=0.1, n_steps=10, progress=False)
    losses = {}
    for linear_term in (False, True):
        _, rec = learn.fit(learn.GLPNet(system, 3, key=0, symmetric=True, linear_term=linear_term), data,
                           progress=False, optimiser=learn.QuasiNewton(300, "bfgs", warm_start=True))
        losses[linear_term] = rec.train_loss
    assert losses[True] < 0.01 * losses[False], losses


def test_arguments():
    with pytest.raises(TypeError, match="symmetric"):
        net(symmetric="yes")
    with pytest.raises(TypeError, match="linear_term"):
        net(linear_term=1)
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


@pytest.mark.slow  # 50 s: three BFGS fits (compilation)
def test_fit_splitting_recipe():
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0 = np.random.default_rng(3).uniform(-1.0, 1.0, size=(6, 3))
    data = it.ground_truth(system, y0, h=0.2, n_steps=10, progress=False)
    strang, (r1,) = learn.fit_splitting(system, data, None, iterations=60, progress=False)
    assert strang.symmetric and strang.linear_term and strang.n_modules == 3 and strang.h == 0.2
    tj, (r1b, r2) = learn.fit_splitting(system, data, iterations=60, progress=False)
    assert tj.n_modules == 7 and r1b.train_loss == r1.train_loss  # same seed, same first stage
    # The refit starts at TripleJump of the Strang fit and keeps only an improvement.
    (X, T), _ = data.split(0.2, 0)  # fit's training pairs
    start = float(learn.state_mse(strang.composed(it.splitting.TripleJump), X, T))
    assert r2.train_loss <= start
    assert float(np.max(np.asarray(tj.poisson_defect(Y)))) < 1e-13
    with pytest.raises(TypeError, match="composition"):
        learn.fit_splitting(system, data, it.splitting.Strang)
