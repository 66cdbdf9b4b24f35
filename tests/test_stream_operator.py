"""learn.StreamOperator and its spectra; liepoisson.internals.harmonic_multiplier."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import learn
from integrators import IsospectralMidpoint
from integrators.splitting import BlanesMoan4, LieTrotter, Strang, Suzuki, Yoshida6
from liepoisson._quantized_sphere import (
    harmonics_to_matrix,
    laplacian,
    matrix_to_harmonics,
    solve_poisson,
)
from liepoisson.internals import harmonic_multiplier
from liepoisson.systems import RigidBody, Zeitlin

EPS = np.finfo(np.float64).eps


def _degrees(N):
    return np.floor(np.sqrt(np.arange(N * N) + 0.5))


@pytest.mark.parametrize("N", [1, 2, 3, 5, 8, 16])  # 5: groups of diagonals of unequal sizes
def test_harmonic_multiplier_against_the_coefficients(N):
    rng = np.random.default_rng(N)
    omega, mu = rng.normal(size=N * N), rng.normal(size=N * N)
    W = harmonics_to_matrix(omega, N)
    out = np.asarray(harmonic_multiplier(W, mu))
    # reference: the coefficients multiplied and mapped back by the numpy per-diagonal loop
    reference = harmonics_to_matrix(mu * omega, N)
    # two transforms by orthogonal bases scaled by sqrt(N): a few eps per entry, times N
    assert np.max(np.abs(out - reference)) <= 16 * N * EPS * np.max(np.abs(reference))
    assert np.max(np.abs(out + out.conj().T)) == 0.0  # skew-Hermitian by construction


@pytest.mark.parametrize("N", [5, 16])
def test_harmonic_multiplier_gradients_in_the_field_and_the_multiplier(N):
    # the operator is self-adjoint in <A, B> = Re tr(A^dagger B) (real eigenvalues, orthogonal
    # harmonics), so the gradient of x -> <L W(x), V> is that of x -> <W(x), L V>, where the
    # second differentiates no product of harmonic_multiplier: its reverse pass (JAX's transposes
    # of the grouped products, or any hand-written one later) checked against its forward pass
    system = Zeitlin(N)
    rng = np.random.default_rng(N)
    x, mu = jnp.asarray(rng.normal(size=N * N)), jnp.asarray(rng.normal(size=N * N))
    V = jnp.asarray(harmonics_to_matrix(rng.normal(size=N * N), N))
    LV = harmonic_multiplier(V, mu)

    def through(x):
        return jnp.real(jnp.sum(jnp.conj(harmonic_multiplier(system.algebra.matrix(x), mu)) * V))

    def around(x):
        return jnp.real(jnp.sum(jnp.conj(system.algebra.matrix(x)) * LV))

    g, reference = np.asarray(jax.grad(through)(x)), np.asarray(jax.grad(around)(x))
    # two transforms by bases scaled by sqrt(N) each way: a few eps per entry, times N
    assert np.max(np.abs(g - reference)) <= 16 * N * EPS * np.max(np.abs(reference))
    # the gradient in the multiplier (what a learned spectrum moves): <L_mu W, V> is linear in
    # mu, its i-th component that of the coefficient omega_i alone, mapped by numpy's loop
    W = system.algebra.matrix(x)
    g_mu = np.asarray(jax.grad(lambda m: jnp.real(jnp.sum(jnp.conj(harmonic_multiplier(W, m)) * V)))(mu))
    omega = matrix_to_harmonics(np.asarray(W))
    coefficients = np.array([np.real(np.sum(np.conj(harmonics_to_matrix(np.where(np.arange(N * N) == i, omega, 0.0), N))
                                            * np.asarray(V))) for i in range(N * N)])
    assert np.max(np.abs(g_mu - coefficients)) <= 16 * N * EPS * np.max(np.abs(coefficients))


@pytest.mark.parametrize("N", [3, 8, 16])
def test_harmonic_multiplier_inverts_the_laplacian(N):
    W = harmonics_to_matrix(np.random.default_rng(1).normal(size=N * N), N)
    l = _degrees(N)
    inverse = np.where(l > 0, -1.0 / np.maximum(l * (l + 1), 1.0), 0.0)
    P = np.asarray(harmonic_multiplier(W, inverse))
    reference = np.asarray(solve_poisson(W))  # the tridiagonal solve: no shared code
    # the tridiagonal solve's own round-off grows with N^2 (its pivots up to N^2): 64 N^2 eps
    assert np.max(np.abs(P - reference)) <= 64 * N * N * EPS * np.max(np.abs(reference))


def test_quasi_geostrophic_stream_against_a_dense_solve():
    N, F = 6, 10.0
    system = Zeitlin(N)
    model = learn.StreamOperator(system, learn.QuasiGeostrophicSpectrum(F), h=0.1)
    W = harmonics_to_matrix(np.random.default_rng(2).normal(size=N * N), N)
    # (Delta_N - F) as a dense N^2 x N^2 complex matrix from the entrywise Laplacian
    basis = np.eye(N * N).reshape(N * N, N, N)
    L = np.stack([np.asarray(laplacian(E)).reshape(-1) for E in basis], axis=1) - F * np.eye(N * N)
    P = np.linalg.solve(L, W.reshape(-1)).reshape(N, N)
    P -= np.trace(P) / N * np.eye(N)  # the multiples of 1 commute with W: the model drops them
    out = np.asarray(model.stream_matrix(W))
    assert np.max(np.abs(out - P)) <= 64 * N * EPS * np.max(np.abs(P))


@pytest.mark.slow  # moved from the default run for its 4-minute budget (3-7 s on 2 quiet workers)
def test_at_the_laplacian_it_is_zeitlins_model():
    N = 8
    system = Zeitlin(N)
    y0 = system.random_state(1, decay=0.0)
    model = learn.StreamOperator(system, h=0.05, tol=1e-13, iterations=12)
    reference = IsospectralMidpoint(system, 0.05, tol=1e-13)
    a, b = model.rollout(y0, 20), reference.rollout(y0, 20)
    # both stage iterations meet tol 1e-13 of ||W||: the two maps agree to that, 20 steps
    assert np.max(np.abs(a - b)) <= 20 * 1e-13 * np.max(np.abs(b))
    assert np.max(np.abs(b[-1] - b[0])) > 0.1  # the field moved
    intervals = jnp.full(20, 0.05)
    c = eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))(model, jnp.asarray(y0), intervals)
    assert np.max(np.abs(np.asarray(c) - a)) <= 20 * 1e-13 * np.max(np.abs(b))


@pytest.mark.parametrize("composition", [None, Yoshida6])
def test_casimirs_of_the_absolute_vorticity_are_kept_for_any_parameters(composition):
    N = 8
    system = Zeitlin(N)
    rng = np.random.default_rng(3)
    spectrum = learn.DegreeSpectrum(-np.arange(1, N) * (np.arange(1, N) + 1.0) * rng.uniform(0.5, 2.0, N - 1))
    model = learn.StreamOperator(system, spectrum, rotation=0.7, composition=composition, tol=1e-12, iterations=10)
    y0 = system.random_state(4, decay=0.0)
    intervals = jnp.asarray(rng.uniform(0.02, 0.08, 50))
    ys = np.asarray(eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))(model, jnp.asarray(y0), intervals))
    assert np.all(np.isfinite(ys))
    f = 0.7 * learn.planetary_vorticity(N)
    q0, q1 = (np.asarray(system.algebra.matrix(y)) + f for y in (ys[0], ys[-1]))
    assert np.linalg.norm(q1 - q0) > 0.1 * np.linalg.norm(q0)  # it moved
    e0, e1 = np.linalg.eigvalsh(1j * q0), np.linalg.eigvalsh(1j * q1)
    for k in range(1, N + 1):
        scale = np.sum(np.abs(e0) ** k)
        # tr(iq)^k from the spectrum; each step a unitary conjugation adds a rounding of a few
        # eps of |q| to q: 50 steps, a random walk of them, times k (the k-th power): 1e-13
        assert abs(np.sum(e1**k) - np.sum(e0**k)) <= 1e-13 * scale, k
    # the relative vorticity's spectrum is not kept on a rotating sphere: the term matters
    w0, w1 = np.linalg.eigvalsh(1j * (q0 - f)), np.linalg.eigvalsh(1j * (q1 - f))
    assert np.max(np.abs(w1 - w0)) > 1e-6 * np.max(np.abs(w0))


@pytest.mark.slow  # eight rollout programs compiled (three compositions, two step counts each): 34 s of the default run's ~480 s CPU
def test_orders_against_heyoka():
    """No composition, `Suzuki` and `Yoshida6` converge at their orders 2, 4 and 6 to the exact flow (heyoka's Taylor method at
    machine precision, an independent reference); a rollout at uneven intervals equals the
    inherited `step` at equal ones."""
    from integrators import ground_truth

    N, T = 6, 0.4
    system = Zeitlin(N)
    y0 = system.random_state(2, decay=0.0)
    exact = ground_truth(system, y0, T, 1, progress=False).states[0, -1]
    roll = eqx.filter_jit(lambda m, y, d, n: m.rollout_intervals(y, d, n))  # n: a Python int, static
    for composition, rate in ((None, 4.0), (Suzuki, 16.0), (Yoshida6(), 64.0)):
        model = learn.StreamOperator(system, composition=composition, tol=1e-14, iterations=20)
        # two uneven intervals, run in n and 2n steps each
        errors = [np.linalg.norm(np.asarray(roll(model, jnp.asarray(y0), jnp.asarray([0.15, T - 0.15]), n))[-1] - exact)
                  for n in (2, 4)]
        # the error of a method of order p falls 2^p-fold when h halves; h is small enough
        # (h |B| ~ 0.05-0.1) for the leading term to dominate to within 25%
        assert 0.75 * rate <= errors[0] / errors[1] <= 1.25 * rate, (composition, errors)
        assert errors[1] <= 1e-3 * np.linalg.norm(exact)
    model = learn.StreamOperator(system, composition="Suzuki", h=0.05, tol=1e-14, iterations=20)
    steps = np.asarray(model.rollout(y0, 6))
    intervals = np.asarray(roll(model, jnp.asarray(y0), jnp.full(6, 0.05), 1))
    # both iterate every stage to 1e-14 of |W|, from different starts: they agree to that, 6 x 5 midpoints
    assert np.max(np.abs(steps - intervals)) <= 30 * 1e-14 * np.max(np.abs(steps))


def test_gauge():
    N = 8
    l = np.arange(1, N)
    qg = -(l * (l + 1.0)) - 10.0
    moved = learn.in_gauge(qg, 0, -2.0)
    assert moved[0] == -2.0
    # the same flow: the inverse eigenvalues differ by one constant
    assert np.ptp(1 / moved - 1 / qg) <= 8 * EPS
    spectrum = learn.DegreeSpectrum(qg)
    assert np.array_equal(spectrum.values(), qg)
    assert spectrum.inverse_values.shape == (N - 2,)  # the reference degree is not learned


def test_the_gauge_is_no_symmetry_on_a_rotating_sphere():
    # dW/dt = [psi, W + Omega f]/hbar: adding kappa to every inverse eigenvalue adds
    # kappa [W, W + Omega f]/hbar = kappa Omega [W, f]/hbar, zero only without rotation
    N, kappa, h = 6, 0.03, 1e-5
    system = Zeitlin(N)
    y = jnp.asarray(system.random_state(3))
    l = np.arange(1, N)
    lam = -(l * (l + 1.0))
    shifted = 1.0 / (1.0 / lam + kappa)
    W, f = system.algebra.matrix(y), jnp.asarray(learn.planetary_vorticity(N))
    for rotation in (None, 0.7):
        a, b = (learn.StreamOperator(system, learn.DegreeSpectrum(s), rotation=rotation, h=h, iterations=12)
                for s in (lam, shifted))
        rate = (np.asarray(b.step(y)) - np.asarray(a.step(y))) / h
        if rotation is None:
            # the same flow: the midpoint tells them apart at O(h^2) only (the module docstring)
            assert np.max(np.abs(rate)) <= 1e-6 * np.max(np.abs(y))
        else:
            expected = np.asarray(system.algebra.coordinates(kappa * rotation * (W @ f - f @ W) / system.hbar))
            # the steps differ by h times the rate plus O(h^2): a relative 1e-3 is ~100 h
            np.testing.assert_allclose(rate, expected, rtol=0, atol=1e-3 * np.max(np.abs(expected)))
            assert np.max(np.abs(expected)) > 1e-2 * np.max(np.abs(y))  # a turning the data see


def test_bad_input():
    system = Zeitlin(4)
    with pytest.raises(TypeError, match="system must be liepoisson.systems.Zeitlin"):
        learn.StreamOperator(RigidBody())
    with pytest.raises(ValueError, match=r"spectrum must hold 3 eigenvalues \(degrees 1..3\) for N = 4; got 2"):
        learn.StreamOperator(system, learn.DegreeSpectrum([-2.0, -6.0]))
    with pytest.raises(ValueError, match=r"values must be finite and nonzero.*values\[1\] = nan"):
        learn.DegreeSpectrum([-2.0, np.nan, -12.0])
    with pytest.raises(ValueError, match=r"values must be finite and nonzero.*values\[0\] = 0"):
        learn.DegreeSpectrum([0.0, -6.0, -12.0])
    with pytest.raises(TypeError, match="spectrum must be a learn.AbstractSpectrum"):
        learn.StreamOperator(system, "per-degree")
    with pytest.raises(TypeError, match="rotation must be None or a real number"):
        learn.StreamOperator(system, rotation=True)
    with pytest.raises(ValueError, match="rotation must be finite"):
        learn.StreamOperator(system, rotation=float("inf"))
    for composition in (4, True, Strang, LieTrotter(), BlanesMoan4):  # not a composition of midpoints
        with pytest.raises(TypeError, match=r"composition must be None \(the isospectral midpoint\) or a composition"):
            learn.StreamOperator(system, composition=composition)
    with pytest.raises(ValueError, match="composition: unknown splitting method 'Suzuki4'; known: LieTrotter, "):
        learn.StreamOperator(system, composition="Suzuki4")
    with pytest.raises(ValueError, match="composition composes one step .* takes no ordering"):
        learn.StreamOperator(system, composition=Suzuki(ordering=(0,)))
    with pytest.raises(ValueError, match="F must be finite and > -2"):
        learn.QuasiGeostrophicSpectrum(-3.0)
    with pytest.raises(ValueError, match="reference must be an index of values"):
        learn.DegreeSpectrum([-2.0, -6.0, -12.0], reference_degree=4)


def test_rollout_refuses_bad_arguments_and_a_step_its_stage_iteration_cannot_take():
    system = Zeitlin(4)
    model = learn.StreamOperator(system)
    y0 = np.asarray(system.random_state(0))  # |y0| = 2
    with pytest.raises(ValueError, match=r"y0 must have shape \(\.\.\., 16\).*got shape \(15,\)"):
        model.rollout_intervals(np.ones(15), [0.1])
    with pytest.raises(ValueError, match=r"y0 must be one state of shape \(16,\); got shape \(2, 16\)"):
        model.rollout_intervals(np.ones((2, 16)), [0.1])
    with pytest.raises(ValueError, match="y0 must be finite"):
        model.rollout_intervals(np.full(16, np.nan), [0.1])
    with pytest.raises(ValueError, match=r"intervals must have shape \(n,\).*got shape \(1, 1\)"):
        model.rollout_intervals(y0, [[0.1]])
    for bad in (-0.1, np.inf, np.nan):
        with pytest.raises(ValueError, match="intervals must be finite and >= 0.* at index 1"):
            model.rollout_intervals(y0, [0.01, bad])
    with pytest.raises(TypeError, match="intervals must be an array"):
        model.rollout_intervals(y0, "0.1")
    # four stage iterations do not reach tol at a step of 0.1 from this field (the same call
    # returned NaN before it was checked); six do, and so do four at ten substeps
    with pytest.raises(ValueError, match=r"did not meet tol=1e-10 in iterations=4 in interval 1 \(of length 0\.1, "
                                         r"1 substep\(s\)\).*give more substeps"):
        model.rollout_intervals(y0, [0.01, 0.1])
    for ok in (learn.StreamOperator(system, iterations=6).rollout_intervals(y0, [0.01, 0.1]),
               model.rollout_intervals(y0, [0.01, 0.1], 10)):
        assert np.all(np.isfinite(np.asarray(ok)))


def test_hamiltonian_is_zeitlins_at_the_laplacian():
    N = 6
    system = Zeitlin(N)
    model = learn.StreamOperator(system, h=0.1)
    y = system.random_state(5)
    # at the Laplacian's spectrum the energy is Zeitlin's (the pairing's normalisation)
    assert abs(float(model.hamiltonian(y)) - float(system.hamiltonian(y))) <= 64 * EPS * float(system.hamiltonian(y))


def test_save_and_load(tmp_path):
    N = 6
    values = -np.arange(1, N) * (np.arange(1, N) + 1.0) - 3.0
    model = learn.StreamOperator(Zeitlin(N), learn.DegreeSpectrum(values, reference_degree=2), rotation=0.3,
                                 composition=Suzuki, h=0.05, iterations=7)
    model.save(tmp_path / "m.h5")
    loaded = learn.StreamOperator.load(tmp_path / "m.h5")
    assert np.array_equal(loaded.spectrum.values(), model.spectrum.values())
    assert loaded.spectrum.reference == 1 and float(loaded.rotation) == 0.3
    assert loaded.iterations == 7 and loaded.h == 0.05 and loaded.composition == Suzuki()
    # a file of 527b794..9644ff9 named the composition by its order
    hp = {**model.hyperparameters(), "order": 6}
    del hp["composition"]
    assert learn.StreamOperator.from_hyperparameters(Zeitlin(N), hp).composition == Yoshida6()
