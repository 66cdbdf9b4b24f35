"""Learning from observations: noisy, regularly or unevenly sampled trajectories of a system
whose Hamiltonian the learner is not given.

    python -m benchmarks.observations [--systems rigid_body kirchhoff] [--noise 0 1e-3 1e-2]
        [--sampling regular uneven] [--models glpnet limit sindy] [--data-seed 1] [--seed 0]
        [--out benchmarks/results/observations.json]

Protocols (the issue's):

- `rigid_body`: I = (2, 1, 2/3); 30 trajectories x 21 observations from initial states on
  |Pi| = 1; 12 held-out initial conditions on the sphere.
- `kirchhoff`: the paper's E5 body (inertia and mass (1, 2, 1)); 40 trajectories x 21
  observations from [-1, 1]^6; 12 held-out initial conditions from the same cube.

Sampling: `regular` h = 0.1, or `uneven` steps drawn from [0.05, 0.3] (`integrators.uneven_times`).
Noise: Gaussian, standard deviation `noise` times the RMS size of the states
(`integrators.observe`). Every model is rolled out 1000 steps of 0.1 (t = 100) from the held-out
initial conditions and compared with heyoka: mean state error at t = 100, max relative energy
error (true H) over the rollout, Casimir drift (max |C(t) - C(0)| over |grad C| |y|), fit time.

Models, all fitted to the same observations:

- `glpnet`: `learn.fit_splitting(system, observations)`: a TripleJump G-LPNet, one module
  per basis direction, fitted by trajectory least squares with the initial states (errors in
  variables); the family of its learned Hamiltonian (quadratic even, quadratic, general)
  chosen by the Bayesian information criterion.
- `limit`: the true model family (`learn.ParametricHamiltonian`: the diagonal quadratic
  Hamiltonian with unknown coefficients, RK4 with 10 sub-steps) fitted by trajectory least
  squares with the initial states: what the data allow at best.
- `sindy`: SINDy (pysindy, extra `peers`: polynomial library of degree 2, STLSQ with its
  defaults), derivatives by pysindy's smoothed finite differences on the observation times
  (plain finite differences do 12x worse at noise 1e-3: BENCHMARKS.md), its ODE integrated
  by LSODA (tolerance 1e-12, as `SINDy.simulate`).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from typing import Any

import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from benchmarks._report import default_out, write_json

H_TEST, STEPS_TEST = 0.1, 1000


def _sphere(n: int, rng: np.random.Generator) -> np.ndarray:
    y = rng.normal(size=(n, 3))
    return y / np.linalg.norm(y, axis=1, keepdims=True)


def _cube(dim: int) -> Callable[[int, np.random.Generator], np.ndarray]:
    return lambda n, rng: rng.uniform(-1.0, 1.0, size=(n, dim))


@dataclasses.dataclass(frozen=True)
class Protocol:
    system: lp.systems.AbstractPoissonSystem
    n_trajectories: int
    n_observations: int
    initial: Callable[[int, np.random.Generator], np.ndarray]
    #: the true model family: H(y; theta) diagonal quadratic, theta = its coefficients
    true_theta: np.ndarray

    def limit_family(self, y, theta):
        return 0.5 * jnp.sum(theta * y**2)


PROTOCOLS = {
    "rigid_body": Protocol(lp.systems.RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0)), 30, 21, _sphere,
                           1.0 / np.array([2.0, 1.0, 2.0 / 3.0])),
    "kirchhoff": Protocol(lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0)), 40, 21, _cube(6),
                          1.0 / np.array([1.0, 2.0, 1.0, 1.0, 2.0, 1.0])),
}


def observations(protocol: Protocol, noise: float, sampling: str, seed: int) -> it.Observations:
    """The protocol's observations: initial states, times and noise all from `seed`."""
    rng = np.random.default_rng(seed)
    y0 = protocol.initial(protocol.n_trajectories, rng)
    if sampling == "regular":
        times = H_TEST * np.arange(protocol.n_observations)
    else:
        times = it.uneven_times(protocol.n_trajectories, protocol.n_observations, (0.05, 0.3), seed=seed)
    return it.observe(protocol.system, y0, times, noise=noise, seed=seed)


