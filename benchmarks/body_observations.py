"""Learning from what instruments measure (W4's protocols, one condition at a time): a tumbling
satellite's attitude and angular velocities, an underwater vehicle's pose and velocities; the
momenta latent. The G-LPNet beside the parametric limit, SINDy and weak SINDy.

    python -m benchmarks.body_observations [--systems satellite vehicle] [--noise 0 1e-3 1e-2]
        [--sampling regular uneven] [--models G-LPNet limit SINDy "weak SINDy"]
        [--time-unit 1e-3] [--out benchmarks/results/body_observations.json]

`--time-unit 1e-3` gives the learned maps the same observations in milliseconds (times x 1000,
velocities / 1000; the predictions are converted back): the figures must not change. The
protocols, models and figures are `paper.w4_bodies`'s; `--trajectories`, `--observations`,
`--t-end` and `--n-test` change their sizes, e.g. the protocol of Latent Lie-Poisson Neural
Networks (200 trajectories x 101 observations at h = 0.1, noise 0.005, 50 test trajectories
of 2001 points; W4's LLPNN part gives its neural ODE `--neural-ode-iterations-per-step 5`):

    python -m benchmarks.body_observations --noise 0.005 --sampling regular --trajectories 200
        --observations 101 --t-end 200 --n-test 50 --models G-LPNet limit
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from benchmarks._report import default_out, write_json
from paper import w4_bodies as w4
from paper._experiment import row_to_json


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.body_observations",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", choices=list(w4.protocols()), default=["satellite"])
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 1e-3, 1e-2])
    parser.add_argument("--sampling", nargs="+", choices=["regular", "uneven"], default=["uneven"])
    parser.add_argument("--models", nargs="+", default=["G-LPNet", "limit", "SINDy", "weak SINDy"])
    parser.add_argument("--steps", type=int, default=200, help="Levenberg-Marquardt steps per fit")
    parser.add_argument("--time-unit", type=float, default=1.0,
                        help="give the learners the observations in this unit of time (seconds)")
    parser.add_argument("--bootstrap", type=int, default=0,
                        help="also refit the G-LPNet's family on N resamples of the trajectories: the spread of its "
                             "inertia's principal values and axes")
    parser.add_argument("--trajectories", type=int, default=None, help="training trajectories (the protocol's)")
    parser.add_argument("--observations", type=int, default=None, help="observations per trajectory")
    parser.add_argument("--t-end", type=float, default=None, help="the predictions' horizon (the protocol's)")
    parser.add_argument("--n-test", type=int, default=w4.N_TEST, help="held-out initial conditions")
    parser.add_argument("--neural-ode-iterations-per-step", type=int, default=w4.NEURAL_ODE_ITERATIONS,
                        help="the neural ODE's L-BFGS-B iterations per step (W4's; its LLPNN part: "
                             f"{w4.LLPNN_NEURAL_ODE_ITERATIONS})")
    parser.add_argument("--out", default=default_out("body_observations"))
    args = parser.parse_args(argv)
    models = [m for m in w4.models(operator_baselines=True, steps=args.steps,
                                   neural_ode_iterations_per_step=args.neural_ode_iterations_per_step)
              if m.label in args.models]
    if args.time_unit != 1.0:  # the learned maps; SINDy's fits are not covariant in time (its thresholds)
        models = [dataclasses.replace(m, unit=args.time_unit) for m in models if isinstance(m, w4.LearnedBodyModel)]
    rows = []
    protocols = w4.protocols()
    for system in args.systems:
        protocol = protocols[system]
        test = w4.test_set(protocol, args.t_end, args.n_test)
        for sampling in args.sampling:
            for noise in args.noise:
                data = w4.observations(protocol, noise, sampling, n_trajectories=args.trajectories,
                                       n_observations=args.observations)
                for model in models:
                    start = time.perf_counter()
                    row = w4.evaluate(protocol, model, data, test, system=system, noise=noise, sampling=sampling)
                    print(w4.EXPERIMENT.line(row), f"({time.perf_counter() - start:.0f} s with the evaluation)", flush=True)
                    rows.append(row)
    for v in w4.EXPERIMENT.verdict(rows):
        print("-", v)
    spread = {}
    if args.bootstrap:
        for system in args.systems:
            protocol = protocols[system]
            for sampling in args.sampling:
                for noise in args.noise:
                    data = w4.observations(protocol, noise, sampling, n_trajectories=args.trajectories,
                                           n_observations=args.observations)
                    M = w4.bootstrap_inertia(protocol, data, args.bootstrap, steps=args.steps)
                    values, axes = np.linalg.eigh(M)
                    truth = np.linalg.inv(protocol.A)
                    true_values, true_axes = np.linalg.eigh(truth * truth.shape[0] / np.trace(truth))
                    # each principal axis's angle from the true one (as lines), per resample
                    cosines = np.abs(np.einsum("kij,ij->kj", axes, true_axes)).clip(0.0, 1.0)
                    angles = np.degrees(np.arccos(cosines))
                    key = f"{system}, {sampling}, noise {noise:g}"
                    spread[key] = {"principal_values_mean": values.mean(0).tolist(),
                                   "principal_values_std": values.std(0, ddof=1).tolist(),
                                   "true_principal_values": true_values.tolist(),
                                   "axes_angle_deg_mean": angles.mean(0).tolist(),
                                   "axes_angle_deg_std": angles.std(0, ddof=1).tolist()}
                    print(key, f"bootstrap of the inertia (trace {truth.shape[0]}):", json.dumps(spread[key]))
    write_json(args.out, args, {"rows": [row_to_json(r) for r in rows], "verdict": w4.EXPERIMENT.verdict(rows),
                                "bootstrap": spread})


if __name__ == "__main__":
    main()
