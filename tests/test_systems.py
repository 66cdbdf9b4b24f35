"""Physical systems: equations of motion from the literature, Poisson test flows and splitting
terms, Jacobi identity, closed-form test flows against ODE solvers, the heyoka right-hand
side, degenerate cases of the charged particle."""

import functools

import heyoka as hy
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
from helpers import (
    EPS,
    SYSTEMS,
    poisson_defect,
    reference_tensor,
    slow_except,
    solve_ivp_flow,
    states,
    system,
    system_names,
    times,
    vectors,
)
from hypothesis import given
from hypothesis import strategies as st

import liepoisson as lp


def _random_state(name, rng):
    y = rng.uniform(-1.5, 1.5, system(name).dim)
    if name == "ChargedParticle":  # keep x away from the origin
        r, phi = rng.uniform(0.3, 1.5), rng.uniform(0, 2 * np.pi)
        y[2:] = r * np.array([np.cos(phi), np.sin(phi)])
    return y


# -- equations of motion from the literature -------------------------------------------------
def _literature_vector_field(name, sys, y):
    if name == "RigidBody":  # Euler: dPi/dt = Pi x Omega
        return np.cross(y, y / sys.inertia)
    if name == "Kirchhoff":  # paper eq. Underwater_body_eqs
        Pi, p = y[:3], y[3:]
        Om, v = Pi / sys.inertia, p / sys.mass
        return np.concatenate([np.cross(Pi, Om) + np.cross(p, v), np.cross(p, Om)])
    if name == "HeavyTop":
        Pi, Ga = y[:3], y[3:]
        Om, chi = Pi / sys.inertia, sys.center_of_mass
        return np.concatenate([np.cross(Pi, Om) + sys.mgl * np.cross(Ga, chi), np.cross(Ga, Om)])
    if name == "ExtendedPendulum":  # paper eq. ext_pendulum, K = u^2/2 - cos v + ur - u^3 - uv^2
        u, v, r = y
        gradK = np.array([u + r - 3 * u**2 - v**2, np.sin(v) - 2 * u * v, u])
        B = np.array([[0, -1, -2 * v], [1, 0, 2 * u], [2 * v, -2 * u, 0]])
        return B @ gradK
    if name == "ChargedParticle":  # dp/dt = q v x B - q grad phi, dx/dt = v = p/m
        p, x = y[:2], y[2:]
        q, m, b0, k = sys.charge, sys.mass, sys.field_strength, sys.potential_strength
        v = p / m
        B3 = b0 * np.linalg.norm(x)
        vxB = np.array([v[1] * B3, -v[0] * B3])
        grad_phi = -k * x / np.linalg.norm(x) ** 3
        return np.concatenate([q * vxB - q * grad_phi, v])
    raise KeyError(name)


@system_names
def test_vector_field_is_the_literature_equation(name):
    sys = system(name)
    rng = np.random.default_rng(30)
    for _ in range(5):
        y = _random_state(name, rng)
        ref = _literature_vector_field(name, sys, y)
        got = np.asarray(sys.vector_field(y))
        np.testing.assert_allclose(got, ref, rtol=0, atol=64 * EPS * max(1.0, np.max(np.abs(ref))))
        np.testing.assert_allclose(
            np.asarray(sys.poisson_tensor(y)), reference_tensor(name, sys, y), atol=8 * EPS
        )


def test_rigid_body_reaches_the_papers_end_point():
    """docs/conventions.md: I = diag(1, 2, 3), Pi0 = (1/sqrt2, -1/sqrt2, 1) reaches (0.426, 1.332, -0.212)
    at t = 99.9 (an independent check of the sign convention of Euler's equations)."""
    sys = system("RigidBody")
    f = jax.jit(sys.vector_field)
    sol = scipy.integrate.solve_ivp(
        lambda t, y: np.asarray(f(y)), (0, 99.9), [2**-0.5, -(2**-0.5), 1.0], method="DOP853",
        rtol=1e-11, atol=1e-12,
    )
    np.testing.assert_allclose(sol.y[:, -1], [0.426, 1.332, -0.212], atol=2e-3)


