"""Bad input raises ValueError/TypeError naming the argument, what was expected and what came."""

import numpy as np
import pytest
from helpers import SYSTEMS, algebra, system

import learn
import liepoisson as lp
from integrators import splitting


def _so3():
    return lp.levi_civita().copy()


# -- structure constants ---------------------------------------------------------------------
def test_non_antisymmetric_constants_say_where():
    C = _so3()
    C[0, 1, 2] = 0.5  # [e1, e2] = 0.5 e3 but [e2, e1] = -e3
    with pytest.raises(ValueError, match=r"antisymmetric.*\(a, b, d\) = \(0, 1, 2\)"):
        lp.LieAlgebra(C)
    C = np.zeros((2, 2, 2))
    C[0, 0, 1] = 1.0  # [e1, e1] != 0
    with pytest.raises(ValueError, match=r"antisymmetric.*\(0, 0, 1\)"):
        lp.LieAlgebra(C)


def test_jacobi_violation_says_where():
    C = np.zeros((3, 3, 3))
    C[0, 1, 2], C[1, 0, 2] = 1.0, -1.0  # [e1, e2] = e3
    C[0, 2, 0], C[2, 0, 0] = 1.0, -1.0  # [e1, e3] = e1: Jacobi(e1, e2, e3) = -e3
    with pytest.raises(ValueError, match=r"Jacobi identity.*largest violation is 1 at \(a, b, c\) ="):
        lp.LieAlgebra(C)


def test_round_off_in_constants_is_accepted_but_not_more():
    C = _so3() * (1 + 1e-14)
    lp.LieAlgebra(C)  # tiny rounding: fine
    C = _so3()
    C[0, 1, 2] += 1e-6
    with pytest.raises(ValueError, match="antisymmetric"):
        lp.LieAlgebra(C)


@pytest.mark.parametrize("shape", [(3, 3), (3, 3, 4), (3,), (2, 3, 3), (0, 0, 0)])
def test_wrong_shapes(shape):
    with pytest.raises(ValueError, match=r"structure_constants must have shape \(n, n, n\)"):
        lp.LieAlgebra(np.zeros(shape))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_constants(bad):
    C = _so3()
    C[1, 2, 0] = bad
    with pytest.raises(ValueError, match=r"structure_constants must be finite.*\(1, 2, 0\)"):
        lp.LieAlgebra(C)


@pytest.mark.parametrize("bad", ["so3", None, _so3() * (1 + 0j), [[[1]], [1, 2]]])
def test_non_numeric_constants(bad):
    with pytest.raises(TypeError, match="structure_constants must be a real array"):
        lp.LieAlgebra(bad)


def test_other_constructor_arguments():
    C = _so3()
    with pytest.raises(ValueError, match="sign must be -1"):
        lp.LieAlgebra(C, sign=0)
    with pytest.raises(ValueError, match="sign must be -1"):
        lp.LieAlgebra(C, sign=True)
    with pytest.raises(ValueError, match="basis_names must have 3 entries; got 2"):
        lp.LieAlgebra(C, basis_names=["a", "b"])
    with pytest.raises(TypeError, match=r"casimirs\[0\] must be a Polynomial in 3 variables"):
        lp.LieAlgebra(C, casimirs=["x^2"])
    with pytest.raises(TypeError, match=r"casimirs\[0\] must be a Polynomial in 3 variables"):
        lp.LieAlgebra(C, casimirs=[lp.Polynomial(2, ((1.0, (2, 0)),))])
    with pytest.raises(TypeError, match="coadjoint_flow must be an AbstractCoadjointFlow; got function"):
        lp.LieAlgebra(C, coadjoint_flow=lambda *a: None)
    with pytest.raises(ValueError, match="direct_sum needs at least one algebra"):
        lp.direct_sum()
    with pytest.raises(TypeError, match="argument 1 is ndarray"):
        lp.direct_sum(lp.so3(), C)
    with pytest.raises(ValueError, match="same sign convention"):
        lp.direct_sum(lp.so3(), lp.so3(sign=1))
    with pytest.raises(ValueError, match="Polynomial exponents must be 2 non-negative integers"):
        lp.Polynomial(2, ((1.0, (1, -1)),))
    with pytest.raises(ValueError, match="Polynomial coefficients must be finite"):
        lp.Polynomial(2, ((np.nan, (1, 0)),))


