"""User-defined systems are first-class: a `LiePoissonSystem` written from structure constants
saves its definition with data sets and models and is rebuilt on load; splittings, Casimir
searches and Hamiltonians that would go wrong later are refused or warned about up front."""

from __future__ import annotations

import itertools
import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import integrators as it
import learn
import liepoisson as lp
from liepoisson.systems import CollectiveTerm, LiePoissonSystem

EPS = np.finfo(np.float64).eps


def so4_constants() -> np.ndarray:
    """so(4) from its 4x4 antisymmetric basis E_(ij), i < j: [E_a, E_b] = C_abd E_d, computed
    from matrix commutators (independent of the catalogue)."""
    pairs = list(itertools.combinations(range(4), 2))
    E = []
    for i, j in pairs:
        m = np.zeros((4, 4))
        m[i, j], m[j, i] = 1.0, -1.0
        E.append(m)
    basis = np.stack([e.ravel() for e in E], axis=1)
    C = np.zeros((6, 6, 6))
    for a, b in itertools.product(range(6), repeat=2):
        comm = E[a] @ E[b] - E[b] @ E[a]
        C[a, b] = np.linalg.lstsq(basis, comm.ravel(), rcond=None)[0]
    return C


def diamond_constants() -> np.ndarray:
    """The 4-dim solvable diamond (oscillator) algebra: [e1, e2] = e3, [e4, e1] = e1,
    [e4, e2] = -e2; e3 central."""
    C = np.zeros((4, 4, 4))
    for a, b, d, v in ((0, 1, 2, 1.0), (3, 0, 0, 1.0), (3, 1, 1, -1.0)):
        C[a, b, d], C[b, a, d] = v, -v
    return C


def r3_constants(lam: float) -> np.ndarray:
    """r_{3,lambda}: [e3, e1] = e1, [e3, e2] = lambda e2 (solvable); its Casimir is a function
    of mu1^lambda / mu2."""
    C = np.zeros((3, 3, 3))
    C[2, 0, 0], C[0, 2, 0] = 1.0, -1.0
    C[2, 1, 1], C[1, 2, 1] = lam, -lam
    return C


def so4_system(**kw) -> LiePoissonSystem:
    algebra = lp.LieAlgebra(so4_constants(), "so4_user")
    inertia = np.array([1.0, 1.5, 2.0, 2.5, 3.0, 3.5])

    def H(m, xp):
        return sum(0.5 * m[i] ** 2 / inertia[i] for i in range(6)) + 0.1 * xp.cos(m[0])

    return LiePoissonSystem(algebra, H, name="so4 body", **kw)


def diamond_system(**kw) -> LiePoissonSystem:
    algebra = lp.LieAlgebra(diamond_constants(), "diamond", ("p", "q", "z", "n"))
    return LiePoissonSystem(
        algebra, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2) + m[3] + 0.1 * xp.exp(-(m[2] ** 2)),
        name="diamond oscillator", **kw,
    )


def diamond_splitting() -> list[CollectiveTerm]:
    """H = p^2/2 + q^2/2 + n + 0.1 exp(-z^2): four pieces, each a function of one linear form."""
    e = np.eye(4)
    return [
        CollectiveTerm(e[0], lambda s: 0.5 * s[0] ** 2, "P"),
        CollectiveTerm(e[1], lambda s: 0.5 * s[0] ** 2, "Q"),
        CollectiveTerm(e[3], lambda s: s[0], "N"),
        CollectiveTerm(e[2], lambda s: 0.1 * 2.718281828459045 ** (-(s[0] ** 2)), "Z"),
    ]


SYSTEMS = {"so4": so4_system, "diamond": diamond_system}


