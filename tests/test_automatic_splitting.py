"""Automatic exact splitting of a user Hamiltonian on any algebra: quadratic addends by the
eigen-decomposition of their Hessian, other addends as functions of the linear forms their
gradient spans; checked against the catalogue's hand-written splitting and heyoka."""

from __future__ import annotations

import numpy as np
import pytest
from test_user_systems import diamond_constants, so4_constants

import integrators as it
import liepoisson as lp
from liepoisson.systems import LiePoissonSystem

EPS = np.finfo(np.float64).eps


def levi_civita_constants() -> np.ndarray:
    C = np.zeros((3, 3, 3))
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        C[a, b, c], C[b, a, c] = 1.0, -1.0
    return C


def user_rigid_body() -> LiePoissonSystem:
    inertia = (1.0, 2.0, 3.0)
    return LiePoissonSystem(lp.LieAlgebra(levi_civita_constants(), "so3_user"),
                            lambda m, xp: sum(0.5 * m[i] ** 2 / inertia[i] for i in range(3)))


def generic_so4() -> LiePoissonSystem:
    A = np.random.default_rng(3).normal(size=(6, 6))
    A = A @ A.T / 6.0
    return LiePoissonSystem(
        lp.LieAlgebra(so4_constants(), "so4"),
        lambda m, xp: 0.5 * sum(A[i, j] * m[i] * m[j] for i in range(6) for j in range(6)) + 0.3 * m[2],
    )


def diamond_with_ridges() -> LiePoissonSystem:
    return LiePoissonSystem(
        lp.LieAlgebra(diamond_constants(), "diamond"),
        lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2) + m[3] + 0.1 * xp.exp(-(m[2] ** 2)) + 0.2 * xp.cos(m[0] - 2 * m[3]),
    )


@pytest.mark.slow  # ~3 s; the pieces-sum and order tests below run by default
def test_diagonal_quadratic_gives_the_axis_splitting_of_the_catalogue():
    """The user-built rigid body splits into the three axis rotations, in the catalogue's order:
    Strang equals the hand-written RigidBody splitting to round-off."""
    user = user_rigid_body()
    pieces = user.hamiltonian_splitting()
    assert len(pieces) == 3
    for k, p in enumerate(pieces):
        np.testing.assert_array_equal(np.abs(p.forms), np.eye(3)[k : k + 1])
    y0 = np.random.default_rng(0).normal(size=(4, 3))
    a = np.asarray(it.splitting.Strang(user, 0.1).rollout(y0, 100))
    b = np.asarray(it.splitting.Strang(lp.systems.RigidBody((1.0, 2.0, 3.0)), 0.1).rollout(y0, 100))
    # Two implementations of the same rotations (matrix exponential vs Rodrigues): a few
    # roundings per step over 100 steps.
    assert np.max(np.abs(a - b)) <= 1e4 * EPS * np.max(np.abs(b))


# with -m slow (~5 s): the diamond's automatic pieces run by default in
# test_observed_order_of_the_automatic_splitting, whose order against heyoka needs every piece exact
# and their sum to be H
@pytest.mark.parametrize("make, n_pieces", [pytest.param(generic_so4, 7, marks=pytest.mark.slow),
                                            pytest.param(diamond_with_ridges, 5, marks=pytest.mark.slow)])
def test_pieces_sum_to_the_hamiltonian_and_conserve_their_forms(make, n_pieces):
    system = make()
    pieces = system.hamiltonian_splitting()
    assert len(pieces) == n_pieces
    y = np.random.default_rng(5).normal(size=(32, system.dim))
    H = np.asarray(system.hamiltonian(y))
    total = sum(np.asarray(p.value(system, y)) for p in pieces)
    d = H - total
    assert np.max(np.abs(d - d[0])) <= 1e3 * EPS * np.max(np.abs(H))
    for p in pieces:
        z = np.asarray(p.flow(system, 0.7, y))
        # each piece's flow is exact: its linear forms and the Casimirs are conserved
        np.testing.assert_allclose(z @ p.forms.T, y @ p.forms.T, rtol=0, atol=1e3 * EPS * np.max(np.abs(y)))
        np.testing.assert_allclose(np.asarray(system.casimirs(z)), np.asarray(system.casimirs(y)),
                                   rtol=1e3 * EPS, atol=1e3 * EPS * np.max(np.abs(y)) ** 2)


_SLOW = pytest.mark.slow  # ~10 s each (heyoka + a compiled rollout); by default the diamond's Strang


@pytest.mark.parametrize(
    "make, method, order",
    [
        pytest.param(generic_so4, it.splitting.Strang, 2, marks=_SLOW),  # so(4) Strang also in test_any_algebra.py
        pytest.param(diamond_with_ridges, it.splitting.Strang, 2, marks=_SLOW),  # the default run's time
        pytest.param(diamond_with_ridges, it.splitting.TripleJump, 4, marks=_SLOW),
        pytest.param(generic_so4, it.splitting.TripleJump, 4, marks=_SLOW),
        pytest.param(user_rigid_body, it.splitting.Strang, 2, marks=_SLOW),  # also: equals the catalogue's Strang
        pytest.param(user_rigid_body, it.splitting.TripleJump, 4, marks=_SLOW),
    ],
)
def test_observed_order_of_the_automatic_splitting(make, method, order):
    system = make()
    y0 = 0.5 * np.random.default_rng(0).normal(size=(3, system.dim))
    ref = it.ground_truth(system, y0, h=1.0, n_steps=1).states[:, -1]  # heyoka, tolerance eps
    hs = (0.1, 0.05)
    # save_every = n: the state at t = 1 only, by one compiled rollout for both h
    errs = [np.max(np.abs(np.asarray(method(system, h).rollout(y0, n := round(1.0 / h), save_every=n))[:, -1] - ref))
            for h in hs]
    observed = np.log2(errs[0] / errs[1])
    assert abs(observed - order) < 0.1, (errs, observed)


@pytest.mark.slow
def test_a_function_of_the_casimirs_is_a_piece_with_the_identity_flow():
    C = levi_civita_constants()
    system = LiePoissonSystem(lp.LieAlgebra(C), lambda m, xp: 0.5 * m[0] ** 2 + xp.sqrt(1.0 + m[0] ** 2 + m[1] ** 2 + m[2] ** 2))
    pieces = system.hamiltonian_splitting()
    y = np.random.default_rng(1).normal(size=(8, 3))
    last = np.asarray(pieces[-1].flow(system, 0.9, y))
    np.testing.assert_allclose(last, y, rtol=0, atol=10 * EPS * np.max(np.abs(y)))


def test_an_addend_on_non_commuting_forms_is_named():
    C = levi_civita_constants()
    system = LiePoissonSystem(lp.LieAlgebra(C), lambda m, xp: 0.5 * m[2] ** 2 + xp.sin(m[0]) * m[1])
    with pytest.raises(ValueError, match=r"no automatic exact splitting: the addend sin\(e1\)\*e2 .* 2 linear forms that do not Poisson-commute.*splitting="):
        it.splitting.Strang(system, 0.1)


def test_a_given_splitting_wins_over_the_automatic_one():
    user = user_rigid_body()
    given = LiePoissonSystem(user.algebra, user._hamiltonian, splitting=lp.systems.RigidBody().hamiltonian_splitting())
    assert given.hamiltonian_splitting()[0].name == "T1"
