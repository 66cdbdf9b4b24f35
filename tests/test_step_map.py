"""integrators.AbstractStepMap: one interface for every classical splitting method and every
learned map (`step` on one state, the shared `rollout`, `poisson_defect`, `cost`)."""

import functools
import re
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import pytest
from helpers import slow_except, system

import integrators
import learn
import liepoisson as lp
from integrators import splitting
from integrators.splitting import IndexedFlows

EPS = np.finfo(np.float64).eps
H = 0.1
ROOT = Path(__file__).resolve().parents[1]

SPLITTING = [cls.__name__ for cls in splitting.METHODS]
LEARNED = ["LPNet", "GLPNet", "MLPBaseline"]
# every splitting method on the rigid body (three pieces), BlanesMoan4 on the extended
# pendulum (it needs two), and Strang on the pendulum too (a system that is not Lie-Poisson)
MAPS = SPLITTING + ["Strang/ExtendedPendulum"] + LEARNED
POISSON = [name for name in MAPS if name not in ("LPNet", "MLPBaseline")]
# The compositions take 3-20 s each to compile and go through the same shared rollout as
# Strang; by default their compiled checks run with -m slow (their orders and Casimir
# conservation are tested by default in test_integrators_splitting.py).
HEAVY = {"TripleJump", "Suzuki", "McLachlan4", "Yoshida6", "BlanesMoan4"}


def compiled(names):
    return [pytest.param(n, marks=pytest.mark.slow) if n in HEAVY else n for n in names]


# The rollout is one shared function: by default Strang and the two learned maps with a network
# (LPNet, G-LPNet); Lie-Trotter, the pendulum's Strang and the baseline with -m slow (the pendulum's
# compiled step by default in test_poisson_defect_at_round_off).
ROLLED_OUT = slow_except(MAPS, {"Strang", "LPNet", "GLPNet"})

# Exact sub-flows per step, from the methods' definitions: N pieces, Strang 2N - 1 flows,
# a composition of s Strang steps s (2N - 1), Blanes-Moan's PRK_6 7 + 6; one test flow per
# LPNet step, one per G-LPNet module, none for the baseline.
EXACT_FLOWS = {
    "LieTrotter": 3, "Strang": 5, "TripleJump": 3 * 5, "Suzuki": 5 * 5, "McLachlan4": 5 * 5,
    "Yoshida6": 7 * 5, "BlanesMoan4": 13, "Strang/ExtendedPendulum": 3,
    "LPNet": 1, "GLPNet": 4, "MLPBaseline": 0,
}


@functools.cache
def step_map(name: str) -> integrators.AbstractStepMap:
    """The map called `name`, built once (its compiled rollout is cached with it)."""
    body = system("RigidBody")
    if name == "BlanesMoan4":
        return splitting.BlanesMoan4(system("ExtendedPendulum"), h=H)
    if name == "Strang/ExtendedPendulum":
        return splitting.Strang(system("ExtendedPendulum"), h=H)
    if name in SPLITTING:
        return getattr(splitting, name)(body, h=H)
    return untrained(name, h=H)


def untrained(name: str, h):
    body = system("RigidBody")
    if name == "LPNet":
        return learn.LPNet(body, hidden=(8,), key=0, h=h)
    if name == "GLPNet":
        return learn.GLPNet(body, n_modules=4, key=0, h=h)
    return learn.MLPBaseline(body, hidden=(8,), key=0, h=h)


@functools.cache
def jitted_step(name: str):
    # eqx.filter_jit: jax.jit needs a hashable function, and the bound method of a map with
    # array leaves (a network's weights) is not
    return eqx.filter_jit(step_map(name).step)


def initial_states(m: integrators.AbstractStepMap) -> tuple[np.ndarray, np.ndarray]:
    """One initial state and four near it."""
    if m.system.name == "ExtendedPendulum":
        y0 = np.array([0.0, 1.0, 1.0])
    else:
        y0 = np.array([1 / np.sqrt(2), -1 / np.sqrt(2), 1.0])
    return y0, y0 + np.random.default_rng(0).uniform(-0.1, 0.1, (4, 3))


def by_hand(name: str, y0: np.ndarray, n_steps: int) -> np.ndarray:
    """`(n_steps + 1, dim)`: the jitted step iterated in Python."""
    step = jitted_step(name)
    ys = [np.asarray(y0)]
    for _ in range(n_steps):
        ys.append(np.asarray(step(ys[-1])))
    return np.stack(ys)