# -- data sets and models round-trip --------------------------------------------------------
@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_data_set_round_trip_rebuilds_the_user_system(name, tmp_path):
    system = SYSTEMS[name]()
    y0 = np.random.default_rng(1).normal(size=(3, system.dim))
    data = it.ground_truth(system, y0, h=0.1, n_steps=5, seed=3)
    data.save(tmp_path / "d.h5")
    back = it.Trajectories.load(tmp_path / "d.h5")
    assert isinstance(back.system, LiePoissonSystem) and back.system is not system
    assert back.system.name == system.name and back.system.state_names == system.state_names
    np.testing.assert_array_equal(back.states, data.states)
    np.testing.assert_array_equal(back.system.algebra.structure_constants, system.algebra.structure_constants)
    assert back.system.n_casimirs == system.n_casimirs
    # The rebuilt Hamiltonian is the same formula: equal up to the order of a few roundings
    # (JAX may fuse the rebuilt tree's operations differently from the original function).
    y = np.random.default_rng(2).normal(size=(16, system.dim))
    h0, h1 = np.asarray(system.hamiltonian(y)), np.asarray(back.system.hamiltonian(y))
    assert np.max(np.abs(h1 - h0)) <= 16 * EPS * np.max(np.abs(h0))
    # ...and the rebuilt system integrates to the same trajectories (heyoka, tolerance eps).
    again = it.ground_truth(back.system, y0, h=0.1, n_steps=5, seed=3)
    assert np.max(np.abs(again.states - data.states)) <= 1e3 * EPS * np.max(np.abs(data.states))


# so(4)'s with -m slow: the diamond's runs the same code by default
@pytest.mark.parametrize("name", [n if n == "diamond" else pytest.param(n, marks=pytest.mark.slow)
                                  for n in sorted(SYSTEMS)])
def test_model_round_trip_without_the_system(name, tmp_path):
    system = SYSTEMS[name]()
    y0 = np.random.default_rng(1).normal(size=(4, system.dim))
    # seeded random weights and a step: what a fit would leave (the file does not know the
    # difference), without compiling a training on this algebra (~5 s)
    model = learn.GLPNet(system, n_modules=system.dim, key=0, h=0.1)
    model.save(tmp_path / "m.h5")
    back = learn.GLPNet.load(tmp_path / "m.h5")
    assert isinstance(back.system, LiePoissonSystem) and back.system.name == system.name
    np.testing.assert_array_equal(np.asarray(back.rollout(y0, 3)), np.asarray(model.rollout(y0, 3)))
    same = learn.GLPNet.load(tmp_path / "m.h5", system=system)
    assert same.system is system


def test_a_data_set_keeps_its_splitting(tmp_path):
    system = diamond_system(splitting=diamond_splitting())
    y0 = np.random.default_rng(0).normal(size=(2, 4))
    it.ground_truth(system, y0, h=0.1, n_steps=2).save(tmp_path / "d.h5")
    back = it.Trajectories.load(tmp_path / "d.h5").system
    a = np.asarray(it.splitting.Strang(system, 0.1).rollout(y0, 20))
    b = np.asarray(it.splitting.Strang(back, 0.1).rollout(y0, 20))
    # Same pieces, rebuilt from their trees: equal to a few roundings per step over 20 steps.
    assert np.max(np.abs(a - b)) <= 1e3 * EPS * np.max(np.abs(a))


def test_an_unsaveable_splitting_is_restored_by_passing_the_system(tmp_path):
    e = np.eye(4)
    pieces = diamond_splitting()[:3] + [CollectiveTerm(e[2], lambda s: 0.1 * jnp.exp(-(s[0] ** 2)), "Z")]
    system = diamond_system(splitting=pieces)
    assert system.params["splitting"] is None  # jnp.exp does not evaluate on symbols
    y0 = np.random.default_rng(0).normal(size=(2, 4))
    it.ground_truth(system, y0, h=0.1, n_steps=2).save(tmp_path / "d.h5")
    rebuilt = it.Trajectories.load(tmp_path / "d.h5").system
    with pytest.raises(ValueError, match=r"splitting of 'diamond oscillator' was not saved.*system="):
        it.splitting.Strang(rebuilt, 0.1)
    given = it.Trajectories.load(tmp_path / "d.h5", system=system).system
    assert given is system and len(it.splitting.Strang(given, 0.1).terms) == 4


@pytest.mark.parametrize(
    "other, reason",
    [
        (lambda: diamond_system(), "names differ"),
        (lambda: LiePoissonSystem(lp.LieAlgebra(so4_constants()), lambda m, xp: m[0] ** 2, name="so4 body"),
         "Hamiltonians differ"),
        (lambda: LiePoissonSystem(lp.LieAlgebra(-so4_constants()), so4_system()._hamiltonian, name="so4 body"),
         "algebras differ"),
        (lambda: lp.systems.RigidBody(), "names differ"),
    ],
)
def test_a_system_that_does_not_match_the_file_is_refused(other, reason, tmp_path):
    system = so4_system()
    it.ground_truth(system, np.ones((1, 6)), h=0.1, n_steps=2).save(tmp_path / "d.h5")
    with pytest.raises(ValueError, match=rf"does not match the file .*d\.h5.*{reason}"):
        it.Trajectories.load(tmp_path / "d.h5", system=other())


