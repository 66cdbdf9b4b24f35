"""Learning from observations (W2's protocols, one condition at a time, in one run): noisy,
regularly or unevenly sampled trajectories of a system whose Hamiltonian the learner is not
given; the G-LPNet beside SINDy, the unstructured MLP and the parametric limit.

    python -m benchmarks.observations [--systems "rigid body" Kirchhoff diamond] [--noise 0 1e-3 1e-2]
        [--sampling regular uneven] [--models G-LPNet limit SINDy MLP] [--data-seed 1]
        [--activation identity|sigmoid] [--window K] [--observed-starts] [--bootstrap N]
        [--out benchmarks/results/observations.json]

The protocols, models and figures are `paper.w2_observations`'s (its docstring says what each
is). `--window` and `--observed-starts` set the G-LPNet's `learn.TrajectoryLoss` (default:
whole trajectories, fitted starts); `--activation` fixes the G-LPNet's family of H~ instead of choosing it by BIC; the data
seed draws initial states, times and noise; the models train with W2's seed.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

import learn
from benchmarks._report import default_out, write_json
from paper import w2_observations as w2
from paper._experiment import row_to_json
from paper._study import SplittingModel

MODELS = ("G-LPNet", "limit", "SINDy", "MLP")


def _models(protocol: w2.Protocol, args: argparse.Namespace) -> dict:
    """W2's models by label, with this run's settings (iterations, the G-LPNet's family and loss)."""
    steps = 200 if args.iterations is None else args.iterations
    mlp_iterations = 1000 if args.iterations is None else args.iterations
    profile = w2.PROFILES["full"].replace(iterations=mlp_iterations, steps=steps)
    models = {model.label: model for model in w2.models(protocol, profile)}
    loss = None
    if args.window or args.observed_starts or args.max_step:
        loss = learn.TrajectoryLoss(window=args.window, latent=not args.observed_starts, max_step=args.max_step)
    glpnet = models["G-LPNet"]
    assert isinstance(glpnet, SplittingModel)
    models["G-LPNet"] = dataclasses.replace(glpnet, activation=args.activation, loss=loss)
    return models


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.observations", description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", choices=list(w2.protocols()), default=["rigid body"])
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 1e-3, 1e-2])
    parser.add_argument("--sampling", nargs="+", choices=["regular", "uneven"], default=["regular"])
    parser.add_argument("--models", nargs="+", choices=list(MODELS), default=["G-LPNet", "limit", "SINDy"])
    parser.add_argument("--data-seed", type=int, default=w2.DATA_SEED)
    parser.add_argument("--activation", default=None, help="fix the G-LPNet's family of H~ (default: chosen by BIC)")
    parser.add_argument("--iterations", type=int, default=None,
                        help="Levenberg-Marquardt steps per stage of the G-LPNet and the limit (default 200), "
                             "L-BFGS-B iterations of the MLP (default 1000)")
    parser.add_argument("--window", type=int, default=None, help="the G-LPNet's loss: intervals per segment")
    parser.add_argument("--max-step", type=float, default=None,
                        help="the G-LPNet's loss: run each interval in equal sub-steps of at most this")
    parser.add_argument("--observed-starts", action="store_true",
                        help="the G-LPNet's loss: segments start from their first observation (no errors in variables)")
    parser.add_argument("--bootstrap", type=int, default=0,
                        help="rigid body: also refit the G-LPNet to N resamples of the trajectories and print the "
                             "spread of the identified 1/I_i - 1/I_j; rotated rigid body: of its principal axes")
    parser.add_argument("--out", default=default_out("observations"))
    args = parser.parse_args(argv)
    protocols = w2.protocols()
    rows = []
    for system in args.systems:
        protocol = protocols[system]
        models = _models(protocol, args)
        y0, reference = w2.test_set(protocol)
        for sampling in args.sampling:
            for noise in args.noise:
                data = w2.observations(protocol, noise, sampling, seed=args.data_seed)
                for name in args.models:
                    model = models.get(name)
                    if model is None or not model.accepts(data):  # SINDy without pysindy; the MLP on uneven data
                        continue
                    row = w2.evaluate(protocol, model, data, y0, reference, system=system, noise=noise,
                                      sampling=sampling)
                    rows.append({**row_to_json(row), "data_seed": args.data_seed})
                    print(w2.EXPERIMENT.line(row), flush=True)
                if args.bootstrap and system == "rotated rigid body":
                    b = w2.bootstrap_axes(protocol, data, args.bootstrap, iterations=args.iterations)
                    rows.append({"system": system, "noise": noise, "sampling": sampling, "model": "G-LPNet bootstrap",
                                 **b})
                    angles = np.degrees(b["angles"])
                    print(f"{system}, {sampling}, noise {noise:g}: over {args.bootstrap} resamples, principal axes "
                          f"within {np.round(angles.mean(0), 3).tolist()} +- {np.round(angles.std(0, ddof=1), 3).tolist()} "
                          f"deg of the true ones (rotation vector {np.round(b['true_rotation_vector'], 4).tolist()}, "
                          f"learned {np.round(b['rotation_vectors'].mean(0), 4).tolist()} +- "
                          f"{np.round(b['rotation_vectors'].std(0, ddof=1), 4).tolist()}); 1/I_k less their mean "
                          f"{np.round(b['values'].mean(0), 5).tolist()} +- {np.round(b['values'].std(0, ddof=1), 5).tolist()} "
                          f"(true {np.round(b['true_values'], 5).tolist()})", flush=True)
                elif args.bootstrap and protocol.diagonal_differences:
                    d = w2.bootstrap_differences(protocol, data, args.bootstrap, iterations=args.iterations)
                    true = w2.differences(protocol.true_theta)
                    rows.append({"system": system, "noise": noise, "sampling": sampling, "model": "G-LPNet bootstrap",
                                 "differences": d, "mean": d.mean(0), "std": d.std(0, ddof=1), "true": true})
                    print(f"{system}, {sampling}, noise {noise:g}: 1/I_i - 1/I_j over {args.bootstrap} resamples "
                          f"{np.round(d.mean(0), 5).tolist()} +- {np.round(d.std(0, ddof=1), 5).tolist()} "
                          f"(true {np.round(true, 5).tolist()})", flush=True)
    write_json(args.out, args, rows)


if __name__ == "__main__":
    main()
