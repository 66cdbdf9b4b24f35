"""Classical splitting: observed order against heyoka, Casimirs to round-off, shapes, validation."""

import equinox as eqx
import jax
import numpy as np
import pytest

import integrators as it
import liepoisson as lp
from integrators import splitting

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
PI0 = np.array([1 / np.sqrt(2), -1 / np.sqrt(2), 1.0])
PENDULUM = lp.systems.ExtendedPendulum()

# Step counts over t in [0, 1] in the asymptotic regime, errors well above round-off
# (Yoshida6 is accurate to ~1e-14 already at h = 1/32, so it gets larger steps).
STEPS = {1: (16, 32, 64, 128), 2: (8, 16, 32, 64), 4: (4, 8, 16, 32), 6: (2, 3, 4, 6)}
CASES = [(m, BODY, PI0) for m in splitting.METHODS if m is not splitting.BlanesMoan4] + [
    (m, PENDULUM, np.array([0.0, 1.0, 1.0])) for m in (splitting.Strang, splitting.BlanesMoan4)
]


def _flows_per_step(method) -> int:
    """Exact sub-flows of one step, counted from the methods' definitions (not their code)."""
    n = len(method.system.hamiltonian_splitting())
    if isinstance(method.method, splitting.LieTrotter):
        return n
    if isinstance(method.method, splitting.BlanesMoan4):
        return len(method.method.a) + len(method.method.b)
    strang = 2 * n - 1
    if isinstance(method.method, splitting.AbstractCompositionMethod):
        return strang * len(method.method.coefficients)
    return strang


# The step map as a pytree argument: h is traced, so one compilation serves every step size.
_jitted_step = jax.jit(lambda method, y: method.step(y))


@pytest.mark.parametrize("cls, system, y0", CASES, ids=lambda v: getattr(v, "__name__", type(v).__name__))
def test_observed_order(cls, system, y0):
    steps = STEPS[cls.order]
    ref = it.ground_truth(system, y0, h=1.0, n_steps=1).states[0, -1]
    errors = []
    for n in steps:  # `step` compiles once for all h (rollout would recompile per n_steps)
        method = cls(system, h=1.0 / n)
        y = y0
        for _ in range(n):
            y = _jitted_step(method, y)
        errors.append(np.linalg.norm(np.asarray(y) - ref))
    slope = np.polyfit(np.log(steps), -np.log(errors), 1)[0]
    assert abs(slope - cls.order) < 0.1, (errors, slope)


# Strang and one composition of Strang steps (TripleJump) by default; the other compositions of the
# same Strang steps and Lie-Trotter with -m slow
_COMPOSED = (splitting.Suzuki, splitting.McLachlan4, splitting.Yoshida6)


@pytest.mark.parametrize("cls", [pytest.param(m, marks=pytest.mark.slow) if m is splitting.LieTrotter or m in _COMPOSED
                                 else m for m in splitting.METHODS if m is not splitting.BlanesMoan4])
def test_casimir_round_off_over_1e4_steps(cls):
    method = cls(BODY, h=0.1)
    n_steps = 10_000
    ys = np.asarray(method.rollout(PI0, n_steps))
    C = np.asarray(BODY.casimirs(ys))[:, 0]
    drift = np.max(np.abs(C - C[0])) / C[0]
    # Each exact sub-flow is a rotation that changes |Pi|^2 by a few eps (relative); those
    # errors add like a random walk, sqrt(n_flows); its maximum over time stays within a few
    # standard deviations: 10 sqrt(n_flows) eps.
    n_flows = n_steps * _flows_per_step(method)
    assert drift < 10 * np.sqrt(n_flows) * EPS, drift


@pytest.mark.slow  # by default BlanesMoan4's order above and the pendulum's Casimir over composed test flows (test_casimirs.py)
def test_blanes_moan_casimir_round_off():
    ys = np.asarray(splitting.BlanesMoan4(PENDULUM, h=0.1).rollout([0.0, 1.5, 2.35], 10_000))
    C = np.asarray(PENDULUM.casimirs(ys))[:, 0]
    scale = np.max(np.abs(ys[:, 2]))  # C = r - u^2 - v^2 cancels terms of size |r|
    assert np.max(np.abs(C - C[0])) < 10 * np.sqrt(13e4) * EPS * scale


@pytest.mark.parametrize(
    "system",
    [pytest.param(lp.systems.HeavyTop(), marks=pytest.mark.slow), lp.systems.Kirchhoff(), lp.systems.ChargedParticle()],
    ids=lambda s: s.name,
)
def test_other_systems_strang_close_to_ground_truth(system):
    y0 = {"HeavyTop": [0.3, -0.2, 0.5, 0.1, 0.6, 0.79], "Kirchhoff": [1, 1, 1, -1, 1, 2], "ChargedParticle": [1, 0.5, 0.5, 1]}[system.name]
    ref = it.ground_truth(system, y0, 0.01, 100).states[0]
    ys = np.asarray(splitting.Strang(system, h=0.01).rollout(y0, 100))
    np.testing.assert_allclose(ys, ref, atol=1e-4)  # Strang: O(h^2) over t = 1


