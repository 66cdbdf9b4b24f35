"""One G-LPNet variant trained like benchmarks/any_algebra.py's G-LPNet (BFGS from the identity
warm start, seed 0, the benchmark's data), its energy error over 2000 steps from the 10 held-out
ICs beside the classical Strang splitting of the exact H.

    python -m benchmarks.exploration.glpnet_variants --system SYSTEM [--method LieTrotter|Strang]
        [--activation sigmoid|identity] [--order basis|triple-jump] [--iterations 1000] [--out FILE]

`--method`: how the modules compose (`LieTrotter`, the paper's cyclic order, order 1; `Strang`,
the symmetric network, order 2); `--order`: `basis` (2n modules cycling over the basis, the
default network) or `triple-jump` (3n - 2 modules in the palindromic order of a TripleJump of
Strang steps, `--method Strang`); `--activation` of the modules. Writes the figures to `--out`
(default `benchmarks/results/exploration/glpnet_variants_SYSTEM_METHOD_ACTIVATION_ORDER_ITERATIONS.json`).
"""

from __future__ import annotations

import argparse
import time

import integrators as it
import learn
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    H,
    add_out_option,
    add_system_option,
    initial_conditions,
    out_path,
    training_data,
)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.glpnet_variants",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser)
    parser.add_argument("--method", choices=["LieTrotter", "Strang"], default="LieTrotter")
    parser.add_argument("--activation", choices=["sigmoid", "identity"], default="sigmoid")
    parser.add_argument("--order", choices=["basis", "triple-jump"], default="basis")
    parser.add_argument("--iterations", type=int, default=1000, help="BFGS iterations")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    n = system.dim
    y_train, y_test = initial_conditions(n, 0)
    data = training_data(system, y_train, 0)
    method = getattr(it.splitting, args.method)
    if args.order == "triple-jump":
        if method is not it.splitting.Strang:
            parser.error("--order triple-jump is a palindrome of Strang steps: give --method Strang")
        order = list(range(n)) + list(range(n - 2, -1, -1)) + list(range(1, n))
        net = learn.GLPNet(system, len(order), order, key=0, method=method, activation=args.activation)
    else:
        net = learn.GLPNet(system, key=0, method=method, activation=args.activation)
    t0 = time.perf_counter()
    fitted, rec = learn.fit(net, data, seed=0, progress=False,
                            optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(args.iterations))))
    seconds = time.perf_counter() - t0
    cmp = it.compare({"g": fitted, "strang": it.splitting.Strang(system, H)}, system, y_test, t_final=200.0,
                     n_outputs=200)
    label = f"{args.method} {args.activation} {args.order}"
    print(args.system, label, args.iterations, f"M={fitted.n_modules} loss={rec.train_loss:.2e}",
          " ".join(f"{r.label}:E={r.energy_error_max:.2e}" for r in cmp.rows), f"{seconds:.0f}s", flush=True)
    name = f"glpnet_variants_{args.system}_{args.method}_{args.activation}_{args.order}_{args.iterations}"
    write_json(out_path(args, name), args, {
        "n_modules": fitted.n_modules, "train_loss": rec.train_loss, "val_loss": rec.val_loss, "fit_s": seconds,
        "energy_error_max": {r.label: r.energy_error_max for r in cmp.rows}})


if __name__ == "__main__":
    main()
