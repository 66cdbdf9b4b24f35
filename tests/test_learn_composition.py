"""Learned maps are built by composition: what a combination that cannot work does (refused at
construction, naming the argument), and the parts that files and restarts must keep."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp

RB = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
Y = np.random.default_rng(0).normal(size=(4, 3))


class MyTripleJump(it.splitting.AbstractCompositionMethod):
    """A user's composition method (TripleJump's table under another name)."""

    order = 4
    coefficients = it.splitting.TripleJump.coefficients


@pytest.mark.parametrize("build, words", [
    (lambda mlp: learn.LPNet(RB, hidden=(4,), network=mlp), "hidden: these describe the default network"),
    (lambda mlp: learn.LPNet(RB, activation="tanh", key=3, network=mlp), "activation, key: these describe"),
    (lambda mlp: learn.MLPBaseline(RB, input_scaling=((1, 1, 1), (2, 2, 2)), network=mlp), "input_scaling"),
    (lambda mlp: learn.GLPNet(RB, n_modules=4, terms=learn.RidgeTerms(3, 6)), "n_modules: these describe the default terms"),
    (lambda mlp: learn.GLPNet(RB, linear_term=True, terms=learn.RidgeTerms(3, 6)), "linear_term"),
])
def test_a_part_given_whole_refuses_the_arguments_it_would_ignore(build, words):
    with pytest.raises(ValueError, match=words):
        build(learn.AffineMLP(3, 3, hidden=(8,)))


def test_a_nested_group_average_is_checked_at_every_depth():
    # [-1, 1, 1] is anti-Poisson for the rigid body (a reversing symmetry, not a symmetry): the
    # claimed equivariance would be false, at the top level or one wrapper down alike.
    inner = learn.GroupAveraged(learn.AffineMLP(3, 3, hidden=(4,)), [[-1, 1, 1]])
    with pytest.raises(ValueError, match=r"\[-1, 1, 1\]"):
        learn.LPNet(RB, network=inner)
    with pytest.raises(ValueError, match=r"\[-1, 1, 1\]"):
        learn.LPNet(RB, network=learn.GroupAveraged(inner, []))


def test_reinitialised_keeps_every_part_and_changes_the_weights():
    mlp = learn.AffineMLP(3, 3, hidden=(4,), key=1, input_scaling=((0.1, 0.2, 0.3), (1.0, 2.0, 3.0)))
    net = learn.Reversible(learn.LPNet(RB, network=learn.GroupAveraged(mlp, lp.systems.sign_symmetries(RB)), h=0.1),
                           symmetry=[1, -1, 1], iterations=7)
    new = net.reinitialised(5)
    assert (new.symmetry, new.iterations, new.h) == (net.symmetry, net.iterations, net.h)
    assert new.lpnet.network.group == net.lpnet.network.group
    assert new.lpnet.network.network.input_scale == (1.0, 2.0, 3.0)
    old_w, new_w = net.lpnet.network.network.mlp.layers[0].weight, new.lpnet.network.network.mlp.layers[0].weight
    assert old_w.shape == new_w.shape and not np.allclose(old_w, new_w)
    g = learn.GLPNet(RB, key=0, h=0.1, method=MyTripleJump)
    g2 = g.reinitialised(4)
    assert g2.method == MyTripleJump() and g2.terms.order == g.terms.order and not np.allclose(g2.terms.a, g.terms.a)


def test_a_map_the_library_cannot_rebuild_is_refused_before_writing(tmp_path):
    path = tmp_path / "g.h5"
    with pytest.raises(ValueError, match="cannot be saved.*MyTripleJump"):
        learn.GLPNet(RB, h=0.1, method=MyTripleJump).save(path)
    assert not path.exists()


@pytest.mark.parametrize("make", [
    lambda: learn.LPNet(RB, hidden=(4,), h=0.1),
    lambda: learn.Reversible(learn.LPNet(RB, hidden=(4,), h=0.1)),
    lambda: learn.GLPNet(RB, h=0.1, method=it.splitting.Strang),
    lambda: learn.MLPBaseline(RB, hidden=(4,), h=0.1),
])
def test_learn_load_reads_any_class(tmp_path, make):
    net = make()
    net.save(tmp_path / "m.h5")
    back = learn.load(tmp_path / "m.h5")
    assert type(back) is type(net)
    assert np.array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(net.step)(Y)))


def test_learn_load_names_a_file_that_holds_no_learned_map(tmp_path):
    data = it.ground_truth(RB, Y, h=0.1, n_steps=2, progress=False)
    data.save(tmp_path / "d.h5")
    with pytest.raises(ValueError, match="trajectory data set"):
        learn.load(tmp_path / "d.h5")


@pytest.mark.slow  # every G-LPNet fit of the default run jits and differentiates the network
def test_a_glpnet_is_a_pytree_jax_transforms():
    # the activation is a static field: jit and grad see only arrays
    g = learn.GLPNet(RB, h=0.1, method=it.splitting.Strang)
    y = jnp.asarray(Y[0])
    assert np.allclose(jax.jit(lambda m, y: m.step(y))(g, y), g.step(y), rtol=0, atol=0)
    grads = jax.grad(lambda m: jnp.sum(m.step(y) ** 2))(g)
    assert np.all(np.isfinite(grads.terms.a)) and np.any(grads.terms.a != 0)


def test_fit_splitting_refuses_a_method_before_training():
    data = it.ground_truth(RB, Y, h=0.1, n_steps=3, progress=False)
    with pytest.raises(ValueError, match="BlanesMoan4 needs a two-part splitting"):
        learn.fit_splitting(RB, data, method=it.splitting.BlanesMoan4, iterations=1)
    with pytest.raises(ValueError, match="LieTrotter would not continue from the Strang fit"):
        learn.fit_splitting(RB, data, method=it.splitting.LieTrotter, iterations=1)


def test_a_method_ordering_of_other_pieces_is_refused():
    with pytest.raises(ValueError, match=r"range\(6\).*got \(2, 1, 0\)"):
        learn.GLPNet(RB, method=it.splitting.Strang(ordering=(2, 1, 0)))


def test_fit_checks_its_flags():
    data = it.ground_truth(RB, Y, h=0.1, n_steps=3, progress=False)
    with pytest.raises(TypeError, match="normalise must be True or False; got 'no'"):
        learn.fit(learn.LPNet(RB, hidden=(4,)), data, normalise="no", epochs=1, progress=False)
    with pytest.raises(ValueError, match="ScipyBFGS.rtol must be a number in \\[0, 1\\); got 'yes'"):
        learn.ScipyBFGS(10, rtol="yes")


def test_group_averaged_scalings_come_from_the_group_orbit():
    # The inner network sees S y and must produce S alpha: on so(3) the orbit of any sample
    # set under the half-turns has mean 0 in every component, so a normalised equivariant
    # network has zero shifts (the average would cancel a shift in a flipped component anyway).
    group = lp.systems.sign_symmetries(RB)
    net = learn.GroupAveraged(learn.AffineMLP(3, 3, hidden=(4,)), group)
    x = np.random.default_rng(1).normal(loc=2.0, size=(50, 3))
    scaled = net.rescaled(x, 3.0 * x)
    assert np.allclose(scaled.network.input_shift, 0.0, atol=1e-12)
    assert np.allclose(scaled.network.output_shift, 0.0, atol=1e-12)
    # and the averaged network is still equivariant with those scalings
    for s in np.asarray(group):
        assert np.allclose(scaled(jnp.asarray(s * x[0])), s * np.asarray(scaled(jnp.asarray(x[0]))), atol=1e-14)


def test_a_zero_start_is_the_constant_test_flow_at_the_output_shift():
    # init="zero": the last layer starts at zero weights and bias, so alpha(y) is the output
    # shift at every y and the step is the exact test flow of that constant alpha.
    shift, scale = (0.3, -0.2, 0.5), (2.0, 3.0, 4.0)
    net = learn.LPNet(RB, hidden=(4,), key=2, output_scaling=(shift, scale), init="zero", h=0.1)
    np.testing.assert_array_equal(np.asarray(jax.vmap(net.network)(Y)), np.broadcast_to(shift, Y.shape))
    want = np.stack([np.asarray(RB.test_flow(jnp.asarray(shift), 0.1, y)) for y in Y])
    np.testing.assert_array_equal(np.asarray(jax.vmap(net.step)(Y)), want)
    # the hidden layer keeps its random start (from the same key as the default network's)
    default = learn.LPNet(RB, hidden=(4,), key=2, h=0.1)
    np.testing.assert_array_equal(net.network.mlp.layers[0].weight, default.network.mlp.layers[0].weight)
    assert not np.any(default.network.mlp.layers[-1].weight == 0.0)


def test_a_zero_start_is_part_of_the_architecture(tmp_path):
    net = learn.LPNet(RB, hidden=(4,), init="zero", h=0.1)
    assert net.network.spec()["init"] == "zero"
    # files written before `init` existed have none: a default network's spec stays the same
    assert "init" not in learn.LPNet(RB, hidden=(4,)).network.spec()
    moved = jax.tree_util.tree_map(lambda w: w + 0.25, net)  # as a fit would leave it
    moved.save(tmp_path / "z.h5")
    back = learn.load(tmp_path / "z.h5")
    assert back.network.init == "zero"
    np.testing.assert_array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(moved.step)(Y)))
    for fresh in (back.reinitialised(7), learn.LPNet.from_hyperparameters(RB, back.hyperparameters(), key=7, h=0.1)):
        last = fresh.network.mlp.layers[-1]
        assert not np.any(last.weight) and not np.any(last.bias)


@pytest.mark.parametrize("init", ["zeros", None, 0])
def test_an_unknown_start_is_refused_naming_it(init):
    with pytest.raises(ValueError, match=r"init must be one of \('random', 'zero'\)"):
        learn.AffineMLP(3, 3, init=init)


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_a_fit_from_a_zero_start_lowers_the_loss():
    # the gradient reaches the zero last layer (and through it the hidden ones): pairs of a map
    # whose alpha varies with the state, y1 = exp flow of grad H(y0) (a Lie-Euler step)
    y0 = np.random.default_rng(3).normal(size=(24, 3))
    y1 = np.asarray(jax.vmap(lambda y: RB.test_flow(RB.hamiltonian_gradient(y), 0.1, y))(jnp.asarray(y0)))
    net = learn.LPNet(RB, hidden=(8,), init="zero", h=0.1).normalised(y0, y1, 0.1)
    before = float(learn.state_mse(net, jnp.asarray(y0), jnp.asarray(y1)))
    fitted, record = learn.fit(net, (y0, y1), h=0.1, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(15)), validation_fraction=0.0,
                                 progress=False, normalise=False)
    assert record.train_loss < 0.1 * before
    assert np.any(fitted.network.mlp.layers[-1].weight != 0.0)


def test_a_glpnet_zero_start_is_the_identity_step_and_is_kept_by_files(tmp_path):
    # init="zero": a_s = b_s = 0, so H~ = 0 and every module's flow is the identity
    net = learn.GLPNet(RB, n_modules=4, init="zero", h=0.1, method=it.splitting.Strang)
    np.testing.assert_array_equal(np.asarray(jax.vmap(net.step)(Y)), Y)
    assert net.hyperparameters()["init"] == "zero" and "init" not in learn.GLPNet(RB).hyperparameters()
    moved = eqx.tree_at(lambda m: m.terms.a, net, net.terms.a + 0.5)  # as a fit would leave it
    moved.save(tmp_path / "g.h5")
    back = learn.load(tmp_path / "g.h5")
    np.testing.assert_array_equal(np.asarray(jax.vmap(back.step)(Y)), np.asarray(jax.vmap(moved.step)(Y)))
    for fresh in (back.reinitialised(3), learn.GLPNet.from_hyperparameters(RB, back.hyperparameters(), key=3)):
        assert fresh.terms.init == "zero" and not np.any(fresh.terms.a) and not np.any(fresh.terms.b)


def test_a_zero_start_gives_full_vectors_of_unit_expected_length():
    # the paper's start draws each component from N(0, 1): |alpha_s|^2 ~ dim; the zero start
    # scales them by 1/sqrt(dim): mean |alpha_s|^2 = 1 (64 modules of dimension 16: the sample
    # mean of a chi^2_16 / 16 has standard deviation 0.044)
    system = lp.systems.Zeitlin(4)
    lengths = [np.mean(np.sum(np.asarray(learn.RidgeTerms(system.dim, 64, key=2, full_vectors=True, init=init)
                                         .vectors()) ** 2, axis=1)) for init in ("random", "zero")]
    assert abs(lengths[0] / system.dim - 1.0) < 0.25 and abs(lengths[1] - 1.0) < 0.25


def test_a_glpnet_fit_from_a_zero_start_lowers_the_loss():
    y0 = np.random.default_rng(4).normal(size=(24, 3))
    y1 = np.asarray(it.splitting.Strang(RB, 0.1).rollout(y0, 1))[:, -1]
    net = learn.GLPNet(RB, n_modules=6, init="zero", h=0.1, method=it.splitting.Strang)
    before = float(learn.state_mse(net, jnp.asarray(y0), jnp.asarray(y1)))
    _, record = learn.fit(net, (y0, y1), h=0.1, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(15)), validation_fraction=0.0,
                               progress=False)
    assert record.train_loss < 0.1 * before
