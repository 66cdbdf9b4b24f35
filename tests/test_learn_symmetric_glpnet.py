"""The G-LPNet as a data-driven splitting method: a splitting method composing learned pieces.
A network with a given method is that method on its learned Hamiltonian (Strang: symmetric,
order 2, runs at other step sizes); the same learned pieces composed by a higher-order method
raise the order; files keep the method."""

import json

import equinox as eqx
import h5py
import jax
import numpy as np
import pytest
from helpers import SYSTEM_FACTORIES

import integrators as it
import learn
import liepoisson as lp

EPS = np.finfo(np.float64).eps
Y = np.random.default_rng(0).normal(size=(6, 3))
RB = lp.systems.RigidBody()


def net(method=it.splitting.Strang, activation="sigmoid", **kw):
    return learn.GLPNet(RB, 6, key=3, h=0.1, method=method, activation=activation, **kw)


def with_linear_term(g, key=7):
    """`g` with random linear coefficients e_s (they start at zero)."""
    return eqx.tree_at(lambda m: m.terms.e, g, 0.5 * jax.random.normal(jax.random.PRNGKey(key), (g.n_modules,)))


# Kirchhoff (12 modules, ~19 s of compilation for the three methods) under -m slow, and the rigid
# body's with -m slow too: its Strang and Lie-Trotter networks are checked against the classical
# method by default in test_every_activation_is_strang_of_its_learned_hamiltonian, a Strang network
# with linear terms in test_a_network_composes_its_modules_in_its_method_ordering, and the TripleJump
# composition's order against heyoka in test_composed_network_has_the_composition_order_at_other_steps.
@pytest.mark.parametrize("system_name", ["RigidBody", pytest.param("Kirchhoff", marks=pytest.mark.slow)])
@pytest.mark.parametrize(
    "method", [pytest.param(it.splitting.LieTrotter, marks=pytest.mark.slow),
               pytest.param(it.splitting.Strang, marks=pytest.mark.slow),
               pytest.param(it.splitting.TripleJump, marks=pytest.mark.slow)],
    ids=lambda m: m.__name__,
)
def test_network_with_a_method_is_that_method_on_its_learned_system(method, system_name):
    # The requirement: a G-LPNet with a given composition and integrators.splitting's
    # same method on its learned system give the same step. The classical side integrates the
    # pieces of H~ (the learned system's CollectiveTerms: rates by autodiff of the potential
    # w Phi_s, at time h), the network its own rates a_s sigma(x) + e_s x + b_s (at time h/M for
    # LieTrotter): a wrong weight w, piece or order would differ by O(h).
    system = SYSTEM_FACTORIES[system_name]()
    g = with_linear_term(learn.GLPNet(system, key=3, h=0.1, method=method, linear_term=True))
    assert g.n_modules == 2 * system.dim and g.activation == "sigmoid"
    y = np.random.default_rng(1).normal(size=(6, system.dim))
    ours = np.asarray(jax.vmap(g.step)(y))
    theirs = np.asarray(it.splitting.Splitting(g.learned_system(), 0.1, g.method).rollout(y, 1))[:, -1]
    # The same flows in the same order; each flow's rate differs by a few roundings (sigmoid
    # against the derivative of softplus, w q against q / M), which moves its output by a few
    # eps |y|, and later flows carry that along (near-isometries at |h alpha| ~ 0.1): 8 eps |y|
    # per flow of the step.
    size = max(np.abs(y).max(), np.abs(ours).max())
    tol = 8 * g.exact_flows_per_step * EPS * size
    assert np.abs(ours - theirs).max() <= tol, (np.abs(ours - theirs).max(), tol)
    assert np.abs(ours - y).max() > 1e4 * tol  # a real step, not the identity on both sides
    assert g.exact_flows_per_step == method().flows_per_step(2 * system.dim)