@pytest.mark.parametrize("name", MAPS)
def test_every_map_is_a_step_map(name):
    m = step_map(name)
    assert isinstance(m, integrators.AbstractStepMap)
    assert m.h == H


N_STEPS = 12


@functools.cache
def rollouts(name: str) -> tuple[np.ndarray, np.ndarray]:
    """`rollout` of one and of many initial states over N_STEPS, compiled once per map."""
    m = step_map(name)
    y0, many = initial_states(m)
    return np.asarray(m.rollout(y0, N_STEPS)), np.asarray(m.rollout(many, N_STEPS))


@pytest.mark.parametrize("name", ROLLED_OUT)
def test_rollout_agrees_with_the_step_iterated_by_hand(name):
    y0, many = initial_states(step_map(name))
    one, batch = rollouts(name)
    n = N_STEPS
    assert one.shape == (n + 1, 3) and batch.shape == (4, n + 1, 3)
    assert np.array_equal(one[0], y0) and np.array_equal(batch[:, 0], many)
    ref_one = by_hand(name, y0, n)
    ref_batch = np.stack([by_hand(name, y, n) for y in many])
    # The rollout is a scan over the vmapped step: XLA may order the sums of a network's
    # matrix products differently (matrix-matrix instead of matrix-vector), a few ulps of |y|
    # per step, carried along n steps (measured: at most 8 ulps after 20 steps).
    tol = 4 * n * EPS * max(np.max(np.abs(ref_one)), np.max(np.abs(ref_batch)))
    np.testing.assert_allclose(one, ref_one, rtol=0, atol=tol)
    np.testing.assert_allclose(batch, ref_batch, rtol=0, atol=tol)


@pytest.mark.parametrize("name", ROLLED_OUT)
def test_save_every_keeps_every_kth_state_exactly(name):
    m = step_map(name)
    y0, many = initial_states(m)
    one, batch = rollouts(name)
    np.testing.assert_array_equal(np.asarray(m.rollout(y0, N_STEPS, save_every=3)), one[::3])
    np.testing.assert_array_equal(np.asarray(m.rollout(many, N_STEPS, save_every=4)), batch[:, ::4])


