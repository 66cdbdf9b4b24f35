"""Bad input to `learn.quadratic_part`, `DoubleBracket`, `compare`/`convergence` and the size of
rollouts and ground truth: a clear error naming the argument, or the right result (issue 40)."""

import os
import warnings

import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp
import liepoisson._memory
from liepoisson.systems import DoubleBracket, damped_rigid_body

INERTIA = (2.0, 1.0, 2.0 / 3.0)
BODY = lp.systems.RigidBody(INERTIA)
INVERSE = 1.0 / np.asarray(INERTIA)


def _on_the_unit_sphere(n, seed=0):
    y = np.random.default_rng(seed).normal(size=(n, 3))
    return y / np.linalg.norm(y, axis=1, keepdims=True)


# -- quadratic_part ------------------------------------------------------------------------------
def test_quadratic_part_checks_the_hamiltonian_and_the_system():
    samples = _on_the_unit_sphere(30)
    with pytest.raises(TypeError, match=r"hamiltonian must be a function of states .* got float 3\.0"):
        learn.quadratic_part(3.0, BODY, samples)
    with pytest.raises(TypeError, match=r"system must be a liepoisson\.systems\.AbstractPoissonSystem .* got str "
                                        r"'RigidBody'"):
        learn.quadratic_part(BODY.hamiltonian, "RigidBody", samples)