# the sigmoid (the default activation) by default; the other activations and the linear term with
# -m slow (a Strang network with linear terms runs by default in
# test_a_network_composes_its_modules_in_its_method_ordering)
@pytest.mark.parametrize(("activation", "linear_term"), [
    ("sigmoid", False),
    *(pytest.param(a, b, marks=pytest.mark.slow)
      for a, b in [("tanh", True), ("identity", False), ("sigmoid", True), ("tanh", False), ("identity", True)]),
])
def test_every_activation_is_strang_of_its_learned_hamiltonian(activation, linear_term):
    g = net(activation=activation, linear_term=linear_term)
    if linear_term:
        g = with_linear_term(g)
    ours = np.asarray(jax.vmap(g.step)(Y))
    strang = np.asarray(it.splitting.Strang(g.learned_system(), 0.1).rollout(Y, 1))[:, -1]
    # The same 11 flows in the same order: equal up to a few roundings.
    assert np.allclose(ours, strang, rtol=0, atol=16 * EPS * np.abs(Y).max())
    assert g.exact_flows_per_step == 11
    # And the paper's network is Lie-Trotter of H/M.
    p = net(method=it.splitting.LieTrotter, activation=activation)
    lt = np.asarray(it.splitting.LieTrotter(p.learned_system(), 0.1).rollout(Y, 1))[:, -1]
    assert np.allclose(np.asarray(jax.vmap(p.step)(Y)), lt, rtol=0, atol=16 * EPS * np.abs(Y).max())
    assert p.exact_flows_per_step == 6


@pytest.mark.parametrize(
    "method, weight",
    [(it.splitting.LieTrotter, 1 / 6), (it.splitting.Strang, 1.0), (it.splitting.TripleJump, 1.0)],
    ids=["LieTrotter", "Strang", "TripleJump"],
)
@pytest.mark.parametrize("linear_term", [False, True])
def test_learned_hamiltonian_is_the_sum_of_the_module_potentials(linear_term, method, weight):
    # w = 1/M for the paper's Lie-Trotter network (each module over h/M), 1 otherwise.
    g = net(method=method, full_vectors=True, linear_term=linear_term)
    g = with_linear_term(g) if linear_term else g
    assert g.hamiltonian_weight == weight
    # Independent: finite differences of H~ along the flow's generator. Each module flow is
    # the test flow with rate a_s sigma(x) + e_s x + b_s, x = <alpha_s, y>: d/dx of its potential.
    H = lambda y: np.asarray(g.hamiltonian(y))
    y = Y[0]
    grad_fd = np.array([(H(y + 1e-6 * e) - H(y - 1e-6 * e)) / 2e-6 for e in np.eye(3)])
    t = g.terms
    vectors = np.asarray(g.module_vectors())
    assert np.array_equal(vectors, np.asarray(t.vectors()))
    rates = np.asarray(t.a) * jax.nn.sigmoid(vectors @ y) + np.asarray(t.b)
    if linear_term:
        rates = rates + np.asarray(t.e) * (vectors @ y)
    # Central differences: error O(1e-12 * H''') + round-off eps|H|/1e-6 ~ 1e-9.
    assert np.allclose(grad_fd, weight * vectors.T @ rates, rtol=0, atol=1e-8)
    assert np.allclose(np.asarray(g.learned_system().hamiltonian(Y)), H(Y), rtol=0, atol=8 * EPS * np.abs(H(Y)).max())


def test_symmetric_network_is_time_symmetric_and_poisson():
    g = net()
    back = eqx.tree_at(lambda m: m.h, g, -0.1)  # with_h refuses h < 0 on purpose
    y1 = jax.vmap(g.step)(Y)
    # Phi_{-h} o Phi_h = id: the palindrome of exact flows.
    assert np.allclose(np.asarray(jax.vmap(back.step)(y1)), Y, rtol=0, atol=64 * EPS * np.abs(Y).max())
    assert float(np.max(np.asarray(g.poisson_defect(Y)))) < 1e-13
    # the paper's Lie-Trotter network is Poisson but not symmetric
    lt = net(method=it.splitting.LieTrotter)
    lt_back = eqx.tree_at(lambda m: m.h, lt, -0.1)
    assert np.abs(np.asarray(jax.vmap(lt_back.step)(jax.vmap(lt.step)(Y))) - Y).max() > 1e-6
    assert float(np.max(np.asarray(lt.poisson_defect(Y)))) < 1e-13


@pytest.mark.parametrize("method, order", [(it.splitting.Strang, 2), (it.splitting.LieTrotter, 1)],
                         ids=["Strang", "LieTrotter"])
