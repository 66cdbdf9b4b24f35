"""Small calls a user waits on: `learn.latent_momenta` compiled and vectorised, and rollouts of
any length from one compiled program (`AbstractStepMap.rollout`, `lifted_rollout`), each
against the implementation it replaced (copied here as the reference)."""


import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import compilations, slow_except

import integrators as it
import learn
import liepoisson as lp
from benchmarks.small_calls import former_latent_momenta, former_lifted_compiled, former_rollout
from integrators import splitting
from integrators.internals import traced_h

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
H = 0.1


# -- the implementations replaced (commit 46d8bf6), kept by the benchmark that times them --------
def old_rollout(m, y0, n_steps, save_every=1):
    """The former `rollout`, its states returned as they are (non-finite ones too)."""
    return former_rollout(m, y0, n_steps, save_every, check=False)


# -- counting compilations ------------------------------------------------------------------------
TRACES = {"step": 0}


class Counted(it.AbstractReconstructingStepMap):
    """A map that counts how often its step is traced (a Python side effect runs at tracing
    only): once per compiled program that steps it."""

    inner: it.AbstractReconstructingStepMap
    system: lp.systems.AbstractPoissonSystem
    h: float | None

    def __init__(self, inner):
        self.inner, self.system, self.h = inner, inner.system, inner.h

    @property
    def exact_flows_per_step(self):
        return self.inner.exact_flows_per_step

    def step(self, y):
        TRACES["step"] += 1
        return self.inner.step(y)

    def lifted_step(self, g, y):
        TRACES["step"] += 1
        return self.inner.lifted_step(g, y)