@system_names
def test_hamiltonian_and_casimirs_are_conserved_by_the_vector_field(name):
    sys = system(name)
    rng = np.random.default_rng(31)
    for _ in range(3):
        y = jnp.asarray(_random_state(name, rng))
        f = sys.vector_field(y)
        dH = jax.grad(sys.hamiltonian)(y)
        assert abs(float(dH @ f)) < 64 * EPS * max(1.0, float(jnp.max(jnp.abs(f))))
        if sys.n_casimirs:
            G = sys.casimir_gradients(y)
            np.testing.assert_allclose(np.asarray(G @ f), 0.0, atol=64 * EPS * 10)
            np.testing.assert_allclose(np.asarray(sys.poisson_tensor(y) @ G.T), 0.0, atol=64 * EPS)
        if name == "ChargedParticle":  # the second integral I (paper eq. Cons_law_momentum)
            dI = jax.grad(sys.angular_integral)(y)
            assert abs(float(dI @ f)) < 64 * EPS * 10


def test_casimir_counts():
    assert [system(n).n_casimirs for n in SYSTEMS] == [1, 2, 2, 1, 0]


# -- Jacobi identity of every Poisson tensor ---------------------------------------------------
@system_names
def test_poisson_tensor_antisymmetric_and_jacobi(name):
    sys = system(name)
    rng = np.random.default_rng(32)
    jac = jax.jit(jax.jacfwd(sys.poisson_tensor))
    for _ in range(4):
        y = jnp.asarray(_random_state(name, rng))
        B = sys.poisson_tensor(y)
        np.testing.assert_array_equal(np.asarray(B), -np.asarray(B).T)
        dB = jac(y)  # dB[j, k, l] = d_l B_jk
        t = jnp.einsum("il,jkl->ijk", B, dB)
        cyc = t + jnp.transpose(t, (1, 2, 0)) + jnp.transpose(t, (2, 0, 1))
        assert float(jnp.max(jnp.abs(cyc))) < 64 * EPS


# -- exact test flows are Poisson maps ---------------------------------------------------------
# Kirchhoff's test flow (se(3)'s coadjoint flow, a Poisson map by default in test_coadjoint.py) with -m slow
@pytest.mark.parametrize("name", slow_except(SYSTEMS, {"RigidBody", "ChargedParticle"}))
@given(data=st.data())
def test_test_flow_is_poisson(name, data):
    sys = system(name)
    alpha = data.draw(vectors(sys.dim), label="alpha")
    y = data.draw(states(name, sys.dim), label="y")
    t = data.draw(times, label="t")
    if name == "ChargedParticle":
        # keep the segment x0 + a s away from the origin (|x| is not differentiable there)
        x = y[2:] + alpha[:2] * np.linspace(0, t, 50)[:, None]
        if np.min(np.linalg.norm(x, axis=1)) < 0.05:
            alpha[:2] *= 0.0
    defect, size = poisson_defect(("system", name), sys.test_flow, sys.poisson_tensor, alpha, t, y)
    # entries of J B J^T are O(|y| |J|^2) <= ~100 here; 1e-10 is ~1e5 eps of that
    assert defect <= 1e-10 * max(1.0, size)


_TERM_DEFECTS = {}


def _term_defects(name):
    """y, t -> Poisson defects of every splitting term's flow (one jitted function per system)."""
    if name not in _TERM_DEFECTS:
        sys = system(name)
        terms = sys.hamiltonian_splitting()

        def defects(t, y):
            out = []
            for term in terms:
                flow = lambda z, term=term: term.flow(sys, t, z)
                J = jax.jacfwd(flow)(y)
                z = flow(y)
                d = jnp.max(jnp.abs(J @ sys.poisson_tensor(y) @ J.T - sys.poisson_tensor(z)))
                out.append(d / jnp.maximum(1.0, jnp.max(jnp.abs(z))))
            return jnp.stack(out)

        _TERM_DEFECTS[name] = jax.jit(defects)
    return _TERM_DEFECTS[name]