def test_quadratic_part_refuses_only_what_the_casimirs_do_not_explain():
    one_state = np.tile(_on_the_unit_sphere(1), (20, 1))
    with pytest.raises(ValueError, match=r"samples do not determine a quadratic in 3 variables \(10 coefficients\): "
                                         r"the rank of their quadratic features is 1 .* Casimirs explain only 1 .* "
                                         r"rank at least 9"):
        learn.quadratic_part(BODY.hamiltonian, BODY, one_state)
    # One trajectory: on one Casimir leaf and one energy level, two quadrics; the energy's is
    # not the Casimirs' (A + t D fits as well as A for any t).
    trajectory = it.ground_truth(BODY, _on_the_unit_sphere(1, seed=3), 0.1, 60).states[0]
    with pytest.raises(ValueError, match=r"the rank of their quadratic features is 8 .* explain only 1 of them"):
        learn.quadratic_part(BODY.hamiltonian, BODY, trajectory)
    # Samples on one Casimir leaf are fine: |Pi| = 1 is a linear relation between the y_i^2
    # features and the constant, which the Casimir explains; the identifiable part is that of
    # samples off the leaf.
    on_leaf = learn.quadratic_part(BODY.hamiltonian, BODY, _on_the_unit_sphere(40))
    spread = learn.quadratic_part(BODY.hamiltonian, BODY, np.random.default_rng(1).normal(size=(40, 3)))
    true = np.diag(INVERSE) - np.mean(INVERSE) * np.eye(3)
    np.testing.assert_allclose(on_leaf.identifiable(), true, rtol=0, atol=1e-13)
    np.testing.assert_allclose(spread.identifiable(), true, rtol=0, atol=1e-13)
    i, j = np.triu_indices(3, 1)
    np.testing.assert_allclose(on_leaf.diagonal_differences(), INVERSE[i] - INVERSE[j], rtol=0, atol=1e-13)
    np.testing.assert_allclose(on_leaf.linear, 0.0, rtol=0, atol=1e-13)
    assert on_leaf.residual < 1e-12
    # The heavy top on one leaf of both its Casimirs (|Gamma| = 1, Pi . Gamma = 0.3).
    top = lp.systems.HeavyTop()
    y = np.random.default_rng(2).normal(size=(80, 6))
    gamma = y[:, 3:] / np.linalg.norm(y[:, 3:], axis=1, keepdims=True)
    y[:, 3:] = gamma
    y[:, :3] += (0.3 - np.sum(y[:, :3] * gamma, axis=1))[:, None] * gamma
    leaf = learn.quadratic_part(top.hamiltonian, top, y)
    everywhere = learn.quadratic_part(top.hamiltonian, top, np.random.default_rng(3).normal(size=(80, 6)))
    np.testing.assert_allclose(leaf.identifiable(), everywhere.identifiable(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(leaf.linear, everywhere.linear, rtol=0, atol=1e-12)


def test_quadratic_part_names_the_samples_when_they_are_not_finite():
    samples = np.random.default_rng(4).normal(size=(20, 3))
    samples[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"samples must be finite; found nan at index \(5, 1\)"):
        learn.quadratic_part(BODY.hamiltonian, BODY, samples)
    with pytest.raises(TypeError, match=r"samples must be real"):
        learn.quadratic_part(BODY.hamiltonian, BODY, samples.astype(complex))


# -- DoubleBracket: complex gamma and metric ------------------------------------------------------
@pytest.mark.parametrize("kwargs, match", [
    ({"gamma": np.complex128(0.1 + 0.2j)}, r"gamma must be a real number >= 0, not complex; got complex128"),
    ({"gamma": np.complex128(0.1)}, r"gamma must be a real number >= 0, not complex"),
    ({"gamma": 0.1, "metric": np.eye(3) + 0.1j}, r"metric must be a \(3, 3\) real matrix, not complex; got complex128"),
])
def test_double_bracket_refuses_complex_numbers(kwargs, match):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not numpy's ComplexWarning: the library's error
        with pytest.raises(TypeError, match=match):
            DoubleBracket(BODY, **kwargs)


# -- compare and convergence: systems by equality -------------------------------------------------
def test_compare_and_convergence_take_an_equal_system():
    y0 = np.array([[0.6, -0.5, 0.7]])
    c = it.compare([it.splitting.Strang(lp.systems.RigidBody(INERTIA), 0.1)], lp.systems.RigidBody(INERTIA), y0,
                   t_final=0.2, n_outputs=2, timing_seconds=0.001, timing_repeats=1)
    assert c.rows[0].error_final < 1e-3
    conv = it.convergence(lambda h: it.LieEuler(damped_rigid_body(), h), damped_rigid_body(), y0, t_final=0.2,
                          hs=[0.1, 0.05])
    assert 0.5 < conv.order < 1.5
    # A system that is not equal is still refused.
    with pytest.raises(ValueError, match=r"is a map of .*not of the system compared"):
        it.compare([it.splitting.Strang(lp.systems.RigidBody((2.0, 1.0, 0.5)), 0.1)], BODY, y0, t_final=0.2,
                   n_outputs=2)


# -- the size of a rollout and of ground truth -----------------------------------------------------
Y0 = np.array([1.0, 0.1, 0.2])


def test_a_rollout_larger_than_memory_is_refused_before_it_allocates():
    with pytest.raises(ValueError, match=r"the rollout's states .* of shape \(1, 1000000000001, 3\) would need "
                                         r".*\(24,000,000,000,024 bytes\), .* GiB of physical memory\); save fewer states "
                                         r"with save_every="):
        it.LieEuler(damped_rigid_body(), 0.1).rollout(Y0, 10**12)
    with pytest.raises(ValueError, match=r"the requested trajectories .* would need .*\(24,000,000,000,024 bytes\), .* "
                                         r"save_ground_truth"):
        it.ground_truth(damped_rigid_body(), Y0, 0.1, 10**12)
    # The same number of steps, saving few of them, is fine.
    assert it.LieEuler(damped_rigid_body(), 0.1).rollout(Y0, 1000, save_every=1000).shape == (2, 3)


def test_the_size_check_without_the_machines_memory(monkeypatch):
    def unavailable(name):
        raise ValueError(f"unrecognized configuration name {name}")

    monkeypatch.setattr(os, "sysconf", unavailable)
    assert liepoisson._memory.physical_memory() == (2**40, False)
    with pytest.raises(ValueError, match=r"of the 1\.02e\+03 GiB of physical memory assumed \(the system does not "
                                         r"report it\)"):
        it.LieEuler(damped_rigid_body(), 0.1).rollout(Y0, 10**12)


# -- a map that ignores h, at uneven steps --------------------------------------------------------
def test_a_map_at_one_fixed_step_refuses_uneven_steps():
    from learn._models._baseline import check_one_step  # called where learn.fit meets observations

    mlp = learn.MLPBaseline(BODY, hidden=(4,), key=0)
    y = np.array([0.3, -0.2, 0.9])
    # its step ignores h: the same output at 0.05 and at 0.3
    np.testing.assert_array_equal(np.asarray(mlp.with_h(0.05).step(y)), np.asarray(mlp.with_h(0.3).step(y)))
    uneven = it.Observations(BODY, [[0.0, 0.05, 0.35, 0.45]], [np.tile(y, (4, 1))])
    with pytest.raises(ValueError, match=r"data has uneven steps, from 0\.05 to 0\.3; MLPBaseline maps a state to the "
                                         r"next at one fixed step \(its step ignores h\)"):
        check_one_step(mlp, uneven.intervals(), None, "data")
    even = it.Observations(BODY, [0.1 * np.arange(4)], [np.tile(y, (4, 1))])
    check_one_step(mlp, even.intervals(), 0.1, "data")  # one step, the map's h
    with pytest.raises(ValueError, match=r"h = 0\.2, but data has steps of 0\.1; .* give h=0\.1 or leave h unset"):
        check_one_step(mlp, even.intervals(), 0.2, "data")
    check_one_step(learn.LPNet(BODY, key=0), uneven.intervals(), 0.1, "data")  # its step takes h
