"""Learned maps are built by composition: what a combination that cannot work does (refused at
construction, naming the argument), and the parts that files and restarts must keep."""

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
    with pytest.raises(TypeError, match="QuasiNewton.warm_start must be True or False"):
        learn.QuasiNewton(10, warm_start="yes")


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