# Kirchhoff's and the charged particle's term flows with -m slow: test_splitting_sums_to_h_and_each_flow_is_exact
# checks them against DOP853 by default
@pytest.mark.parametrize("name", slow_except(SYSTEMS, {"RigidBody"}))
@given(data=st.data())
def test_splitting_terms_are_poisson_and_commute(name, data):
    """Each term's flow (the test flow with alpha frozen at L^T dphi(L y)) is a Poisson map,
    and the forms L of a term Poisson-commute, L B(y) L^T = 0."""
    sys = system(name)
    y = data.draw(states(name, sys.dim), label="y")
    t = data.draw(times, label="t")
    B = np.asarray(sys.poisson_tensor(y))
    for term in sys.hamiltonian_splitting():
        L = term.forms
        np.testing.assert_allclose(L @ B @ L.T, 0.0, atol=16 * EPS)
    defects = np.asarray(_term_defects(name)(jnp.asarray(t), jnp.asarray(y)))
    assert np.all(defects <= 1e-10), defects


@system_names
def test_splitting_sums_to_h_and_each_flow_is_exact(name):
    sys = system(name)
    rng = np.random.default_rng(33)
    y0 = _random_state(name, rng)
    terms = sys.hamiltonian_splitting()
    total = sum(float(term.value(sys, y0)) for term in terms)
    assert abs(total - float(sys.hamiltonian(y0))) < 16 * EPS * max(1.0, abs(total))
    t = 0.6
    B = jax.jit(sys.poisson_tensor)
    for term in terms:
        grad = jax.jit(jax.grad(functools.partial(term.value, sys)))
        sol = scipy.integrate.solve_ivp(
            lambda s, z, grad=grad: np.asarray(B(z) @ grad(z)), (0, t), y0, method="DOP853",
            rtol=1e-13, atol=1e-13,
        )
        got = np.asarray(term.flow(sys, t, y0))
        np.testing.assert_allclose(got, sol.y[:, -1], atol=1e-10, err_msg=term.name)


# -- closed-form test flows against ODE solvers ------------------------------------------------
@system_names
def test_test_flow_matches_dop853(name):
    sys = system(name)
    rng = np.random.default_rng(34)
    for t in (0.0, 0.3, -1.1, 2.0):
        alpha = rng.uniform(-1, 1, sys.dim)
        y0 = _random_state(name, rng)
        ref = solve_ivp_flow(lambda y: reference_tensor(name, sys, y), alpha, t, y0)
        got = np.asarray(sys.test_flow(alpha, t, y0))
        np.testing.assert_allclose(got, ref, atol=1e-11 * max(1.0, np.max(np.abs(ref))))


def _phi_reference(x0, a, t):
    """int_0^t |x0 + a s| ds from the textbook antiderivative of sqrt(z^2 + d^2)
    (Gradshteyn-Ryzhik 2.271.3) in extended precision; for |a t| << |x0| (where that
    difference cancels) its Taylor series |x0| t + (x0.a) t^2/(2|x0|) + |x0 x a|^2 t^3/(6|x0|^3)."""
    x0, a, t = (np.asarray(v, dtype=np.longdouble) for v in (x0, a, t))
    A = np.sqrt(a @ a)
    r0 = np.sqrt(x0 @ x0)
    cross = x0[0] * a[1] - x0[1] * a[0]
    if A * abs(t) < 1e-7 * r0:
        return float(r0 * t + (x0 @ a) * t**2 / (2 * r0) + cross**2 * t**3 / (6 * r0**3))
    c, d = (x0 @ a) / A, abs(cross) / A

    def G(z):
        r = np.sqrt(z * z + d * d)
        return 0.5 * (z * r + (d * d * np.arcsinh(z / d) if d > 0 else 0.0))

    return float((G(c + A * t) - G(c)) / A)


def _phi_quad(x0, a, t):
    """Second opinion by adaptive quadrature, split at the closest approach."""
    a2 = float(a @ a)
    s_star = -float(x0 @ a) / a2 if a2 > 0 else 0.0
    pts = [s_star] if min(0, t) < s_star < max(0, t) else None
    val, _ = scipy.integrate.quad(lambda s: np.linalg.norm(x0 + a * s), 0, t, points=pts, epsabs=1e-13, epsrel=1e-11, limit=200)
    return val