# -- states, parameters and times --------------------------------------------------------------
@pytest.mark.parametrize("name", ["so3", "se3"])
def test_algebra_methods_validate_states(name):
    g = algebra(name)
    n = g.dim
    good = np.ones(n)
    calls = {
        "mu": [lambda x: g.poisson_tensor(x), lambda x: g.casimirs(x), lambda x: g.casimir_gradients(x),
               lambda x: g.coadjoint_flow(good, 1.0, x), lambda x: g.ad_star(good, x)],
        "alpha": [lambda x: g.coadjoint_flow(x, 1.0, good), lambda x: g.coadjoint_generator(x)],
        "xi": [lambda x: g.bracket(x, good), lambda x: g.ad(x)],
    }
    for arg, fns in calls.items():
        for fn in fns:
            with pytest.raises(ValueError, match=rf"{arg} must have shape \(\.\.\., {n}\).*got shape \({n + 1},\)"):
                fn(np.ones(n + 1))
            with pytest.raises(ValueError, match=rf"{arg} must have shape.*got shape \(\)"):
                fn(1.0)
            bad = good.copy()
            bad[1] = np.nan
            with pytest.raises(ValueError, match=rf"{arg} must be finite; found nan at index \(1,\)"):
                fn(bad)
            with pytest.raises(TypeError, match=rf"{arg} must be an array .* got str"):
                fn("abc")
            with pytest.raises(TypeError, match=rf"{arg} must be an array .* got NoneType"):
                fn(None)
            with pytest.raises(TypeError, match=rf"{arg} must be real; got dtype complex128"):
                fn(good * (1 + 1j))
            with pytest.raises(TypeError, match=rf"{arg} must be a real numeric array; got dtype <U1"):
                fn(["a"] * n)


def test_times_are_validated():
    g = algebra("so3")
    a = np.ones(3)
    with pytest.raises(ValueError, match="t must be finite"):
        g.coadjoint_flow(a, np.nan, a)
    with pytest.raises(ValueError, match="t must be finite"):
        g.coadjoint_flow(a, np.inf, a)
    with pytest.raises(TypeError, match="t must be real"):
        g.coadjoint_flow(a, 1j, a)
    with pytest.raises(TypeError, match="t must be a real number or array; got str"):
        g.coadjoint_flow(a, "1", a)
    with pytest.raises(ValueError):  # t of shape (4,) against a batch of 3 cannot broadcast
        g.coadjoint_flow(np.ones((3, 3)), np.ones(4), np.ones((3, 3)))


@pytest.mark.parametrize("name", SYSTEMS)
def test_system_methods_validate_states(name):
    sys = system(name)
    n = sys.dim
    good = np.full(n, 0.5)
    fns = [sys.hamiltonian, sys.poisson_tensor, sys.vector_field, sys.casimirs, sys.casimir_gradients,
           sys.hamiltonian_gradient, lambda y: sys.test_flow(good, 0.1, y)]
    for fn in fns:
        with pytest.raises(ValueError, match=rf"y must have shape \(\.\.\., {n}\).*got shape \({n - 1},\)"):
            fn(np.ones(n - 1))
        bad = good.copy()
        bad[-1] = np.inf
        with pytest.raises(ValueError, match=rf"y must be finite; found inf at index \({n - 1},\)"):
            fn(bad)
        with pytest.raises(TypeError, match="y must be an array"):
            fn("state")
        with pytest.raises(TypeError, match="y must be real"):
            fn(good + 0j)
    with pytest.raises(ValueError, match=rf"alpha must have shape \(\.\.\., {n}\)"):
        sys.test_flow(np.ones(n + 2), 0.1, good)
    with pytest.raises(ValueError, match="alpha must be finite"):
        sys.test_flow(np.full(n, np.nan), 0.1, good)
    with pytest.raises(ValueError, match="t must be finite"):
        sys.test_flow(good, np.nan, good)
    for term in sys.hamiltonian_splitting():
        with pytest.raises(ValueError, match=rf"y must have shape \(\.\.\., {n}\)"):
            term.flow(sys, 0.1, np.ones(n + 1))