@pytest.mark.parametrize("name", MAPS)
@pytest.mark.parametrize(
    "args, kwargs, error, words",
    [
        ((np.ones(3), 10), {"save_every": 3}, ValueError, ["save_every", "divide", "10", "3"]),
        ((np.ones(3), 10), {"save_every": 0}, ValueError, ["save_every", ">= 1", "0"]),
        ((np.ones(3), -1), {}, ValueError, ["n_steps", ">= 0", "-1"]),
        ((np.ones(3), 2.5), {}, TypeError, ["n_steps", "2.5"]),
        ((np.ones(4), 3), {}, ValueError, ["y0", "(4,)"]),
        ((np.ones((2, 2, 3)), 3), {}, ValueError, ["y0", "(n_traj, 3)", "(2, 2, 3)"]),
        ((np.array([1.0, np.inf, 0.0]), 3), {}, ValueError, ["y0", "finite", "inf"]),
        ((np.array([[1.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]), 3), {}, ValueError, ["y0", "finite", "(1, 0)"]),
        (("y0", 3), {}, TypeError, ["y0", "str"]),
    ],
)
def test_rollout_rejects_bad_arguments(name, args, kwargs, error, words):
    with pytest.raises(error) as info:
        step_map(name).rollout(*args, **kwargs)
    for w in words:
        assert w in str(info.value)


@pytest.mark.parametrize("name", LEARNED)
def test_a_learned_map_without_h_cannot_step_forward(name):
    m = untrained(name, h=None)
    for call in (lambda: m.rollout(np.ones(3), 3), lambda: m.poisson_defect(np.ones(3)), m.cost):
        with pytest.raises(ValueError, match="no step size h"):
            call()


@pytest.mark.parametrize("name", compiled(MAPS))  # the compositions' steps: -m slow
def test_step_takes_one_state(name):
    m = step_map(name)
    y0, many = initial_states(m)
    assert m.step(y0).shape == (3,)
    with pytest.raises(ValueError, match=r"one state of shape \(3,\); got shape \(4, 3\)"):
        m.step(many)
    with pytest.raises(ValueError, match="y"):
        m.step(np.ones(4))


def test_poisson_defect_shapes():
    m = step_map("Strang")
    y = np.random.default_rng(1).uniform(-2, 2, (2, 8, 3))
    assert np.asarray(m.poisson_defect(y)).shape == (2, 8)
    assert np.asarray(m.poisson_defect(y[0, 0])).shape == ()
    with pytest.raises(ValueError, match=r"y must have shape \(\.\.\., 3\)"):
        m.poisson_defect(np.ones(4))


# Compiling the Jacobian of BlanesMoan4's 13 pendulum flows takes 10-20 s: slow run only
# (the pendulum's defect is checked by default through Strang); Lie-Trotter's with -m slow too
@pytest.mark.parametrize(
    "name", slow_except(POISSON, {"Strang", "Strang/ExtendedPendulum", "GLPNet"})
)
def test_poisson_defect_at_round_off(name):
    m = step_map(name)
    y = np.random.default_rng(1).uniform(-2, 2, (16, 3))
    defect = np.asarray(m.poisson_defect(y))
    # J B J^T - B(Phi(y)): every exact sub-flow adds a few ulps to J, in entries of size |B|
    # ~ 2 |y| (measured: at most 5 ulps of 1)
    scale = 2 * np.max(np.abs(y))
    assert np.max(defect) < 8 * EXACT_FLOWS[name] * EPS * scale, defect


@pytest.mark.parametrize("name", ["LPNet", pytest.param("MLPBaseline", marks=pytest.mark.slow)])  # the baseline's drift: test_learn_training.py
def test_poisson_defect_of_an_unstructured_step(name):
    y = np.random.default_rng(1).uniform(-2, 2, (16, 3))
    defect = np.asarray(step_map(name).poisson_defect(y))
    # the LPNet's parameters depend on the point and the baseline has no structure: neither
    # is a Poisson map (measured: min 1e-4 and 1e-2 for these weights)
    assert np.min(defect) > 1e-6
    if name == "MLPBaseline":
        assert np.min(defect) > 1e-3


# by default Strang and every learned map; Lie-Trotter and the pendulum's Strang with -m slow
@pytest.mark.parametrize("name", slow_except(MAPS, {"Strang", "LPNet", "GLPNet", "MLPBaseline"}))
def test_cost_counts_the_exact_sub_flows(name, monkeypatch):
    m = step_map(name)
    cost = m.cost()
    assert isinstance(cost, integrators.StepCost)
    assert cost.exact_flows == m.exact_flows_per_step == EXACT_FLOWS[name]
    assert np.isfinite(cost.flops) and cost.flops > 0
    # and that is how many exact flows one step evaluates: count them while it runs (every
    # exact sub-flow of the library is a test flow of the system)
    calls = []
    test_flow = lp.systems.AbstractPoissonSystem.test_flow

    def counting(self, alpha, t, y):
        calls.append(1)
        return test_flow(self, alpha, t, y)

    monkeypatch.setattr(lp.systems.AbstractPoissonSystem, "test_flow", counting)
    y = initial_states(m)[0]
    # a composition scans over its Strang steps (one traced for all): without jit, jax.lax.scan
    # runs its body once per step, so every exact flow is counted
    with jax.disable_jit():
        if isinstance(getattr(m, "flows", lambda: None)(), IndexedFlows):
            # a G-LPNet scans over its modules (one flow traced for all): count the flows of the
            # same composition unrolled, which its step equals (tests/test_least_squares.py)
            m.method.compose(list(m.flows()), y, m.h)
        else:
            m.step(y)
    assert len(calls) == EXACT_FLOWS[name]


def test_one_rollout_in_the_library():
    """`grep -rn "def rollout("` over the packages finds the one shared definition."""
    hits = []
    for package in ("liepoisson", "integrators", "learn", "paper"):
        for path in sorted((ROOT / package).rglob("*")):
            if not path.is_file() or "__pycache__" in path.parts:
                continue
            try:
                text = path.read_text()
            except UnicodeDecodeError:  # data files
                continue
            for number, line in enumerate(text.splitlines(), 1):
                if "def rollout(" in line:
                    hits.append(f"{path.relative_to(ROOT)}:{number}")
    assert len(hits) == 1 and re.fullmatch(r"integrators/_step_map\.py:\d+", hits[0]), hits