def test_order_against_heyoka_on_the_learned_hamiltonian(method, order):
    # The step map is a splitting of H~, so against H~'s exact flow (heyoka on the learned
    # system) it converges with the splitting's order as h -> 0.
    g = net(method=method)
    system = g.learned_system()
    y0, T = Y[0], 2.0
    ref = np.asarray(it.ground_truth(system, y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([20, 40, 80, 160])
    errors = [np.linalg.norm(np.asarray(g.with_h(T / n).rollout(y0, int(n), save_every=int(n)))[-1] - ref) for n in steps]
    observed = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(observed - order) < 0.1, (errors, observed)


@pytest.mark.slow  # a composed network's order against heyoka by default in test_composed_network_has_the_composition_order_at_other_steps
def test_compositions_of_the_learned_splitting_raise_the_order():
    g = net()
    system = g.learned_system()
    y0, T = Y[1], 2.0
    ref = np.asarray(it.ground_truth(system, y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([10, 20, 40])
    errors = [
        np.linalg.norm(np.asarray(it.splitting.TripleJump(system, T / n).rollout(y0, int(n), save_every=int(n)))[-1] - ref) for n in steps
    ]
    observed = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(observed - 4) < 0.15, (errors, observed)


# with -m slow: a composed network's order against heyoka runs by default
# (test_composed_network_has_the_composition_order_at_other_steps)
@pytest.mark.parametrize(
    "method, n_modules",
    [pytest.param(it.splitting.TripleJump, 1, marks=pytest.mark.slow),
     pytest.param(it.splitting.TripleJump, 3, marks=pytest.mark.slow),
     pytest.param(it.splitting.Suzuki, 2, marks=pytest.mark.slow),
     pytest.param(it.splitting.Yoshida6, 2, marks=pytest.mark.slow)],
)
def test_composed_network_is_the_composition_of_its_strang_steps(method, n_modules):
    g = learn.GLPNet(RB, n_modules, key=3, h=0.1, method=it.splitting.Strang, full_vectors=True)
    c = learn.GLPNet(RB, terms=g.terms, method=method, h=g.h)
    r = len(method.coefficients)
    # the same learned pieces, composed by another method
    assert c.terms is g.terms and c.method == method() and c.h == g.h
    assert c.exact_flows_per_step == r * (2 * n_modules - 1)
    # Independent: r Strang steps of g at gamma_j h in sequence (negative gammas included).
    expected = Y
    for gamma in method.coefficients:
        expected = jax.vmap(eqx.tree_at(lambda m: m.h, g, gamma * g.h).step)(expected)
    # The same r (2M - 1) flows: a few roundings per flow.
    tol = 8 * r * (2 * n_modules - 1) * EPS * np.abs(Y).max()
    assert np.allclose(np.asarray(jax.vmap(c.step)(Y)), np.asarray(expected), rtol=0, atol=tol)
    # A splitting of the same learned Hamiltonian (w = 1 for both).
    H = np.asarray(g.hamiltonian(Y))
    assert np.allclose(np.asarray(c.hamiltonian(Y)), H, rtol=0, atol=8 * EPS * np.abs(H).max())
    assert float(np.max(np.asarray(c.poisson_defect(Y)))) < 1e-13


def test_lie_trotter_pieces_composed_by_another_method_drop_the_one_over_m():
    # The paper's network runs each module over h/M: its Hamiltonian is (1/M) sum Phi_s. The same
    # pieces composed by Strang or TripleJump run each over h (or its fractions): sum Phi_s.
    lt = with_linear_term(net(method=it.splitting.LieTrotter, linear_term=True))
    tj = learn.GLPNet(RB, terms=lt.terms, method=it.splitting.TripleJump, h=lt.h)
    H6 = 6 * np.asarray(lt.hamiltonian(Y))
    tol = 8 * EPS * np.abs(H6).max()  # a sum of six potentials, each a few roundings
    assert np.allclose(np.asarray(tj.hamiltonian(Y)), H6, rtol=0, atol=tol)
    assert np.allclose(np.asarray(tj.learned_system().hamiltonian(Y)), H6, rtol=0, atol=tol)


def test_composed_network_has_the_composition_order_at_other_steps():
    # TripleJump of the learned Strang step is order 4 in h when run at other step sizes
    # (with_h), against the exact flow of the learned Hamiltonian (heyoka).
    g = net()
    c = learn.GLPNet(RB, terms=g.terms, method=it.splitting.TripleJump, h=g.h)
    y0, T = Y[2], 2.0
    ref = np.asarray(it.ground_truth(g.learned_system(), y0, h=T, n_steps=1, progress=False).states)[0, -1]
    steps = np.array([10, 20, 40])
    errors = [np.linalg.norm(np.asarray(c.with_h(T / n).rollout(y0, int(n), save_every=int(n)))[-1] - ref) for n in steps]
    observed = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(observed - 4) < 0.15, (errors, observed)


@pytest.mark.slow  # 40 s
def test_refit_of_the_composed_network_beats_the_strang_fit():
    # The recipe: a Strang fit, its pieces composed by TripleJump, refitted from there. On the
    # rigid body the Strang fit is already good (H is two pieces up to a Casimir): 8x measured.
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0 = np.random.default_rng(1).uniform(-1.0, 1.0, size=(10, 3))
    data = it.ground_truth(system, y0, h=0.2, n_steps=10, progress=False)
    strang, r1 = learn.fit(learn.GLPNet(system, 3, key=0, method=it.splitting.Strang), data, progress=False,
                           optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(300))))
    composed = learn.GLPNet(system, terms=strang.terms, method=it.splitting.TripleJump, h=strang.h)
    _, r2 = learn.fit(composed, data, progress=False, optimiser=learn.KeepIfBetter(learn.ScipyBFGS(300)))
    assert r2.stages[0].kept and r2.train_loss < 0.2 * r1.train_loss, (r1.train_loss, r2.train_loss)


def test_method_and_terms_arguments():
    with pytest.raises(TypeError, match="method must be a splitting method"):
        net(method="TripleJump")
    with pytest.raises(TypeError, match="method must be a splitting method"):
        net(method=learn.GLPNet)
    with pytest.raises(ValueError, match="BlanesMoan4 needs a two-part splitting.*6 modules"):
        net(method=it.splitting.BlanesMoan4)
    # a class stands for its instance without ordering; a step map is not a method
    assert net(method=it.splitting.Strang).method == it.splitting.Strang()
    with pytest.raises(TypeError, match="step map bound to a system: pass its method"):
        net(method=it.splitting.Strang(RB, 0.1))
    with pytest.raises(ValueError, match=r"ordering must be a permutation of range\(6\) \(the 6 pieces of a GLPNet"):
        net(method=it.splitting.Strang(ordering=(2, 1, 0)))
    with pytest.raises(TypeError, match="terms must be a learn.RidgeTerms"):
        learn.GLPNet(RB, terms="pieces")
    with pytest.raises(ValueError, match="terms are for states of dimension 3"):
        learn.GLPNet(lp.systems.Kirchhoff(), terms=net().terms)


def test_a_network_composes_its_modules_in_its_method_ordering():
    # A method is a stateless object: Strang(ordering=p) in a G-LPNet applies the modules in
    # order p, as the same method bound to the learned system's pieces does (the classical
    # side integrates the CollectiveTerms of H~, by autodiff of the potentials: a few roundings
    # per flow, carried along by the later flows, as in the test above).
    p = (3, 0, 5, 1, 4, 2)
    assert it.splitting.Strang(ordering=p) != it.splitting.Strang(ordering=(0, 1, 2, 3, 4, 5))
    assert it.splitting.Strang(ordering=p) != it.splitting.Strang()
    assert it.splitting.Strang(ordering=p) == it.splitting.Strang(ordering=list(p))
    assert hash(it.splitting.Strang(ordering=p)) == hash(it.splitting.Strang(ordering=list(p)))
    g = with_linear_term(net(method=it.splitting.Strang(ordering=p), linear_term=True))
    assert g.method.ordering == p
    ours = np.asarray(jax.vmap(g.step)(Y))
    bound = it.splitting.Splitting(g.learned_system(), 0.1, it.splitting.Strang(ordering=p))
    assert bound.terms == tuple(bound.pieces[k] for k in p)
    theirs = np.asarray(bound.rollout(Y, 1))[:, -1]
    tol = 8 * g.exact_flows_per_step * EPS * max(np.abs(Y).max(), np.abs(ours).max())
    assert np.abs(ours - theirs).max() <= tol, (np.abs(ours - theirs).max(), tol)
    # and the ordering matters: the modules' own order gives another step
    plain = np.asarray(jax.vmap(learn.GLPNet(RB, terms=g.terms, method=it.splitting.Strang(), h=g.h).step)(Y))
    assert np.abs(plain - theirs).max() > 1e4 * tol


def test_method_ordering_survives_save_and_load_and_older_files_name_the_method(tmp_path):
    p = (5, 4, 3, 2, 1, 0)
    g = net(method=it.splitting.TripleJump(ordering=p))
    assert g.hyperparameters()["method"] == {"name": "TripleJump", "ordering": list(p)}
    g.save(tmp_path / "g.h5")
    back = learn.GLPNet.load(tmp_path / "g.h5", RB)
    assert back.method == it.splitting.TripleJump(ordering=p)
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(g.step)(Y)))
    # a file written before the ordering was recorded names the method alone
    old = net(method=it.splitting.Strang)
    old.save(tmp_path / "old.h5")
    with h5py.File(tmp_path / "old.h5", "r+") as f:
        hp = json.loads(f.attrs["hyperparameters_json"])
        f.attrs["hyperparameters_json"] = json.dumps({**hp, "method": "Strang"})
    back = learn.GLPNet.load(tmp_path / "old.h5", RB)
    assert back.method == it.splitting.Strang()
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(old.step)(Y)))