@pytest.mark.parametrize(
    "make, exc, pattern",
    [
        (lambda: lp.systems.RigidBody(inertia=(1.0, 0.0, 3.0)), ValueError, r"inertia must be finite and > 0.*\[1.0, 0.0, 3.0\]"),
        (lambda: lp.systems.RigidBody(inertia=(1.0, -2.0, 3.0)), ValueError, "inertia must be finite and > 0"),
        (lambda: lp.systems.RigidBody(inertia=(1.0, np.nan, 3.0)), ValueError, "inertia must be finite and > 0"),
        (lambda: lp.systems.RigidBody(inertia=(1.0, 2.0)), ValueError, r"inertia must have shape \(3,\); got shape \(2,\)"),
        (lambda: lp.systems.RigidBody(inertia="abc"), TypeError, "inertia must be 3 positive numbers"),
        (lambda: lp.systems.RigidBody(inertia=(1 + 1j, 2, 3)), TypeError, "inertia must be 3 positive numbers"),
        (lambda: lp.systems.Kirchhoff(mass=(1.0, 2.0, 0.0)), ValueError, "mass must be finite and > 0"),
        (lambda: lp.systems.Kirchhoff(inertia=(1.0, 2.0, -1.0)), ValueError, "inertia must be finite and > 0"),
        (lambda: lp.systems.HeavyTop(mgl=0.0), ValueError, "mgl must be finite and > 0; got 0.0"),
        (lambda: lp.systems.HeavyTop(mgl=np.inf), ValueError, "mgl must be finite and > 0"),
        (lambda: lp.systems.HeavyTop(mgl="1"), TypeError, "mgl must be a positive real number; got str"),
        (lambda: lp.systems.HeavyTop(mgl=1j), TypeError, "mgl must be a positive real number; got complex"),
        (lambda: lp.systems.HeavyTop(center_of_mass=(0, 0, 0)), ValueError, "center_of_mass must be a non-zero direction"),
        (lambda: lp.systems.HeavyTop(center_of_mass=(0, 1)), ValueError, r"center_of_mass must have shape \(3,\)"),
        (lambda: lp.systems.HeavyTop(center_of_mass=(0, np.nan, 1)), ValueError, "center_of_mass must be finite"),
        (lambda: lp.systems.ChargedParticle(charge=0.0), ValueError, "charge must be finite and non-zero"),
        (lambda: lp.systems.ChargedParticle(charge=np.nan), ValueError, "charge must be finite"),
        (lambda: lp.systems.ChargedParticle(charge="1"), TypeError, "charge must be a finite real number; got str"),
        (lambda: lp.systems.ChargedParticle(mass=-1.0), ValueError, "mass must be finite and > 0"),
        (lambda: lp.systems.ChargedParticle(field_strength=np.inf), ValueError, "field_strength must be finite"),
        (lambda: lp.systems.ChargedParticle(field_strength=None), TypeError, "field_strength must be a finite real number"),
        (lambda: lp.systems.ChargedParticle(potential_strength=1j), TypeError, "potential_strength must be a finite real number"),
        (lambda: lp.systems.from_name("Pendulum"), ValueError, "unknown system 'Pendulum'; known systems are"),
        (lambda: lp.systems.LiePoissonSystem(lp.levi_civita(), lambda y, xp: 0.0), TypeError, "algebra must be a liepoisson.LieAlgebra or MatrixLieAlgebra; got ndarray"),
        (lambda: lp.systems.LiePoissonSystem(lp.so3(), 3.0), TypeError, "hamiltonian must be callable"),
        (lambda: lp.systems.LiePoissonSystem(lp.so3(), lambda y, xp: xp.sin(y[0]) * y[1]).hamiltonian_splitting(), ValueError, "no automatic exact splitting"),
    ],
)
def test_system_parameters(make, exc, pattern):
    with pytest.raises(exc, match=pattern):
        make()


# -- one validation module for every package ----------------------------------------------------
def _pairs():
    y0 = np.random.default_rng(0).normal(size=(10, 3))
    return y0, y0 + 0.01


