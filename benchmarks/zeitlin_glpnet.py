r"""A G-LPNet on Zeitlin's model at N = 16 or 32 (dimension 256, 1024): W5's data and test fields, a
G-LPNet of M ridge modules against the isospectral midpoint at the same step
(BENCHMARKS.md, "G-LPNets on Zeitlin's model").

    python -m benchmarks.zeitlin_glpnet [--N 16] [--modules 16] [--iterations 50] [--init zero]
    python -m benchmarks.zeitlin_glpnet --report

The G-LPNet is `learn.GLPNet` with `Strang()` over M modules
$\Phi_s(\langle\alpha_s, W\rangle)$, identity activation (each piece a quadratic, as Zeitlin's
energy is: a sum of $N^2 - 1$ squares in the Laplacian's eigenbasis) and learned full vectors
$\alpha_s$, started at $\widetilde H = 0$ (`init="zero"`: the identity step, vectors of unit
expected length; `--init random` is the paper's start, vectors of length about $\sqrt{256}$),
fitted by L-BFGS-B (`learn.ScipyLBFGSB`) to the pairs of
W5's full profile (12 fields x 40 steps of quflow's step H, the isospectral midpoint at H/16);
tested as W5 tests (`paper.w5_zeitlin.measure`, 8 fields x 400 steps against the isospectral
triple jump at H/16). Every step is 2M - 1 conjugations, each an exact Poisson map: the
G-LPNet is exactly Poisson and keeps the spectrum of W; its energy is the learned
$\widetilde H$'s, a rank-M quadratic where Zeitlin's has rank $N^2 - 1$. The fitted network is
saved beside the results (`--model`). The default files are `zeitlin_glpnet.json` / `.h5` at
N = 16 from the zero start, with `_N32` and `_random_init` appended for the others.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import integrators as it
import learn
import liepoisson as lp
from integrators.splitting import Strang
from paper.w5_zeitlin import (
    PROFILES,
    TOL,
    measure,
    quflow_step,
    test_reference,
    training_trajectories,
)

from ._report import RESULTS, add_output_arguments, default_out, saved_results, write_json

NAME = "zeitlin_glpnet"


def run(N: int, modules: int, iterations: int, init: str, model_path: Path) -> list[dict]:
    P = PROFILES["full"]
    system = lp.systems.Zeitlin(N)
    H = quflow_step(system)
    trajectories = training_trajectories(system, H, P.n_train, P.train_steps)
    pairs = (trajectories[:, :-1].reshape(-1, system.dim), trajectories[:, 1:].reshape(-1, system.dim))
    reference = test_reference(system, H, P.n_test, P.test_steps)
    net = learn.GLPNet(system, n_modules=modules, method=Strang(), activation="identity", full_vectors=True, h=H,
                       init=init)
    begin = time.perf_counter()
    fitted, record = learn.fit(net, pairs, h=H, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(iterations)), validation_fraction=0.2,
                               progress=True)
    fit_seconds = time.perf_counter() - begin
    fitted.save(model_path)
    rows = []
    for name, step_map, extra in (
        (f"G-LPNet, {modules} modules", fitted, {"fit_seconds": fit_seconds, "train_loss": float(record.train_loss),
                                                 "iterations": iterations, "init": init}),
        ("isospectral midpoint", it.IsospectralMidpoint(system, H, tol=TOL), {}),
    ):
        row = measure(system, name, step_map, H, reference, 1, theta=None, fit_seconds=None, train_loss=None)
        rows.append({"N": N, "model": name, "h": H, "state_error_early": row.state_error_early,
                     "state_error_final": row.state_error_final, "energy_error_early": row.energy_error_early,
                     "energy_error_max": row.energy_error_max, "casimir_drift_max": row.casimir_drift_max,
                     "ms_per_step": row.ms_per_step, **extra})
    return rows


def report(results: list[dict]) -> None:
    print("N   model                     state error (10 steps / end)  energy error (10 steps / max)  "
          "Casimirs   ms/step  fit")
    for r in results:
        fit = f"{r['fit_seconds']:.0f} s, loss {r['train_loss']:.3g}" if "fit_seconds" in r else ""
        print(f"{r['N']:<3d} {r['model']:<25s} {r['state_error_early']:.3g} / {r['state_error_final']:.3g}"
              f"{'':17s}{r['energy_error_early']:.2g} / {r['energy_error_max']:.2g}{'':16s}"
              f"{r['casimir_drift_max']:.1e}  {r['ms_per_step']:.3f}    {fit}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--N", type=int, default=16)
    parser.add_argument("--modules", type=int, default=16)
    parser.add_argument("--iterations", type=int, default=50)
    parser.add_argument("--init", choices=["zero", "random"], default="zero")
    parser.add_argument("--model", type=Path, default=None, help="default: beside --out's default, by N and init")
    add_output_arguments(parser, NAME)
    parser.set_defaults(out=None)
    args = parser.parse_args(argv)
    name = NAME + ("" if args.N == 16 else f"_N{args.N}") + ("" if args.init == "zero" else f"_{args.init}_init")
    args.out = default_out(name) if args.out is None else args.out
    args.model = RESULTS / f"{name}.h5" if args.model is None else args.model
    if args.report:
        report(saved_results(args.out))
        return
    results = run(args.N, args.modules, args.iterations, args.init, args.model)
    report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