@pytest.mark.slow
def test_shapes_and_batching():
    method = splitting.Strang(BODY, h=0.1)
    y0s = PI0 + np.random.default_rng(0).uniform(-0.1, 0.1, (5, 3))
    many = method.rollout(y0s, 7)
    assert many.shape == (5, 8, 3) and many.dtype == np.float64
    one = method.rollout(y0s[2], 7)
    assert one.shape == (8, 3)
    np.testing.assert_allclose(many[2], one, rtol=0, atol=4 * EPS)
    np.testing.assert_array_equal(many[:, 0], y0s)
    # `step` takes one state; many states go through jax.vmap
    np.testing.assert_allclose(jax.vmap(method.step)(y0s), many[:, 1], rtol=0, atol=4 * EPS)
    assert method.step(PI0).shape == (3,)


def test_strang_is_symmetric():
    method = splitting.Strang(BODY, h=0.3)
    # Phi_{-h} o Phi_h = id: step backwards by flowing the pieces for negative time (the
    # constructor takes h > 0 only; tree_at builds the same method with h = -0.3)
    backwards = eqx.tree_at(lambda m: m.h, method, -0.3)
    y1 = np.asarray(method.step(PI0))
    back = np.asarray(backwards.step(y1))
    np.testing.assert_allclose(back, PI0, rtol=0, atol=8 * EPS)


def test_blanes_moan_needs_two_terms():
    with pytest.raises(ValueError, match=r"RigidBody.*3 pieces"):
        splitting.BlanesMoan4(BODY, h=0.1)


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"h": 0.0}, ValueError, ["h", "> 0", "0.0"]),
        ({"h": -1.0}, ValueError, ["h", "-1.0"]),
        ({"h": "0.1"}, TypeError, ["h", "str"]),
        ({"n_steps": -1}, ValueError, ["n_steps", "-1"]),
        ({"n_steps": 1.5}, TypeError, ["n_steps", "1.5"]),
        ({"save_every": 2}, ValueError, ["save_every", "divide", "3"]),
        ({"save_every": 0}, ValueError, ["save_every", "0"]),
        ({"y0": [np.nan, 0, 1]}, ValueError, ["y0", "finite"]),
        ({"y0": [1.0, 2.0]}, ValueError, ["y0", "(2,)"]),
    ],
)
def test_validation(kwargs, error, words):
    args = {"y0": PI0, "h": 0.1, "n_steps": 3} | kwargs
    with pytest.raises(error) as info:
        h = args.pop("h")
        splitting.Strang(BODY, h=h).rollout(**args)
    for w in words:
        assert w in str(info.value)


def test_n_steps_zero_is_the_initial_state():
    np.testing.assert_array_equal(splitting.Strang(BODY, h=0.1).rollout(PI0, 0), PI0[None])


def test_system_type_checked():
    with pytest.raises(TypeError, match="system"):
        splitting.Strang("RigidBody", h=0.1)


# the compositions of Strang steps beyond TripleJump with -m slow (they compose Strang's rule)
@pytest.mark.parametrize("cls", [pytest.param(m, marks=pytest.mark.slow) if m in _COMPOSED else m for m in splitting.METHODS],
                         ids=lambda m: m.__name__)
def test_a_method_composes_listed_and_indexed_flows_alike_in_its_ordering(cls):
    # One rule for both kinds of flows: a Python loop over separate functions (FlowList) and a
    # scan over one function of a traced index (IndexedFlows) apply the same flows at the
    # same times; `ordering` permutes them, as a list permuted by hand does. The flows do not
    # commute (an Euler step of a nonlinear field that depends on k), so a wrong order shows.
    import functools

    import jax.numpy as jnp

    def flow(k, t, y):
        return y + t * jnp.sin(y * (k + 1.0) + k)

    n = 2 if cls is splitting.BlanesMoan4 else 3
    p = (1, 0) if n == 2 else (2, 0, 1)
    listed = [functools.partial(flow, k) for k in range(n)]
    y, h = jnp.asarray([0.3, -0.8, 0.5]), 0.1
    by_hand = cls().compose([listed[k] for k in p], y, h)
    for flows in (listed, splitting.FlowList(listed), splitting.IndexedFlows(flow, n)):
        # a few roundings per flow where XLA fuses the scanned and the unrolled code differently
        np.testing.assert_allclose(np.asarray(cls(ordering=p).compose(flows, y, h)), np.asarray(by_hand),
                                   rtol=0, atol=8 * cls().flows_per_step(n) * EPS)
    assert np.abs(np.asarray(cls().compose(listed, y, h)) - np.asarray(by_hand)).max() > 1e-6
    assert cls(ordering=p) != cls() and cls(ordering=p) == cls(ordering=list(p))
    with pytest.raises(ValueError, match=rf"ordering must be a permutation of range\({n + 1}\)"):
        cls(ordering=p).compose(listed + [listed[0]], y, h)