PHI_CASES = {
    "a=0": ([0.5, 1.0], [0.0, 0.0], 1.3),
    "tiny a": ([0.5, 1.0], [1e-12, -3e-12], 1.3),
    "a below the switch": ([0.5, 1.0], [1e-200, 0.0], 1.3),
    "through origin": ([1.0, -0.5], [-1.0, 0.5], 2.0),  # d = 0, crosses at s = 1
    "start at origin": ([0.0, 0.0], [0.3, 0.4], 1.5),
    "parallel away": ([0.6, 0.8], [0.3, 0.4], 1.5),  # d = 0, moving outwards
    "parallel toward, stops short": ([0.6, 0.8], [-0.3, -0.4], 1.0),
    "near miss": ([1.0, 1e-9], [-1.0, 0.0], 2.0),
    "generic": ([0.5, 1.0], [-0.7, 0.2], 3.0),
    "negative time": ([0.5, 1.0], [-0.7, 0.2], -1.0),
    "far": ([30.0, -40.0], [0.1, 0.05], 2.0),
}


@pytest.mark.parametrize("case", list(PHI_CASES))
def test_segment_field_integral_degenerate_cases(case):
    x0, a = (np.asarray(v, dtype=float) for v in PHI_CASES[case][:2])
    t = PHI_CASES[case][2]
    got = float(lp.systems.segment_field_integral(jnp.asarray(x0), jnp.asarray(a), jnp.asarray(t)))
    ref = _phi_reference(x0, a, t)
    assert np.isfinite(got)
    # Phi is a sum of O(|x| t) terms: round-off ~ 16 eps |x| |t|
    assert abs(got - ref) <= 16 * EPS * max(1.0, abs(ref)), (got, ref)
    assert abs(got - _phi_quad(x0, a, t)) <= 1e-10 * max(1.0, abs(ref))


@pytest.mark.parametrize("scale", [0.0, 1e-103, 1e-30, 1e-8, 1e-3])
def test_segment_field_integral_gradient_for_small_a(scale):
    """dPhi/da -> x0 t^2 / (2|x0|) as a -> 0 (Taylor series); dPhi/dx0 -> t x0/|x0|. The
    difference-quotient form lost this to eps |x0|^2 / |a|^2 (NaN or 1e69 at |a| = 1e-103)."""
    x0, t = jnp.array([0.6, -0.8]), jnp.asarray(1.3)
    a = scale * jnp.array([0.3, 0.9])
    ga, gx = jax.grad(lp.systems.segment_field_integral, argnums=(1, 0))(x0, a, t)
    r0 = 1.0
    np.testing.assert_allclose(np.asarray(ga), np.asarray(x0) * float(t) ** 2 / (2 * r0), atol=1e-12 + 2 * scale)
    np.testing.assert_allclose(np.asarray(gx), np.asarray(x0) * float(t) / r0, atol=1e-14 + 2 * scale)


@pytest.mark.parametrize("case", ["a=0", "through origin", "parallel away", "start at origin", "near miss"])
def test_charged_particle_degenerate_test_flows(case):
    """The test flow in degenerate geometries: no NaN, value equal to the quadrature
    reference p(t) = p0 + q b0 Phi (a2, -a1) - beta t, x(t) = x0 + a t; gradients finite
    except at the exact origin crossing."""
    sys = system("ChargedParticle")
    x0, a, t = np.asarray(PHI_CASES[case][0]), np.asarray(PHI_CASES[case][1]), PHI_CASES[case][2]
    p0, beta = np.array([0.4, -0.3]), np.array([0.2, 0.1])
    alpha = np.concatenate([a, beta])
    y0 = np.concatenate([p0, x0])
    got = np.asarray(sys.test_flow(alpha, t, y0))
    qphi = sys.charge * sys.field_strength * _phi_reference(x0, a, t)
    ref = np.concatenate([p0 + qphi * np.array([a[1], -a[0]]) - beta * t, x0 + a * t])
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, atol=1e-12)
    if case in ("a=0", "parallel away", "near miss"):
        J = np.asarray(jax.jacfwd(sys.test_flow, argnums=(0, 2))(jnp.asarray(alpha), t, jnp.asarray(y0))[1])
        assert np.all(np.isfinite(J))