# fit_splitting's network (TripleJump, linear terms) by default; the other three with -m slow
@pytest.mark.parametrize(("method", "linear_term"), [
    pytest.param(m, b, id=f"{m.__name__}-{b}",
                 marks=() if (m, b) == (it.splitting.TripleJump, True) else pytest.mark.slow)
    for m in (it.splitting.Strang, it.splitting.TripleJump) for b in (False, True)])
def test_method_survives_save_and_load(tmp_path, linear_term, method):
    g = net(method=method, linear_term=linear_term)
    g = with_linear_term(g) if linear_term else g
    g.save(tmp_path / "g.h5")
    back = learn.GLPNet.load(tmp_path / "g.h5", lp.systems.RigidBody())
    assert back.method == g.method and back.terms.linear_term == linear_term
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(g.step)(Y)))


@pytest.mark.parametrize("symmetric, method", [(True, it.splitting.Strang), (False, it.splitting.LieTrotter)])
def test_version_1_file_of_a_glpnet_loads_with_its_method(tmp_path, symmetric, method):
    # Written by hand as format version 1 stored a GLPNet: the flag symmetric, the arrays a, c,
    # b, e of the network in field order.
    g = with_linear_term(net(method=method, linear_term=True))
    t = g.terms
    with h5py.File(tmp_path / "v1.h5", "w") as f:
        f.attrs["format"] = "learn-model"
        f.attrs["format_version"] = 1
        f.attrs["class"] = "GLPNet"
        f.attrs["system"] = RB.name
        f.attrs["system_params_json"] = json.dumps(RB.params)
        f.attrs["hyperparameters_json"] = json.dumps({
            "n_modules": 6, "order": list(t.order), "full_vectors": False, "activation": "sigmoid",
            "symmetric": symmetric, "linear_term": True})
        f.attrs["h"] = 0.1
        f.attrs["liepoisson_version"] = lp.__version__
        weights = f.create_group("weights")
        weights.attrs["kind"] = "list"
        weights.attrs["count"] = 4
        for i, array in enumerate((t.a, t.c, t.b, t.e)):
            weights.create_dataset(f"{i:04d}", data=np.asarray(array))
    back = learn.GLPNet.load(tmp_path / "v1.h5")
    assert back.method == method() and back.h == 0.1 and back.terms.linear_term
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(g.step)(Y)))


