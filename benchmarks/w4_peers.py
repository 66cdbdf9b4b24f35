"""W4's peers alone, on W4's own data and test set: each model's row as W4 measures it, and the
settings its rule chose on the training data (docs/conventions.md, "Peers").

    python -m benchmarks.w4_peers [--systems satellite] [--noise 0 1e-3 1e-2] [--sampling uneven]
        [--models SINDy "weak SINDy"] [--steps 200] [--out benchmarks/results/w4_peers.json]

The rows are `paper.w4_bodies.evaluate`'s (the protocol's observations, its 12 held-out starts,
heyoka's reference), so they equal those of `python -m paper run W4` at the same conditions;
`--steps` is the profile's (the neural ODE's budget is `NEURAL_ODE_ITERATIONS` times it).
"""

from __future__ import annotations

import argparse
import time

from benchmarks._report import default_out, write_json
from paper import w4_bodies as w4

MODELS = {"SINDy": w4.SINDyBodyModel, "weak SINDy": w4.WeakSINDyBodyModel, "neural ODE": w4.NeuralODEBodyModel}


class _Chosen:
    """A model that keeps what its rule chose (the fitted field's `describe()`)."""

    def __init__(self, model: w4.AbstractBodyModel):
        self.model, self.label, self.chosen = model, model.label, None

    def fit(self, protocol, data, *, progress=False):
        fitted = self.model.fit(protocol, data)
        self.chosen = fitted.describe()
        return fitted

    def predict(self, fitted, protocol, test):
        return self.model.predict(fitted, protocol, test)

    def identified(self, fitted, protocol):
        return self.model.identified(fitted, protocol)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.w4_peers", description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", choices=("satellite", "vehicle"), default=["satellite"])
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 1e-3, 1e-2])
    parser.add_argument("--sampling", nargs="+", choices=("regular", "uneven"), default=["uneven"])
    parser.add_argument("--models", nargs="+", choices=list(MODELS), default=["SINDy", "weak SINDy"])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--neural-ode-iterations-per-step", type=int, default=w4.NEURAL_ODE_ITERATIONS,
                        help="the neural ODE's L-BFGS-B iterations per step (W4's)")
    parser.add_argument("--out", default=str(default_out("w4_peers")))
    args = parser.parse_args(argv)
    rows = []
    for system in args.systems:
        protocol = w4.protocols()[system]
        test = w4.test_set(protocol)
        for sampling in args.sampling:
            for noise in args.noise:
                data = w4.observations(protocol, noise, sampling)
                for name in args.models:
                    budget = {"iterations_per_step": args.neural_ode_iterations_per_step} if name == "neural ODE" else {}
                    model = _Chosen(MODELS[name](steps=args.steps, **budget))
                    start = time.perf_counter()
                    row = w4.evaluate(protocol, model, data, test, system=system, noise=noise, sampling=sampling)
                    rows.append({"system": system, "sampling": sampling, "noise": noise, "model": name,
                                 "attitude_error": row.attitude_error, "velocity_error": row.velocity_error,
                                 "position_error": row.position_error, "fit_seconds": row.fit_seconds,
                                 "chosen": model.chosen, "seconds": time.perf_counter() - start})
                    print(f"{system}, {sampling}, noise {noise:g}, {name}: attitude error {row.attitude_error:.4g} rad, "
                          f"velocity {row.velocity_error:.4g}"
                          + ("" if row.position_error is None else f", position {row.position_error:.4g}")
                          + f", fit {row.fit_seconds:.1f} s; chosen: {model.chosen}", flush=True)
    write_json(args.out, args, {"rows": rows})


if __name__ == "__main__":
    main()
