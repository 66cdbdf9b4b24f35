"""Bad input found by a held-out battery, each refused with a message naming the argument:
matrix algebras too large to build, tolerances of the isospectral stage iteration,
quaternions given scalar first, the named nonholonomic systems' arguments."""

import time

import numpy as np
import pytest

import liepoisson as lp
import liepoisson._memory
from liepoisson._matrix_algebra import FAMILIES, SEMIDIRECT, MatrixLieAlgebra

# -- matrix algebras too large for the machine ---------------------------------------------------
_CONSTRUCTORS = {"so": lp.so, "u": lp.u, "su": lp.su, "sp": lp.sp, "gl": lp.gl, "sl": lp.sl, "se": lp.se}


@pytest.mark.parametrize("family", [*_CONSTRUCTORS, "Zeitlin"])
def test_too_large_an_algebra_is_refused_at_once(family):
    build = lp.systems.Zeitlin if family == "Zeitlin" else _CONSTRUCTORS[family]
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"^N: .* at N = 1,000,000 .* would need .* GiB .* available to one "
                                         r"request .*; give N <= [0-9,]+ for"):
        build(10**6)
    assert time.perf_counter() - t0 < 0.5  # the size is checked from a closed form, nothing is built
    with pytest.raises(ValueError, match="^N: "):  # any integer: the check does not overflow
        build(10**400)


@pytest.mark.parametrize("family", sorted(SEMIDIRECT.values()))
def test_too_large_a_semidirect_product_is_refused(family, monkeypatch):
    small = MatrixLieAlgebra(family, 3)
    monkeypatch.setattr(liepoisson._memory, "physical_memory", lambda: (1000, True))  # after small is built
    with pytest.raises(ValueError, match=r"^algebra: .* at N = 3 .* would need"):
        lp.semidirect(small)


@pytest.mark.parametrize("family", FAMILIES)
def test_the_largest_size_said_to_fit_is_built(family, monkeypatch):
    # 4 MiB of "physical memory": the N the message offers is built, one more is refused
    monkeypatch.setattr(liepoisson._memory, "physical_memory", lambda: (2**22, True))
    with pytest.raises(ValueError, match="give N <= ") as info:
        MatrixLieAlgebra(family, 10**4)
    largest = int(str(info.value).rsplit("give N <= ", 1)[1].split()[0].replace(",", ""))
    g = MatrixLieAlgebra(family, largest)
    assert g.N == largest
    with pytest.raises(ValueError, match=f"^N: {family}\\(N\\) at N = {largest + 1:,} "):
        MatrixLieAlgebra(family, largest + 1)


# -- the isospectral stage iteration's relative tolerance -----------------------------------------
@pytest.mark.parametrize("tol", [1.0, 10, 1e300])
def test_stage_tolerance_must_be_below_one(tol):
    import integrators as it
    import learn

    body = lp.systems.GeneralizedRigidBody((1.0, 1.3, 1.9, 2.6))
    for build in (lambda: it.IsospectralMidpoint(body, 0.1, tol=tol), lambda: it.IsospectralTripleJump(body, 0.1, tol=tol),
                  lambda: learn.IsospectralPolynomial(body, h=0.1, tol=tol)):
        with pytest.raises(ValueError, match=r"^tol must be in \(0, 1\): .* got "):
            build()
    # a small tolerance is taken as it is
    assert it.IsospectralMidpoint(body, 0.1, tol=0.5).tol == 0.5
    assert learn.IsospectralPolynomial(body, h=0.1, tol=1e-14).tol == 1e-14


# -- the named nonholonomic systems: every error names the user's argument --------------------------
@pytest.mark.parametrize(("a", "error", "message"), [
    ((0.0, 0.0, 0.0), ValueError, r"^a must be a non-zero body vector .* which is zero"),
    ((1e200, 1e200, 0.0), ValueError, r"^a must be a non-zero body vector .* squared length is beyond float64"),
    ((1e-300, 0.0, 0.0), ValueError, r"^a must be a non-zero body vector"),
    ((1.0, 2.0), ValueError, r"^a must have shape \(3,\); got shape \(2,\)"),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], ValueError, r"^a must have shape \(3,\); got shape \(2, 3\)"),
    (np.eye(3), ValueError, r"^a must have shape \(3,\)"),
    ((1.0, np.nan, 0.0), ValueError, r"^a must be finite"),
    ("x", TypeError, r"^a must be 3 real numbers"),
    ([1j, 0.0, 0.0], TypeError, r"^a must be 3 real numbers"),
    (None, ValueError, r"^a must have shape \(3,\)"),
])
def test_suslov_errors_name_a(a, error, message):
    with pytest.raises(error, match=message):
        lp.systems.suslov(a=a)


@pytest.mark.parametrize(("inertia", "error"), [((1.0, -2.0, 3.0), ValueError), ((1.0, 2.0), ValueError),
                                                ("x", TypeError)])