def test_warm_start_of_a_linear_term_network_is_exact():
    # The identity-activation fit maps onto the sigmoid network with a_s = 0, e_s = a_s + e_s:
    # the same rates, so the same step up to rounding.
    g = with_linear_term(net(linear_term=True))
    lin = eqx.tree_at(lambda m: m.terms, g, g.terms.with_activation("identity"))
    mapped = learn.linear_to_activation(g, lin, Y)
    assert mapped.activation == "sigmoid" and mapped.method == g.method
    assert np.allclose(np.asarray(jax.vmap(mapped.step)(Y)), np.asarray(jax.vmap(lin.step)(Y)),
                       rtol=0, atol=64 * EPS * np.abs(Y).max())
    assert not np.allclose(np.asarray(jax.vmap(g.step)(Y)), np.asarray(jax.vmap(lin.step)(Y)))
    # the warm start learn.fit asks the network for is that identity-activation network
    simpler, _ = g.warm_start()
    assert simpler.activation == "identity" and simpler.method == g.method and simpler.terms.a is g.terms.a


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
        _, rec = learn.fit(learn.GLPNet(system, 3, key=0, method=it.splitting.Strang, linear_term=linear_term),
                           data, progress=False, optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(300))))
        losses[linear_term] = rec.train_loss
    assert losses[True] < 0.01 * losses[False], losses