def test_set(protocol: Protocol, seed: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """12 held-out initial conditions and heyoka's states at t = 0.1 k, k = 0..1000."""
    y0 = protocol.initial(12, np.random.default_rng(seed))
    return y0, it.ground_truth(protocol.system, y0, H_TEST, STEPS_TEST).states


def figures(system, states: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Mean state error at the end, max relative energy error, Casimir drift of rollouts
    `(n, steps + 1, dim)` against the reference."""
    if not np.all(np.isfinite(states)):
        return {"state_error": float("inf"), "energy_error": float("inf"), "casimir_drift": float("inf")}
    err = float(np.mean(np.linalg.norm(states[:, -1] - reference[:, -1], axis=-1)))
    energy = np.asarray(system.hamiltonian(states))
    energy0 = np.asarray(system.hamiltonian(reference[:, :1]))
    out = {"state_error": err, "energy_error": float(np.max(np.abs(energy - energy0) / np.abs(energy0)))}
    if system.n_casimirs:
        c = np.asarray(system.casimirs(states)).reshape(*states.shape[:2], -1)
        g = np.asarray(system.casimir_gradients(states[:, :1])).reshape(states.shape[0], 1, -1, states.shape[-1])
        scale = np.linalg.norm(g, axis=-1) * np.linalg.norm(states[:, :1], axis=-1)[..., None]
        out["casimir_drift"] = float(np.max(np.abs(c - c[:, :1]) / scale))
    return out


def differences(theta: np.ndarray) -> np.ndarray:
    """theta_i - theta_j for i < j (what the rigid body's dynamics identify)."""
    i, j = np.triu_indices(theta.size, 1)
    return theta[i] - theta[j]


GLPNET: dict[str, Any] = {}  # fit_splitting's settings (--activation, --window, --latent)


def fit_glpnet(protocol: Protocol, data: it.Observations, seed: int) -> tuple[Any, dict[str, Any]]:
    model, records = learn.fit_splitting(protocol.system, data, key=seed, seed=seed, validation_fraction=0.0,
                                         progress=False, **GLPNET)
    chosen = records[-1].stages[-1].details
    extra = {"train_loss": records[-1].train_loss, "family": chosen.get("family", GLPNET.get("activation")),
             "bic": {r.stages[-1].details.get("family"): r.stages[-1].details.get("bic") for r in records}}
    if protocol.system.name == "RigidBody":  # the identified 1/I_i - 1/I_j
        quadratic = learn.quadratic_part(model.hamiltonian, protocol.system, np.concatenate(data.states))
        extra["difference_error"] = np.abs(quadratic.diagonal_differences() - differences(protocol.true_theta))
    return model, extra


def fit_limit(protocol: Protocol, data: it.Observations, seed: int) -> tuple[Any, dict[str, Any]]:
    theta0 = np.ones_like(protocol.true_theta)
    model = learn.ParametricHamiltonian(protocol.system, protocol.limit_family, theta0, substeps=10)
    fitted, record = learn.fit(model, data, loss=learn.TrajectoryLoss(), optimiser=learn.QuasiNewton(500, "bfgs"),
                               validation_fraction=0.0, seed=seed, progress=False)
    theta = np.asarray(fitted.theta)
    return fitted, {"train_loss": record.train_loss, "theta": theta,
                    "difference_error": np.abs(differences(theta) - differences(protocol.true_theta))}


class _Sindy:
    """A fitted SINDy model rolled out like a step map: its ODE integrated by LSODA (tolerance
    1e-12, as `SINDy.simulate`), stopped (and reported as diverged) once |y| exceeds 100 times
    its start."""

    def __init__(self, model):
        self.model = model

    def rollout(self, y0: np.ndarray) -> np.ndarray:
        from scipy.integrate import solve_ivp

        t = H_TEST * np.arange(STEPS_TEST + 1)
        out = np.full((y0.shape[0], t.size, y0.shape[1]), np.nan)
        for i, y in enumerate(y0):
            limit = 100.0 * max(float(np.linalg.norm(y)), 1e-3)

            def blow_up(_, z, limit=limit):
                return limit - np.linalg.norm(z)

            blow_up.terminal = True
            sol = solve_ivp(lambda _, z: self.model.predict(z[None])[0], (0.0, t[-1]), y, method="LSODA", t_eval=t,
                            rtol=1e-12, atol=1e-12, events=blow_up)
            out[i, : sol.y.shape[1]] = sol.y.T
        return out


def fit_sindy(protocol: Protocol, data: it.Observations, seed: int) -> tuple[Any, dict[str, Any]]:
    import pysindy as ps

    model = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=2), optimizer=ps.STLSQ(),
                     differentiation_method=ps.SmoothedFiniteDifference())
    model.fit(list(data.states), t=list(data.times))
    return _Sindy(model), {}


FITS = {"glpnet": fit_glpnet, "limit": fit_limit, "sindy": fit_sindy}


def run(system: str, noise: float, sampling: str, models: list[str], data_seed: int, seed: int) -> list[dict]:
    protocol = PROTOCOLS[system]
    data = observations(protocol, noise, sampling, data_seed)
    y0, reference = test_set(protocol)
    rows = []
    for name in models:
        start = time.perf_counter()
        model, extra = FITS[name](protocol, data, seed)
        fit_s = time.perf_counter() - start
        if isinstance(model, _Sindy):
            states = model.rollout(y0)
        else:
            states = np.asarray(model.with_h(H_TEST).rollout(y0, STEPS_TEST, nonfinite="return"))
        row = {"system": system, "noise": noise, "sampling": sampling, "model": name, "data_seed": data_seed,
               "seed": seed, "fit_s": fit_s, **figures(protocol.system, states, reference), **extra}
        rows.append(row)
        print(line(row), flush=True)
    return rows


def line(row: dict) -> str:
    extra = ""
    if "difference_error" in row:
        extra = f", |diff error| max {np.max(row['difference_error']):.1e}"
    if "family" in row:
        extra += f", family {row['family']}"
    return (f"{row['system']:10s} noise {row['noise']:<6g} {row['sampling']:7s} {row['model']:7s}: state error "
            f"(t=100) {row['state_error']:.3e}, energy {row['energy_error']:.2e}, Casimir "
            f"{row.get('casimir_drift', float('nan')):.1e}, fit {row['fit_s']:.1f} s{extra}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.observations", description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", choices=list(PROTOCOLS), default=["rigid_body"])
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 1e-3, 1e-2])
    parser.add_argument("--sampling", nargs="+", choices=["regular", "uneven"], default=["regular"])
    parser.add_argument("--models", nargs="+", choices=list(FITS), default=list(FITS))
    parser.add_argument("--data-seed", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--activation", default=None, help="fix the G-LPNet's family (default: chosen by BIC)")
    parser.add_argument("--window", type=int, default=None)
    parser.add_argument("--observed-starts", action="store_true", help="no errors in variables")
    parser.add_argument("--iterations", type=int, default=1000)
    parser.add_argument("--out", default=default_out("observations"))
    args = parser.parse_args(argv)
    GLPNET.update(activation=args.activation, iterations=args.iterations,
                  loss=learn.TrajectoryLoss(window=args.window, latent=not args.observed_starts))
    rows = []
    for system in args.systems:
        for sampling in args.sampling:
            for noise in args.noise:
                rows += run(system, noise, sampling, args.models, args.data_seed, args.seed)
    write_json(args.out, args, rows)


if __name__ == "__main__":
    main()