def test_ground_truth_tells_two_user_systems_on_one_algebra_apart():
    """The compiled heyoka integrator is cached by the system's definition: two Hamiltonians on
    the same algebra must not share it (they did when only the algebra's name was the key)."""
    algebra = lp.LieAlgebra(so4_constants(), "so4_user")
    a = LiePoissonSystem(algebra, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 / 2 + m[5] ** 2 / 3))
    b = LiePoissonSystem(algebra, lambda m, xp: 0.5 * (m[0] ** 2 / 3 + m[1] ** 2 + m[5] ** 2 / 2))
    y0 = np.random.default_rng(0).normal(size=(1, 6))
    ya = it.ground_truth(a, y0, h=0.5, n_steps=4).states
    yb = it.ground_truth(b, y0, h=0.5, n_steps=4).states
    assert np.max(np.abs(ya - yb)) > 1e-2
    # Each trajectory conserves its own system's energy (a shared integrator would not).
    for system, y in ((a, ya), (b, yb)):
        energy = np.asarray(system.hamiltonian(y))
        assert np.max(np.abs(energy - energy[:, :1])) <= 1e3 * EPS * np.max(np.abs(energy))


# -- mistakes named at construction ---------------------------------------------------------
def test_pieces_that_do_not_sum_to_the_hamiltonian_are_refused():
    pieces = diamond_splitting()
    pieces[2] = CollectiveTerm(np.eye(4)[3], lambda s: 2.0 * s[0], "N")
    with pytest.raises(ValueError, match=r"splitting must sum to the Hamiltonian.*'N'"):
        diamond_system(splitting=pieces)
    with pytest.raises(ValueError, match=r"splitting must sum to the Hamiltonian"):
        diamond_system(splitting=diamond_splitting()[:3])


def test_a_piece_whose_forms_do_not_commute_is_named():
    """p^2/2 + q^2/2 as one piece with forms (p, q): {p, q} = z != 0, so the frozen flow is not
    its exact flow (Strang would silently drop to order 1)."""
    e = np.eye(4)
    pieces = [CollectiveTerm(e[:2], lambda s: 0.5 * (s[0] ** 2 + s[1] ** 2), "PQ")] + diamond_splitting()[2:]
    with pytest.raises(ValueError, match=r"splitting\[0\]: the linear forms of piece 0 \(PQ\) do not Poisson-commute"):
        diamond_system(splitting=pieces)
    # The same check guards hand-written terms given to a splitting method.
    with pytest.raises(ValueError, match=r"terms\[0\].*PQ.*Poisson-commute"):
        it.splitting.Strang(diamond_system(), 0.1, terms=pieces)


@pytest.mark.parametrize("piece", ["not a term", None, 3.0])
def test_a_piece_that_is_not_an_exact_term_is_named(piece):
    with pytest.raises(TypeError, match=r"splitting\[1\] must be an exact piece"):
        diamond_system(splitting=[diamond_splitting()[0], piece])


def test_an_exact_term_whose_flow_does_not_conserve_its_value_is_named():
    class Wrong(lp.systems.AbstractExactTerm):
        name = "drift"

        def value(self, system, y):
            return jnp.asarray(y)[..., 3]

        def flow(self, system, t, y):
            return jnp.asarray(y) + t  # not the flow of n: it moves n itself

    pieces = diamond_splitting()[:2] + [Wrong(), diamond_splitting()[3]]
    with pytest.raises(ValueError, match=r"splitting\[2\]: the flow of piece 2 \(drift\) does not conserve"):
        diamond_system(splitting=pieces)