def _fit(**kwargs):
    body = system("RigidBody")
    args = {"data": _pairs(), "h": 0.1, "optimiser": learn.Adam(1), "progress": False} | kwargs
    return learn.fit(learn.LPNet(body, hidden=(2,)), args.pop("data"), **args)


def _strang(h=0.1):
    return splitting.Strang(system("RigidBody"), h=h)


_BODY = system("RigidBody")
_Y_NAN = np.array([0.1, np.nan, 0.3])


@pytest.mark.parametrize(
    "call, exc, message",
    [
        # integers (positive_int)
        (lambda: _strang().rollout(np.ones(3), -1), ValueError, "n_steps must be an integer >= 0; got -1"),
        (lambda: _strang().rollout(np.ones(3), 2, save_every=0), ValueError, "save_every must be an integer >= 1; got 0"),
        (lambda: learn.GLPNet(_BODY, n_modules=0), ValueError, "n_modules must be an integer >= 1; got 0"),
        (lambda: learn.Adam(0), ValueError, "Adam.epochs must be an integer >= 1; got 0"),
        (lambda: _fit(seed=-1), ValueError, "seed must be an integer >= 0; got -1"),
        (lambda: learn.ScipyLBFGSB(2.5), TypeError, "ScipyLBFGSB.iterations must be an integer >= 1; got float 2.5"),
        # step sizes and rates (positive_float)
        (lambda: _strang(h=0.0), ValueError, "h must be finite and > 0; got 0.0"),
        (lambda: learn.LPNet(_BODY, h=-1.0), ValueError, "h must be finite and > 0; got -1.0"),
        (lambda: learn.MLPBaseline(_BODY, h=np.inf), ValueError, "h must be finite and > 0; got inf"),
        (lambda: learn.Adam(learning_rate=0), ValueError, "Adam.learning_rate must be finite and > 0; got 0.0"),
        (lambda: _fit(h=0.0), ValueError, "h must be finite and > 0; got 0.0"),
        # fractions
        (lambda: _fit(validation_fraction=1.5), ValueError, r"validation_fraction must be in \[0, 1\); got 1.5"),
        # states and pairs (states, pairs, as_state)
        (lambda: _strang().rollout(_Y_NAN, 2), ValueError, r"y0 must be finite; found nan at index \(1,\)"),
        (lambda: _strang().rollout(np.ones(4), 2), ValueError, r"y0 must have shape \(\.\.\., 3\).*got shape \(4,\)"),
        (lambda: _strang().step(_Y_NAN), ValueError, r"y must be finite; found nan at index \(1,\)"),
        (lambda: learn.LPNet(_BODY, h=0.1).step(_Y_NAN), ValueError, r"y must be finite; found nan at index \(1,\)"),
        (lambda: _strang().poisson_defect("y"), TypeError, "y must be an array"),
        (lambda: _fit(data=(_pairs()[0], _pairs()[1][:5])), ValueError, r"y0 and y1 must have the same shape; got \(10, 3\) and \(5, 3\)"),
        (lambda: _fit(data=(_pairs()[0], np.full((10, 3), np.inf))), ValueError, r"y1 must be finite; found inf at index \(0, 0\)"),
        # systems (check_system)
        (lambda: splitting.Strang("RigidBody", h=0.1), TypeError, "system must be a liepoisson.systems.AbstractPoissonSystem; got str"),
        (lambda: learn.LPNet("RigidBody"), TypeError, "system must be a liepoisson.systems.AbstractPoissonSystem; got str"),
        (lambda: learn.GLPNet("RigidBody"), TypeError, "system must be a liepoisson.systems.AbstractPoissonSystem; got str"),
        (lambda: learn.MLPBaseline(3), TypeError, "system must be a liepoisson.systems.AbstractPoissonSystem; got int"),
        (lambda: learn.TestFlowParametrisation(None), TypeError, "system must be a liepoisson.systems.AbstractPoissonSystem; got NoneType"),
    ],
)
def test_every_package_validates_alike(call, exc, message):
    """integrators, learn and liepoisson share one validation module: the same check gives
    the same message (argument, expectation, value received) wherever it is called from."""
    with pytest.raises(exc, match=message):
        call()