def test_arguments():
    with pytest.raises(TypeError, match="linear_term"):
        net(linear_term=1)
    with pytest.raises(TypeError, match="full_vectors"):
        net(full_vectors="yes")
    with pytest.raises(ValueError, match="antiderivative"):
        net(activation="relu").hamiltonian(Y)
    with pytest.raises(ValueError, match="h"):
        net().with_h(0.0)


@pytest.mark.slow  # 23 s
def test_compiled_losses_are_shared_across_step_sizes_without_mixing_them():
    """Quasi-Newton losses are compiled once per model structure with h as an argument: a fit
    at h = 0.2 after one at h = 0.1 (cache warm) equals a fit at h = 0.2 from a cold cache."""
    import learn._solvers._compiled as compiled

    body = lp.systems.RigidBody()
    y0 = np.random.default_rng(0).uniform(-1.0, 1.0, size=(6, 3))
    opt = learn.KeepIfBetter(learn.ScipyBFGS(15))

    def fitted(h):
        data = it.ground_truth(body, y0, h=h, n_steps=5, seed=0)
        model, _ = learn.fit(learn.GLPNet(body, key=0, method=it.splitting.Strang), data, optimiser=opt,
                             validation_fraction=0.0, progress=False)
        return model

    fitted(0.1)
    warm = fitted(0.2)
    assert compiled._CACHE  # the fits compiled through the shared cache
    compiled._CACHE.clear()  # every solver's compiled functions
    cold = fitted(0.2)
    for name in ("a", "b", "c"):
        np.testing.assert_array_equal(np.asarray(getattr(warm.terms, name)), np.asarray(getattr(cold.terms, name)))
    assert warm.h == cold.h == 0.2


@pytest.mark.slow  # 50 s: three BFGS fits (compilation)
def test_fit_splitting_recipe():
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0 = np.random.default_rng(3).uniform(-1.0, 1.0, size=(6, 3))
    data = it.ground_truth(system, y0, h=0.2, n_steps=10, progress=False)
    strang, (r1,) = learn.fit_splitting(system, data, None, iterations=60, progress=False)
    assert strang.method == it.splitting.Strang() and strang.terms.linear_term
    assert strang.n_modules == 3 and strang.h == 0.2
    tj, (r1b, r2) = learn.fit_splitting(system, data, iterations=60, progress=False)
    assert tj.method == it.splitting.TripleJump() and tj.n_modules == 3
    assert r1b.train_loss == r1.train_loss  # same seed, same first stage
    # The refit starts at TripleJump of the Strang fit's pieces and keeps only an improvement.
    (X, T), _ = data.split(0.2, 0)  # fit's training pairs
    start = learn.GLPNet(system, terms=strang.terms, method=it.splitting.TripleJump, h=strang.h)
    assert r2.train_loss <= float(learn.state_mse(start, X, T))
    assert float(np.max(np.asarray(tj.poisson_defect(Y)))) < 1e-13
    with pytest.raises(TypeError, match="method must be a splitting method"):
        learn.fit_splitting(system, data, "TripleJump")