def test_pendulum_special_cases_are_the_papers_T():
    """Paper eq. H_test_solutions: T1 (y1, y2 + a1 t, y3 + 2 t a1 y2 + a1^2 t^2), T2, T3."""
    sys = system("ExtendedPendulum")
    y = np.array([0.4, -0.7, 1.9])
    a, t = 0.8, 1.3
    np.testing.assert_allclose(
        np.asarray(sys.test_flow([a, 0, 0], t, y)), [y[0], y[1] + a * t, y[2] + 2 * t * a * y[1] + a**2 * t**2], atol=8 * EPS
    )
    np.testing.assert_allclose(
        np.asarray(sys.test_flow([0, a, 0], t, y)), [y[0] - a * t, y[1], y[2] - 2 * t * a * y[0] + a**2 * t**2], atol=8 * EPS
    )
    w = 2 * a * t
    rot = [np.cos(w) * y[0] - np.sin(w) * y[1], np.sin(w) * y[0] + np.cos(w) * y[1], y[2]]
    np.testing.assert_allclose(np.asarray(sys.test_flow([0, 0, a], t, y)), rot, atol=8 * EPS)
    # alpha -> 0 and zero time: identity
    # r is rebuilt as C + u^2 + v^2: identity up to one rounding of r
    np.testing.assert_allclose(np.asarray(sys.test_flow([0, 0, 0], t, y)), y, rtol=0, atol=4 * EPS * y[2])
    np.testing.assert_allclose(np.asarray(sys.test_flow([1e-12, 0, 1e-12], t, y)), y, atol=1e-11)


# -- heyoka right-hand side --------------------------------------------------------------------
# the rigid body by default; the others with -m slow (their heyoka ground truth against Strang by
# default in test_integrators_splitting.py)
@pytest.mark.parametrize("name", slow_except(SYSTEMS, {"RigidBody"}))
def test_heyoka_rhs_equals_vector_field(name):
    sys = system(name)
    pairs = sys.heyoka_system()
    assert len(pairs) == sys.dim
    variables = [v for v, _ in pairs]
    cf = hy.cfunc([rhs for _, rhs in pairs], variables)
    rng = np.random.default_rng(35)
    ys = np.array([_random_state(name, rng) for _ in range(8)])
    got = np.asarray(cf(np.ascontiguousarray(ys.T))).T
    ref = np.asarray(sys.vector_field(ys))
    np.testing.assert_allclose(got, ref, rtol=0, atol=32 * EPS * np.max(np.abs(ref)))


# -- batching, jit, vmap, grad; registry -------------------------------------------------------
# the rigid body (so(3)) by default; the rest with -m slow (the charged particle's test flow and its
# Jacobian by default in test_charged_particle_degenerate_test_flows)
@pytest.mark.parametrize("name", slow_except(SYSTEMS, {"RigidBody"}))
def test_system_batching_and_transformations(name):
    sys = system(name)
    rng = np.random.default_rng(36)
    ys = np.array([[_random_state(name, rng) for _ in range(3)] for _ in range(2)])
    alphas = rng.uniform(-1, 1, ys.shape)
    for fn, shape in [
        (sys.hamiltonian, (2, 3)),
        (sys.vector_field, (2, 3, sys.dim)),
        (sys.poisson_tensor, (2, 3, sys.dim, sys.dim)),
        (sys.casimirs, (2, 3, sys.n_casimirs)),
    ]:
        assert fn(ys).shape == shape
    vf = np.asarray(sys.vector_field(ys))
    np.testing.assert_allclose(vf[1, 2], np.asarray(sys.vector_field(ys[1, 2])), atol=8 * EPS * np.max(np.abs(vf)))
    c = np.asarray(sys.casimirs(ys))
    np.testing.assert_allclose(c[1, 2], np.asarray(sys.casimirs(ys[1, 2])), atol=8 * EPS * max(1.0, np.max(np.abs(c), initial=0)))
    np.testing.assert_allclose(np.asarray(jax.vmap(sys.vector_field)(ys[0])), vf[0], atol=8 * EPS * np.max(np.abs(vf)))
    flows = np.asarray(sys.test_flow(alphas, 0.4, ys))
    assert flows.shape == ys.shape
    np.testing.assert_allclose(flows[1, 0], np.asarray(sys.test_flow(alphas[1, 0], 0.4, ys[1, 0])), atol=1e-14)
    # jit, vmap and grad together: energy after a test flow, d/dalpha against central differences
    vg = jax.jit(jax.vmap(jax.value_and_grad(lambda a, y: sys.hamiltonian(sys.test_flow(a, 0.4, y)))))
    h = 1e-6
    steps = np.concatenate([np.zeros((1, sys.dim)), h * np.eye(sys.dim), -h * np.eye(sys.dim)])
    values, grads = vg(alphas[0, 0] + steps, np.broadcast_to(ys[0, 0], steps.shape))
    values = np.asarray(values)
    np.testing.assert_allclose(values[0], float(sys.hamiltonian(flows[0, 0])), atol=1e-13)
    fd = (values[1 : 1 + sys.dim] - values[1 + sys.dim :]) / (2 * h)
    np.testing.assert_allclose(np.asarray(grads[0]), fd, atol=1e-7)