def starts(n_traj, seed=0):
    """`(y0, g0)`: momenta `(n_traj, 3)` and unit quaternions `(n_traj, 4)`."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n_traj, 4))
    return rng.normal(size=(n_traj, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)


# -- latent_momenta --------------------------------------------------------------------------------
# batches of more than one shape under -m slow (the default run's time): the single state by default
@pytest.mark.parametrize("key, shape", [(0, (3,)), pytest.param(1, (5, 3), marks=pytest.mark.slow),
                                        pytest.param(2, (2, 2, 3), marks=pytest.mark.slow)])
def test_latent_momenta_is_the_python_loop_it_replaced(key, shape):
    net = learn.GLPNet(BODY, n_modules=3, key=key, h=H)
    # velocities the network reaches (its sigmoid ridges saturate: not every xi has momenta)
    mu_true = np.random.default_rng(key).normal(size=shape)
    xi = np.asarray(jax.vmap(net.body_velocity)(mu_true.reshape(-1, 3))).reshape(shape)
    mu = np.asarray(learn.latent_momenta(net, xi))
    want = np.asarray(former_latent_momenta(net, xi))
    assert mu.shape == shape
    # the same Newton steps, stopped once a step is at round-off (the loop took 20): both solve
    # grad H(mu) = xi to a rounding, so they differ by a few roundings of mu times the
    # condition number of the Hessian (measured: up to 2.9 eps cond |mu|, 54 samples of three
    # networks at momenta of size 0.3-3)
    flat, ref = mu.reshape(-1, 3), want.reshape(-1, 3)
    cond = np.linalg.cond(np.asarray(jax.vmap(jax.jacfwd(net.body_velocity))(jnp.asarray(ref))))
    assert np.all(np.max(np.abs(flat - ref), axis=1) <= 16 * EPS * cond * np.max(np.abs(ref), axis=1))
    residual = np.asarray(jax.vmap(net.body_velocity)(jnp.asarray(flat))) - xi.reshape(-1, 3)
    assert np.max(np.abs(residual)) <= 4 * EPS * np.max(np.abs(xi))


class Quadratic(eqx.Module):
    r"""$\widetilde H(\mu) = \tfrac12\mu^\top A\mu$, the body velocity $A\mu$."""

    A: jax.Array
    system: lp.systems.AbstractPoissonSystem = BODY
    h: float | None = None

    def body_velocity(self, y):
        return self.A @ y


def test_latent_momenta_of_a_quadratic_hamiltonian_take_one_newton_step():
    A = np.array([[1.0, 0.2, 0.0], [0.2, 0.5, 0.1], [0.0, 0.1, 1 / 3]])
    xi = np.random.default_rng(2).normal(size=(4, 3))
    one = np.asarray(learn.latent_momenta(Quadratic(jnp.asarray(A)), xi, iterations=1))
    # one step from 0 solves A mu = xi (by a pseudo-inverse: a few roundings times cond(A) ~ 6)
    want = np.linalg.solve(A, xi.T).T
    np.testing.assert_allclose(one, want, rtol=0, atol=64 * EPS * np.max(np.abs(want)))
    # the default stops once a step is at round-off (here the second) and agrees
    default = np.asarray(learn.latent_momenta(Quadratic(jnp.asarray(A)), xi))
    np.testing.assert_allclose(default, one, rtol=0, atol=16 * EPS * np.max(np.abs(want)))


def test_latent_momenta_compiles_once_per_model_structure():
    xi = np.random.default_rng(3).normal(size=3)
    first = learn.latent_momenta(learn.GLPNet(BODY, n_modules=3, key=0, h=H), xi)
    # other weights, another step size (or none), another iteration count, other velocities:
    # the same program, and no small one compiled on the way
    with compilations() as seen:
        for key, h, iterations in [(1, 0.2, 20), (2, 0.05, 7), (0, None, 1)]:
            learn.latent_momenta(learn.GLPNet(BODY, n_modules=3, key=key, h=h), xi + key, iterations=iterations)
        again = learn.latent_momenta(learn.GLPNet(BODY, n_modules=3, key=0, h=H), xi)
    assert seen["traces"] == 0
    np.testing.assert_array_equal(np.asarray(again), np.asarray(first))


@pytest.mark.parametrize("iterations", [0, -1])
def test_latent_momenta_refuses_fewer_than_one_iteration(iterations):
    net = learn.GLPNet(BODY, n_modules=3, key=0, h=H)
    with pytest.raises(ValueError, match=rf"iterations must be an integer >= 1; got {iterations}"):
        learn.latent_momenta(net, np.ones(3), iterations=iterations)


# -- rollouts ------------------------------------------------------------------------------------
MAPS = {
    "Strang": lambda: splitting.Strang(BODY, h=H),
    "GLPNet": lambda: learn.GLPNet(BODY, n_modules=3, key=0, h=H),
}
# lengths within one piece of 128 saved states, at its end and past it (two and three pieces)
LENGTHS = [(0, 1), (5, 1), (128, 1), (129, 1), (300, 1), (390, 3)]


@pytest.mark.parametrize("name", slow_except(list(MAPS), {"Strang"}))
def test_rollout_is_bit_identical_to_one_scan(name):
    m = MAPS[name]()
    y0, _ = starts(4)
    for n_steps, save_every in LENGTHS:
        got = m.rollout(y0, n_steps, save_every=save_every)
        assert isinstance(got, jax.Array) and got.shape == (4, n_steps // save_every + 1, 3)
        np.testing.assert_array_equal(np.asarray(got), np.asarray(old_rollout(m, y0, n_steps, save_every)))
    single = m.rollout(y0[1], 129, save_every=3)
    assert single.shape == (44, 3)
    np.testing.assert_array_equal(np.asarray(single), np.asarray(old_rollout(m, y0[1], 129, 3)))


@pytest.mark.slow  # the default run's time: the uncarried rollout's bit-identity by default
def test_rollout_of_a_carried_state_is_bit_identical_to_one_scan():
    # the isospectral midpoint carries its matrix W (and a predictor's history) between steps:
    # the carry is made by a program of its own, then handed from piece to piece
    system = lp.systems.GeneralizedRigidBody((1.0, 1.2, 1.7, 2.0, 3.1))
    m = it.IsospectralMidpoint(system, 0.05)
    y0 = np.random.default_rng(4).normal(size=(2, system.dim))
    for n_steps, save_every in [(5, 1), (260, 2)]:
        np.testing.assert_array_equal(np.asarray(m.rollout(y0, n_steps, save_every=save_every)),
                                      np.asarray(old_rollout(m, y0, n_steps, save_every)))


@pytest.mark.slow  # the default run's time; one compilation for every length of lifted rollouts by default
@pytest.mark.parametrize("name", list(MAPS))
def test_lifted_rollout_is_bit_identical_to_one_scan(name):
    m = MAPS[name]()
    y0, g0 = starts(3, seed=1)
    for n_steps, save_every in [(0, 1), (7, 1), (129, 1), (260, 2)]:
        gs, ys = m.lifted_rollout(g0, y0, n_steps, save_every=save_every)
        ref_g, ref_y = former_lifted_compiled(traced_h(m), jnp.asarray(g0), jnp.asarray(y0), n_steps // save_every,
                                           save_every)
        np.testing.assert_array_equal(np.asarray(gs), np.asarray(ref_g))
        np.testing.assert_array_equal(np.asarray(ys), np.asarray(ref_y))
    g, y = m.lifted_rollout(g0[0], y0[0], 10)
    assert g.shape == (11, 4) and y.shape == (11, 3)


def test_fifty_rollouts_of_fifty_lengths_compile_once():
    m = Counted(splitting.Strang(BODY, h=H))
    y0, g0 = starts(5, seed=2)
    lengths = np.random.default_rng(0).permutation(np.arange(3, 403, 8))[:50]
    # the counters see a recompilation: the former rollout compiles once per length
    TRACES["step"] = 0
    with compilations() as seen:
        for n in lengths[:2]:
            old_rollout(m, y0, int(n))
    assert TRACES["step"] == 2 and seen["traces"] >= 2
    TRACES["step"] = 0
    m.rollout(y0, int(lengths[0]))
    with compilations() as seen:
        for n in lengths[1:]:
            m.rollout(y0, int(n))
    assert TRACES["step"] == 1  # one program for the 50 lengths
    assert seen["traces"] == 0  # and nothing else compiled per length (no small eager programs)
    TRACES["step"] = 0
    m.lifted_rollout(g0, y0, 2 * int(lengths[0]), save_every=2)
    with compilations() as seen:
        for n in lengths[1:]:
            m.lifted_rollout(g0, y0, 2 * int(n), save_every=int(n))  # any spacing: the same program
    assert TRACES["step"] == 1 and seen["traces"] == 0


@pytest.mark.parametrize("save_every", [1, 3])
def test_a_diverging_rollout_returns_and_raises_as_before(save_every):
    m = it.RK4(BODY, h=20.0)  # far beyond RK4's stability region: overflows within 60 steps
    y0 = np.array([[1e-3, 2e-3, 1e-3], [1.0, 0.5, 0.2]])
    old = np.asarray(old_rollout(m, y0, 300, save_every))  # three pieces, non-finite from the first
    np.testing.assert_array_equal(np.asarray(m.rollout(y0, 300, save_every=save_every, nonfinite="return")), old)
    finite = np.isfinite(old).all(axis=-1)
    first = np.where(finite.all(axis=1), old.shape[1], np.argmin(finite, axis=1))
    with pytest.raises(it.RolloutDivergedError) as error:
        m.rollout(y0, 300, save_every=save_every)
    assert error.value.trajectory == int(np.argmin(first))
    assert error.value.step == int(np.min(first)) * save_every
