"""The reported regression's protocol (issue: "a regression on simulated data"): the rigid body
I = (2, 1, 2/3), 30 trajectories x 21 observations at h = 0.1 of Pi with Gaussian noise sigma
per component, 12 new starts on |Pi| = 1 predicted to t = 100 from their true state.

    python -m benchmarks.noisy_protocol [--noise 1e-3 1e-2] [--data-seed 1 2] [--models G-LPNet limit SINDy]
        [--selection held-out bic] [--out benchmarks/results/noisy_protocol.json]

W2's rigid body (`paper.w2_observations`: initial states on |Pi| = 1 drawn by the data seed,
`integrators.observe` of heyoka's motion; noise relative to the states' RMS size, 1 here, so
sigma per component; the test starts and heyoka's reference its `test_set`). Models:

- **G-LPNet**: `learn.fit_splitting(system, observations)` (its defaults, as the issue's call;
  one row per `--selection` given, passed as `selection=`). Per family fitted: its sum of squared residuals, BIC, effective parameters and
  Levenberg-Marquardt steps, beside
- **the SSR of the true parameters** on the same data: from the true starts (the noise itself)
  and from starts fitted with the true Hamiltonian (each trajectory's start by least squares,
  RK4 at 1/10 of the step): what a converged fit of a family holding the body reaches, less
  what its few extra parameters absorb;
- **limit**: W2's (the true family by trajectory least squares with the initial states);
- **SINDy** and **weak SINDy**: W2's (`paper._sindy.SINDyModel`, `WeakSINDyModel`), the STLSQ
  threshold, constant and derivative or support width chosen by every study's rule
  (`paper._sindy.choose_sparse_field`, on the training trajectories only).

The mean state error at t = 100 is the mean over the 12 starts of |y - y_heyoka|. The script
runs on older commits too (`PYTHONPATH=<worktree> python benchmarks/noisy_protocol.py --models
G-LPNet`): only `learn.fit_splitting` and W2's protocol are used for the G-LPNet rows.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import learn
from benchmarks._report import default_out, write_json
from paper import w2_observations as w2

MODELS = ("G-LPNet", "limit", "SINDy", "weak SINDy")


def state_error(states: np.ndarray, reference: np.ndarray) -> float:
    """Mean over the starts of |y(t_end) - y_ref(t_end)| (infinite for a rollout that diverged)."""
    end = np.linalg.norm(np.asarray(states)[:, -1] - reference[:, -1], axis=-1)
    return float(np.mean(end)) if np.all(np.isfinite(end)) else float("inf")


def true_ssr(protocol: w2.Protocol, data, clean, substeps: int = 10) -> dict[str, float]:
    """The SSR of the true parameters on `data`: from the true starts (`clean`, the noise-free
    observations), and from each trajectory's start fitted by least squares with the true vector
    field (RK4, `substeps` per interval; Gauss-Newton, the Jacobian by forward differentiation)."""
    noisy = np.stack(data.states)
    t = np.asarray(data.times[0])
    from_truth = float(np.sum((noisy - np.stack(clean.states)) ** 2))
    field = protocol.system.vector_field
    dt = float(t[1] - t[0]) / substeps

    def rk4(y):
        k1 = field(y)
        k2 = field(y + 0.5 * dt * k1)
        k3 = field(y + 0.5 * dt * k2)
        k4 = field(y + dt * k3)
        return y + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    def trajectory(y0):
        def interval(y, _):
            y = jax.lax.fori_loop(0, substeps, lambda _, z: rk4(z), y)
            return y, y

        _, ys = jax.lax.scan(interval, y0, None, length=t.size - 1)
        return jnp.concatenate([y0[None], ys])

    residuals = jax.jit(jax.vmap(lambda y0, obs: (trajectory(y0) - obs).reshape(-1)))
    jacobian = jax.jit(jax.vmap(lambda y0, obs: jax.jacfwd(lambda z: (trajectory(z) - obs).reshape(-1))(y0)))
    y0, obs = jnp.asarray(noisy[:, 0]), jnp.asarray(noisy)
    for _ in range(20):  # Gauss-Newton per trajectory (3 unknowns each, a start near the noisy one)
        r, J = residuals(y0, obs), jacobian(y0, obs)
        step = jnp.linalg.solve(jnp.einsum("nki,nkj->nij", J, J), -jnp.einsum("nki,nk->ni", J, r)[..., None])[..., 0]
        y0 = y0 + step
        if float(jnp.max(jnp.abs(step))) < 1e-13:
            break
    fitted = float(jnp.sum(residuals(y0, obs) ** 2))
    return {"true_starts": from_truth, "fitted_starts": fitted, "n": int(noisy.size)}


def glpnet(protocol: w2.Protocol, data, y0, reference, selection: str | None) -> dict:
    """`learn.fit_splitting` with its defaults (as the issue's call) and each family's criterion
    from the records."""
    kwargs = {} if selection is None else {"selection": selection}
    start = time.perf_counter()
    net, records = learn.fit_splitting(protocol.system, data, progress=False, **kwargs)
    seconds = time.perf_counter() - start
    states = np.asarray(net.with_h(w2.H_TEST).rollout(y0, reference.shape[1] - 1, nonfinite="return"))
    families = []
    for r in records:
        d = r.stages[-1].details
        families.append({k: d.get(k) for k in ("family", "ssr", "bic", "effective_parameters", "held_out_error",
                                                "target_loss")}
                        | {"steps": sum(s.iterations for s in r.stages), "seconds": r.wall_time_s})
    chosen = records[-1].stages[-1].details
    return {"model": "G-LPNet", "state_error": state_error(states, reference), "fit_seconds": seconds,
            "family": chosen.get("family"), "skipped": list(chosen.get("skipped", [])), "families": families}


def limit(protocol: w2.Protocol, data, y0, reference) -> dict:
    """W2's limit: the true family fitted by trajectory least squares with the initial states."""
    model = next(m for m in w2.models(protocol, w2.PROFILES["full"].replace(iterations=1000, steps=200)) if m.label == "limit")
    start = time.perf_counter()
    fitted = model.fit(protocol.system, data)
    seconds = time.perf_counter() - start
    states = model.simulate(fitted, y0, reference.shape[1] - 1, w2.H_TEST)
    record = fitted.records[-1]
    return {"model": "limit", "state_error": state_error(states, reference), "fit_seconds": seconds,
            "ssr": record.train_loss * data.n_observations * data.dim, "theta": np.asarray(fitted.step_map.theta)}


def sindy(protocol: w2.Protocol, data, y0, reference, name: str = "SINDy") -> dict:
    """W2's SINDy or weak SINDy (`name`), its settings chosen on the training trajectories."""
    from paper._sindy import SINDyModel, WeakSINDyModel

    start = time.perf_counter()
    model = SINDyModel() if name == "SINDy" else WeakSINDyModel()
    fitted = model.fit(protocol.system, data)
    seconds = time.perf_counter() - start
    states = model.simulate(fitted, y0, reference.shape[1] - 1, w2.H_TEST)
    field = fitted.step_map.model
    return {"model": name, "state_error": state_error(states, reference), "fit_seconds": seconds,
            "threshold": field.threshold, "chosen": field.describe()}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.noisy_protocol", description=__doc__.splitlines()[0])
    parser.add_argument("--noise", nargs="+", type=float, default=[1e-3, 1e-2])
    parser.add_argument("--data-seed", nargs="+", type=int, default=[w2.DATA_SEED])
    parser.add_argument("--models", nargs="+", choices=list(MODELS), default=list(MODELS))
    parser.add_argument("--selection", nargs="+", default=None,
                        help="fit_splitting's selection=, one G-LPNet row each (default: one row, its own default)")
    parser.add_argument("--out", default=default_out("noisy_protocol"))
    args = parser.parse_args(argv)
    protocol = w2.protocols()["rigid body"]
    y0, reference = w2.test_set(protocol)
    rows = []
    for seed in args.data_seed:
        for noise in args.noise:
            data = w2.observations(protocol, noise, "regular", seed=seed)
            clean = w2.observations(protocol, 0.0, "regular", seed=seed)
            truth = true_ssr(protocol, data, clean)
            print(f"seed {seed}, noise {noise:g}: SSR of the true parameters {truth['true_starts']:.5g} (true starts), "
                  f"{truth['fitted_starts']:.5g} (fitted starts); n sigma^2 = {truth['n'] * noise**2:.5g}", flush=True)
            runs = [(name, None) for name in args.models if name != "G-LPNet"]
            if "G-LPNet" in args.models:
                runs = [("G-LPNet", selection) for selection in args.selection or [None]] + runs
            for name, selection in runs:
                if name == "G-LPNet":
                    row = glpnet(protocol, data, y0, reference, selection)
                elif name == "limit":
                    row = limit(protocol, data, y0, reference)
                else:
                    row = sindy(protocol, data, y0, reference, name)
                row = {"data_seed": seed, "noise": noise, **row, "selection": selection, "true_ssr": truth}
                rows.append(row)
                print(f"  {name}{'' if selection is None else f' ({selection})'}: state error at t = 100 {row['state_error']:.4g}, fit {row['fit_seconds']:.1f} s"
                      + (f", chose {row['family']!r}" if "family" in row else "")
                      + (f", SSR {row['ssr']:.5g}" if "ssr" in row else "")
                      + (f"; chosen: {row['chosen']}" if "chosen" in row else ""), flush=True)
                for f in row.get("families", []):
                    print(f"    {f['family']}: SSR {f['ssr']}, BIC {f['bic']}, k {f['effective_parameters']}, "
                          f"held-out {f['held_out_error']}, {f['steps']} steps, {f['seconds']:.1f} s", flush=True)
    write_json(args.out, args, rows)


if __name__ == "__main__":
    main()
