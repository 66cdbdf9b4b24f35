"""RK4 and the implicit midpoint rule as step maps, and the orderings of a splitting: orders
against heyoka, what each conserves, and their input checks."""

import functools

import numpy as np
import pytest
from helpers import system

import integrators as it

EPS = np.finfo(np.float64).eps
PI0 = np.array([1 / np.sqrt(2), -1 / np.sqrt(2), 1.0])
T = 10.0
STEPS = (50, 100, 200, 400)


@functools.cache
def reference():
    """heyoka at tolerance eps: its error (~1e-14) is far below the smallest error fitted."""
    return it.ground_truth(system("RigidBody"), PI0, h=T / 10, n_steps=10).states[0, -1]


def observed_order(make) -> float:
    # save_every=n: the state at T only, by one compiled rollout for every n
    errors = [np.linalg.norm(np.asarray(make(T / n).rollout(PI0, n, save_every=n))[-1] - reference()) for n in STEPS]
    return -np.polyfit(np.log(STEPS), np.log(errors), 1)[0]


@pytest.mark.parametrize("method, order", [(it.RK4, 4), (it.ImplicitMidpoint, 2)])
def test_order_against_heyoka(method, order):
    body = system("RigidBody")
    assert isinstance(method(body, h=0.1), it.AbstractStepMap)
    # A log-log fit over h = 0.2 .. 0.025: within 0.1 of the theoretical order.
    assert abs(observed_order(lambda h: method(body, h=h)) - order) < 0.1


@pytest.mark.slow
def test_implicit_midpoint_conserves_quadratic_invariants_but_is_not_poisson():
    body = system("RigidBody")
    m = it.ImplicitMidpoint(body, h=0.1)
    y = np.asarray(m.rollout(PI0, 2000))
    report = it.diagnostics(y, body)
    # |Pi|^2 and the quadratic energy are conserved up to the Newton solve and the roundings
    # of each step: a random walk of ~eps per step over 2000 steps stays below 1e3 eps.
    assert report.max_casimir_drift_relative < 1e3 * EPS
    assert report.max_energy_error < 1e3 * EPS
    # Not a Poisson map of the Lie-Poisson bracket: the defect is O(h^3), far above round-off.
    assert float(np.max(m.poisson_defect(y[:20]))) > 1e-7
    rk4 = it.RK4(body, h=0.1)
    assert it.diagnostics(np.asarray(rk4.rollout(PI0, 2000)), body).max_casimir_drift_relative > 1e-9


@pytest.mark.parametrize("ordering", [(2, 0, 1), pytest.param((1, 2, 0), marks=pytest.mark.slow)])
def test_every_ordering_has_order_two(ordering):
    body = system("RigidBody")
    assert abs(observed_order(lambda h: it.splitting.Strang(body, h=h, ordering=ordering)) - 2) < 0.1


@pytest.mark.slow  # two 2000-step rollouts; an ordering's order by default above
def test_orderings_of_the_rigid_body_splitting():
    body = system("RigidBody")
    energy = []
    # Each ordering is its own compiled rollout: the two extremes of the six (measured over
    # 2000 steps: 3.6e-5 for (0, 1, 2), 7.1e-5 for (0, 2, 1) and (1, 2, 0), 3.6e-4 for
    # (1, 0, 2) and (2, 1, 0), 4.8e-4 for (2, 0, 1)).
    for p in [(0, 1, 2), (2, 0, 1)]:
        y = np.asarray(it.splitting.Strang(body, h=0.1, ordering=p).rollout(PI0, 2000))
        energy.append(it.diagnostics(y, body).max_energy_error)
    # The orderings are different methods (Fasso 2003): their energy errors differ by a factor
    # of ~13 here.
    assert max(energy) / min(energy) > 5
    assert it.splitting.Strang(body, h=0.1).ordering == (0, 1, 2)


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"h": 0.0}, ValueError, ["h", "> 0"]),
        ({"h": -0.1}, ValueError, ["h"]),
        ({"h": "0.1"}, TypeError, ["h"]),
    ],
)
def test_runge_kutta_arguments(kwargs, error, words):
    for method in (it.RK4, it.ImplicitMidpoint):
        with pytest.raises(error) as info:
            method(system("RigidBody"), **kwargs)
        assert all(w in str(info.value) for w in words)
    with pytest.raises(TypeError, match="system"):
        it.RK4("rigid body", h=0.1)
    with pytest.raises(ValueError, match="iterations"):
        it.ImplicitMidpoint(system("RigidBody"), h=0.1, iterations=0)


@pytest.mark.parametrize("ordering, error", [((0, 1), ValueError), ((0, 1, 1), ValueError), ("abc", TypeError)])
def test_ordering_must_be_a_permutation(ordering, error):
    with pytest.raises(error, match="ordering"):
        it.splitting.Strang(system("RigidBody"), h=0.1, ordering=ordering)