def test_suslov_errors_name_inertia(inertia, error):
    with pytest.raises(error, match="^inertia must"):
        lp.systems.suslov(inertia=inertia)


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"a": None}, TypeError, r"^a must be a real number .* got NoneType None"),
    ({"a": 1j}, TypeError, r"^a must be a real number .* got complex 1j"),
    ({"a": np.array(1 + 0j)}, TypeError, r"^a must be a real number"),
    ({"a": True}, TypeError, r"^a must be a real number"),
    ({"a": [1.0]}, TypeError, r"^a must be a real number"),
    ({"a": np.inf}, ValueError, r"^a must be finite"),
    ({"mass": 0.0}, ValueError, r"^mass must be finite and > 0"),
    ({"mass": None}, TypeError, r"^mass must be a positive real number"),
    ({"inertia": -1.0}, ValueError, r"^inertia must be finite and > 0"),
    # overflow of the inverse mass matrix: named, not a failure deep inside the Hamiltonian
    ({"a": 1e200}, ValueError, r"^mass = 1.0, inertia = 1.0 and a = 1e\+200 give an inverse mass matrix beyond"),
    ({"mass": 1e300, "inertia": 1e-300, "a": 1e300}, ValueError, r"^mass = 1e\+300, inertia = 1e-300 and a = 1e\+300"),
])
def test_chaplygin_sleigh_errors_name_the_argument(kwargs, error, message):
    with pytest.raises(error, match=message):
        lp.systems.chaplygin_sleigh(**kwargs)


def test_chaplygin_sleigh_velocity_from_its_momentum():
    # xi = M^{-1} mu with M^{-1} in closed form: to round-off of mu's own size, also where
    # mass a^2 dwarfs inertia
    for m, inertia, a in ((1.0, 1.0, 0.5), (2.0, 0.7, -0.3), (1.0, 1.0, 100.0)):
        sleigh = lp.systems.chaplygin_sleigh(m, inertia, a)
        M = np.array([[inertia + m * a * a, 0.0, m * a], [0.0, m, 0.0], [m * a, 0.0, m]])
        xi = np.array([0.3, -0.2, 0.0])  # admissible: no sideways velocity
        mu = M @ xi
        np.testing.assert_allclose(np.asarray(sleigh.hamiltonian_gradient(mu)), xi, rtol=0,
                                   atol=16 * np.finfo(float).eps * np.abs(mu).max() * max(1.0, a * a))
    for arg in (np.float32(0.5), np.array(0.5), np.int64(1)):  # NumPy scalars are real numbers
        lp.systems.chaplygin_sleigh(a=arg)


# -- quaternions given scalar first ---------------------------------------------------------------
def _observed(system, g0, noise):
    import integrators as it

    n = g0.shape[0]
    y0 = np.random.default_rng(0).normal(size=(n, system.dim))
    return it.observe_body(system, y0 / np.linalg.norm(y0, axis=1, keepdims=True), g0,
                           it.uneven_times(n, 21, (0.05, 0.3), seed=2), noise=noise, seed=3)


def _scalar_first(q):
    return np.concatenate([q[:, 3:4], q[:, :3], q[:, 4:]], axis=1)  # (x, y, z, w, ...) -> (w, x, y, z, ...)


@pytest.mark.parametrize("noise", [0.0, 1e-3, 1e-2])
@pytest.mark.parametrize("vehicle", [False, True], ids=["attitudes", "poses"])
def test_quaternions_given_scalar_first_are_refused(noise, vehicle):
    from scipy.spatial.transform import Rotation

    import integrators as it

    system = lp.systems.Kirchhoff() if vehicle else lp.systems.RigidBody((2.0, 1.0, 2.0 / 3.0))
    q0 = Rotation.random(4, random_state=1).as_quat()
    g0 = np.concatenate([q0, np.zeros((4, 3))], axis=1) if vehicle else q0
    obs = _observed(system, g0, noise)  # built by BodyObservations: correct data pass, exact or noisy
    again = it.BodyObservations(system, obs.times, obs.configurations, obs.velocities)
    assert len(again) == 4
    wrong = [_scalar_first(g) for g in obs.configurations]
    convert = r"g\[:, \[1, 2, 3, 0, 4, 5, 6\]\]" if vehicle else r"np\.roll\(q, -1, axis=-1\)"
    with pytest.raises(ValueError, match=r"^configurations look like quaternions given scalar first, \(w, x, y, z\): "
                                         rf"read scalar last.* by \d+% .* read scalar first by \d+%\. Convert them "
                                         rf"with {convert}"):
        it.BodyObservations(system, obs.times, wrong, obs.velocities)
    # as the message says: converted back, they pass (and are the attitudes given)
    fixed = [np.roll(g[:, :4], -1, axis=-1) for g in wrong] if not vehicle else [g[:, [1, 2, 3, 0, 4, 5, 6]]
                                                                                  for g in wrong]
    back = it.BodyObservations(system, obs.times, fixed, obs.velocities)
    np.testing.assert_array_equal(np.concatenate(back.configurations), np.concatenate(obs.configurations))
    # either alone cannot be compared: taken as given
    it.BodyObservations(system, obs.times, wrong)


def test_noise_that_swamps_the_motion_trips_nothing():
    from scipy.spatial.transform import Rotation

    import integrators as it

    system = lp.systems.RigidBody((2.0, 1.0, 2.0 / 3.0))
    times = it.uneven_times(4, 21, (0.001, 0.002), seed=2)  # 1-2 mrad a step, 0.5 rad of attitude noise
    y0 = np.random.default_rng(0).normal(size=(4, 3))
    obs = it.observe_body(system, y0, Rotation.random(4, random_state=1).as_quat(), times, noise=0.5, seed=3)
    for configurations in (obs.configurations, [_scalar_first(g) for g in obs.configurations]):
        it.BodyObservations(system, obs.times, configurations, obs.velocities)