@system_names
def test_registry_round_trip(name):
    sys = system(name)
    again = lp.systems.from_name(sys.name, sys.params)
    y = _random_state(name, np.random.default_rng(37))
    np.testing.assert_array_equal(np.asarray(again.vector_field(y)), np.asarray(sys.vector_field(y)))
    assert repr(again) == repr(sys)


def test_systems_described_by_their_params_are_equal_by_value_so_compiled_code_is_shared():
    import pickle

    from liepoisson.systems import LiePoissonSystem, RigidBody

    a, b, c = RigidBody(inertia=(1.0, 2.0, 3.0)), RigidBody(inertia=(1.0, 2.0, 3.0)), RigidBody(inertia=(1.0, 2.0, 4.0))
    assert a == b and hash(a) == hash(b) and a != c
    assert pickle.loads(pickle.dumps(a)) == a  # a copy on a Dask worker finds a's compiled code
    assert a != lp.systems.Kirchhoff()
    g = lp.so3()

    def H(m, xp):
        return 0.5 * (m[0] ** 2 + m[1] ** 2 / 2 + m[2] ** 2 / 3)

    u, v = LiePoissonSystem(g, H, name="u"), LiePoissonSystem(g, H, name="u")
    assert u == v and hash(u) == hash(v)
    assert u != LiePoissonSystem(g, H, name="other name")
    assert u != LiePoissonSystem(g, lambda m, xp: H(m, xp) + m[0], name="u")

    class Opaque(RigidBody):  # a subclass that opts out: equal only to itself
        def value_key(self):
            return None

    o = Opaque(inertia=(1.0, 2.0, 3.0))
    assert o == o  # noqa: PLR0124 (an opaque system equals itself: identity)
    assert o != Opaque(inertia=(1.0, 2.0, 3.0)) and o != a


@system_names
def test_capabilities_are_classes(name):
    """A closed-form solution and dissipation are abstract classes a system is an instance of:
    the rigid body is exactly solvable, the double-bracket systems are dissipative, and the
    splitting methods and `ExactFlow` decide by `isinstance`."""
    import integrators as it
    from liepoisson.systems import AbstractDissipativeSystem, AbstractExactlySolvableSystem

    s = system(name)
    assert isinstance(s, AbstractExactlySolvableSystem) == (name == "RigidBody")
    assert not isinstance(s, AbstractDissipativeSystem)
    if isinstance(s, AbstractExactlySolvableSystem):
        np.testing.assert_array_equal(np.asarray(it.ExactFlow(s, 0.1).step(np.array([0.3, -1.1, 0.8]))),
                                      np.asarray(s.exact_flow(0.1, np.array([0.3, -1.1, 0.8]))))
    else:
        with pytest.raises(TypeError, match="AbstractExactlySolvableSystem"):
            it.ExactFlow(s, 0.1)


def test_a_method_named_exact_flow_is_not_the_capability():
    """A system with a method `exact_flow` but not of the class is refused; the class is the
    capability, and a damped system is dissipative whatever it wraps."""
    import integrators as it
    from liepoisson.systems import AbstractDissipativeSystem, DoubleBracket, RigidBody

    class Kirchhoff(lp.systems.Kirchhoff):
        def exact_flow(self, t, y):
            return y

    with pytest.raises(TypeError, match="AbstractExactlySolvableSystem"):
        it.ExactFlow(Kirchhoff(), 0.1)
    damped = DoubleBracket(RigidBody(), 0.1)
    assert isinstance(damped, AbstractDissipativeSystem)
    with pytest.raises(ValueError, match="dissipative"):
        it.splitting.Strang(damped, 0.1)