@pytest.mark.parametrize(
    "hamiltonian, what",
    [
        (lambda m, xp: np.sqrt(1.0 + m[0] ** 2), "numpy.sqrt"),
        (lambda m, xp: np.cos(m[0]) + m[1], "numpy.cos"),
        (lambda m, xp: jnp.cos(m[0]), "raised"),
        (lambda m, xp: math.exp(m[0]), "converts"),
        (lambda m, xp: m[0] if m[0] > 0 else -m[0], "branches"),
        (lambda m, xp: np.array([1.0, 2.0, 3.0, 4.0]) @ np.array(m), "numpy array"),
        (lambda m, xp: [m[0], m[1]], "returned a list"),
    ],
)
def test_a_hamiltonian_not_written_against_xp_is_refused_when_the_system_is_built(hamiltonian, what):
    with pytest.raises(TypeError, match=rf"hamiltonian: .*{what}.*xp\.sqrt"):
        LiePoissonSystem(lp.LieAlgebra(diamond_constants()), hamiltonian)


def test_xp_formulas_with_numpy_scalars_and_constants_are_accepted():
    inv = np.array([1.0, 0.5, 0.25, 2.0])
    system = LiePoissonSystem(
        lp.LieAlgebra(diamond_constants()),
        lambda m, xp: sum(np.float64(0.5) * inv[i] * m[i] ** 2 for i in range(4)) + xp.sqrt(2.0) * xp.log(1 + m[2] ** 2),
    )
    y = np.array([0.3, -1.2, 0.7, 2.0])
    expected = 0.5 * np.sum(inv * y**2) + np.sqrt(2.0) * np.log(1 + y[2] ** 2)
    assert abs(float(system.hamiltonian(y)) - expected) <= 8 * EPS * abs(expected)


# -- Casimir search shortfall --------------------------------------------------------------
def test_missing_casimirs_warn_with_the_degree_and_how_to_raise_it():
    """r_{3,-5}: generic corank 1, Casimir mu1^5 mu2 of degree 6, beyond the default search."""
    with pytest.warns(UserWarning, match=r"found 0 polynomial Casimir\(s\) of degree <= 4.*corank 1.*max_casimir_degree=6"):
        algebra = lp.LieAlgebra(r3_constants(-5.0))
    assert algebra.n_casimirs == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        raised = lp.LieAlgebra(r3_constants(-5.0), max_casimir_degree=6)
    assert raised.n_casimirs == 1
    y = np.random.default_rng(0).normal(size=(8, 3))
    c = np.asarray(raised.casimirs(y))[:, 0]
    np.testing.assert_allclose(c / c[0], (y[:, 0] ** 5 * y[:, 1]) / (y[0, 0] ** 5 * y[0, 1]), rtol=1e-12)


def test_non_polynomial_casimirs_warn_and_full_searches_do_not():
    with pytest.warns(UserWarning, match="not polynomial"):
        lp.LieAlgebra(r3_constants(math.sqrt(2.0)))  # Casimir mu1^sqrt2 / mu2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert lp.LieAlgebra(diamond_constants()).n_casimirs == 2  # z and p q + z n (corank 2)
        assert lp.LieAlgebra(so4_constants()).n_casimirs == 2


def test_catalogue_files_check_a_given_system(tmp_path):
    body = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    it.ground_truth(body, np.ones((1, 3)), h=0.1, n_steps=2).save(tmp_path / "d.h5")
    assert it.Trajectories.load(tmp_path / "d.h5", system=body).system is body
    with pytest.raises(ValueError, match=r"does not match the file .*parameters differ"):
        it.Trajectories.load(tmp_path / "d.h5", system=lp.systems.RigidBody(inertia=(1.0, 2.0, 4.0)))
    with pytest.raises(TypeError, match=r"system must be an AbstractPoissonSystem or None; got str"):
        it.Trajectories.load(tmp_path / "d.h5", system="RigidBody")


def test_a_damaged_definition_is_named(tmp_path):
    import h5py

    it.ground_truth(diamond_system(), np.ones((1, 4)), h=0.1, n_steps=2).save(tmp_path / "d.h5")
    with h5py.File(tmp_path / "d.h5", "r+") as f:
        f.attrs["system_params"] = f.attrs["system_params"].replace('"mul"', '"frobnicate"')
    with pytest.raises(ValueError, match=r"d\.h5.*cannot rebuild the system.*unknown node 'frobnicate'"):
        it.Trajectories.load(tmp_path / "d.h5")
