"""Why the LPNet of benchmarks/any_algebra.py misses 1e-3 on the compact algebras: one system,
one recipe, several seeds, on the benchmark's data (40 ICs x 50 pairs at h = 0.1, uniform in
[-1, 1]^dim; 10 held-out ICs).

    python -m benchmarks.exploration.recipes --system SYSTEM [--seeds 0 1 2] [--adam 20000] [--lbfgs N]
        [--width 16] [--skip] [--reversible] [--equivariant] [--long] [--out FILE]

The recipe: Adam `--adam` epochs, then L-BFGS-B `--lbfgs` iterations (0: none); hidden width
`--width`; `--skip`: a linear skip in the parameter network, alpha(y) = MLP(y) + L y, L trained
from zero (`LinearSkip` below); `--equivariant`: the network averaged over the system's sign
symmetries (`learn.GroupAveraged`); `--reversible`: `learn.Reversible(lpnet, "auto")`; `--long`:
also the held-out ICs over 10000 steps. Prints per seed, under the recipe's name of the first
runs (e.g. `adam_lbfgs30000_skip`, `adam_lbfgs_rev_eq_long`): train / validation loss, the
one-step RMS error at the held-out ICs' first steps, the max relative energy error over 2000
steps from the held-out ICs and from 10 of the training ICs. Writes them to `--out` (default
`benchmarks/results/exploration/recipes_SYSTEM_RECIPE.json`).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    add_out_option,
    add_system_option,
    initial_conditions,
    lpnet,
    out_path,
    training_data,
)


class LinearSkip(learn.AbstractWrappedNetwork):
    """alpha(y) = N(y) + L y with L trained from zero: a wrapper of any network whose input and
    output have the same size (exploration only; its files cannot be read back)."""

    network: learn.AbstractNetwork
    skip: jax.Array

    def __init__(self, network: learn.AbstractNetwork):
        self.network = network
        self.skip = jnp.zeros((network.out_size, network.in_size))

    def __call__(self, y: jax.Array) -> jax.Array:
        return self.network(y) + self.skip @ y

    def spec(self) -> dict[str, Any]:
        return {"kind": "LinearSkip", "network": self.network.spec()}

    def reinitialised(self, key) -> LinearSkip:
        return LinearSkip(self.network.reinitialised(key))


def recipe_name(args: argparse.Namespace) -> str:
    """The name the first runs gave the recipe (their lines: `git log -p BENCHMARKS.md`)."""
    words = ["adam" if args.adam == 20_000 else f"adam{args.adam}"]
    if args.lbfgs:
        words.append("lbfgs" if args.lbfgs == 5000 else f"lbfgs{args.lbfgs}")
    if args.width != 16:
        words.append(f"w{args.width}")
    words += [w for w, on in (("skip", args.skip), ("rev", args.reversible), ("eq", args.equivariant),
                              ("long", args.long)) if on]
    return "_".join(words)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.recipes",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--adam", type=int, default=20_000, help="Adam epochs")
    parser.add_argument("--lbfgs", type=int, default=0, help="L-BFGS-B iterations after Adam (0: none)")
    parser.add_argument("--width", type=int, default=16, help="hidden width (3 layers)")
    parser.add_argument("--skip", action="store_true", help="alpha(y) = MLP(y) + L y")
    parser.add_argument("--reversible", action="store_true", help="learn.Reversible(lpnet, 'auto')")
    parser.add_argument("--equivariant", action="store_true", help="the network averaged over the sign symmetries")
    parser.add_argument("--long", action="store_true", help="also the held-out ICs over 10000 steps")
    add_out_option(parser)
    args = parser.parse_args(argv)
    recipe = recipe_name(args)
    system = SYSTEMS[args.system]()
    rows = []
    for seed in args.seeds:
        y_train, y_test = initial_conditions(system.dim, seed)
        data = training_data(system, y_train, seed)
        test = training_data(system, y_test, seed)
        stages = [learn.Adam(args.adam)] + ([learn.KeepIfBetter(learn.ScipyLBFGSB(args.lbfgs))] if args.lbfgs else [])
        model = lpnet(system, width=args.width, key=seed, symmetry="auto" if args.reversible else None,
                      equivariant=args.equivariant, network_wrapper=LinearSkip if args.skip else None)
        t0 = time.perf_counter()
        net, rec = learn.fit(model, data, optimiser=stages, seed=seed, progress=False)
        seconds = time.perf_counter() - t0
        y = np.asarray(test.states)
        pred = np.asarray(net.rollout(y[:, 0], 1))[:, -1]
        rms = float(np.sqrt(np.mean((pred - y[:, 1]) ** 2)))
        energy = {}
        for label, y0 in (("held-out", y_test), ("train", y_train[:10])):
            energy[label] = it.compare({"lpnet": net}, system, y0, t_final=200.0, n_outputs=200).rows[0].energy_error_max
        if args.long:
            energy["held-out, 10000 steps"] = it.compare({"lpnet": net}, system, y_test, t_final=1000.0,
                                                         n_outputs=200).rows[0].energy_error_max
        print(f"{args.system} {recipe} seed {seed}: loss {rec.train_loss:.2e} / val {rec.val_loss:.2e}, one-step RMS "
              f"at held-out ICs {rms:.2e}, max energy error held-out {energy['held-out']:.2e}, train ICs "
              f"{energy['train']:.2e}"
              + (f", held-out over 10000 steps {energy['held-out, 10000 steps']:.2e}" if args.long else "")
              + f", {seconds:.0f} s", flush=True)
        rows.append({"seed": seed, "train_loss": rec.train_loss, "val_loss": rec.val_loss, "one_step_rms_held_out": rms,
                     "energy_error_max": energy, "fit_s": seconds})
    write_json(out_path(args, f"recipes_{args.system}_{recipe}"), args, {"recipe": recipe, "seeds": rows})


if __name__ == "__main__":
    main()
