"""Exploration: Levenberg-Marquardt on the weights of a reversible LPNet saved by per_ic.py
(`--save`), on the same data, then the max energy error per held-out IC over 2000 steps. Not a
library optimiser: a dense Jacobian by forward mode (13 s per iteration on 2 cores for so(4)).

    python -m benchmarks.exploration.levenberg_marquardt --model MODEL.h5 [--iterations 60]
        [--system so4] [--seed 0] [--save REFINED.h5] [--out FILE]

`--seed` must be the seed of the per_ic.py run that wrote `--model` (it draws the data and the
train/validation split, as `learn.fit` did). Writes the losses and the energy errors to `--out`
(default `benchmarks/results/exploration/levenberg_marquardt_SYSTEM_s{seed}_{iterations}.json`).
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

import learn
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    add_out_option,
    add_system_option,
    initial_conditions,
    out_path,
    relative_energy_error,
    training_data,
)
from liepoisson import vmap_samples


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.levenberg_marquardt",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--model", required=True, help="a reversible LPNet written by per_ic.py --save")
    parser.add_argument("--iterations", type=int, default=60)
    add_system_option(parser, default="so4")
    parser.add_argument("--seed", type=int, default=0, help="the data seed of the per_ic.py run")
    parser.add_argument("--save", help="write the refined model to this HDF5 file")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    y_train, y_test = initial_conditions(system.dim, args.seed)
    data = training_data(system, y_train, args.seed)
    net = learn.Reversible.load(args.model, system)
    # learn.fit's split: validation_fraction 0.2, seeded by the fit's seed
    (X, T), (Xv, Tv) = (tuple(jnp.asarray(a.reshape(-1, system.dim)) for a in part)
                        for part in data.split(0.2, args.seed))
    params, static = eqx.partition(net, eqx.is_inexact_array)
    x0, unravel = ravel_pytree(params)
    print("params", x0.size, "pairs", X.shape, flush=True)

    def resid(x, X, T):
        m = eqx.combine(unravel(x), static)
        return (vmap_samples(m.training_prediction)(X, T) - T).ravel()

    @jax.jit
    def normal(x):
        r = resid(x, X, T)
        J = jax.jacfwd(resid)(x, X, T)
        return r @ r, J.T @ J, J.T @ r

    loss = jax.jit(lambda x, X, T: jnp.mean(resid(x, X, T) ** 2))
    x, lam = x0, 1e-3
    t0 = time.perf_counter()
    f, A, g = normal(x)
    history = [{"iteration": -1, "train_loss": float(f / X.size), "val_loss": float(loss(x, Xv, Tv))}]
    print("initial", history[0]["train_loss"], history[0]["val_loss"], f"{time.perf_counter() - t0:.1f}s", flush=True)
    stalled = False
    for k in range(args.iterations):
        D = jnp.diag(A)
        while True:
            step = jnp.linalg.solve(A + lam * jnp.diag(D + 1e-12 * jnp.max(D)), -g)
            xn = x + step
            fn = float(jnp.sum(resid(xn, X, T) ** 2))
            if np.isfinite(fn) and fn < f:
                x, lam = xn, max(lam / 3, 1e-12)
                break
            lam *= 4
            if lam > 1e12:
                stalled = True
                break
        if stalled:
            print("stalled")
            break
        f, A, g = normal(x)
        if k % 10 == 0 or k == args.iterations - 1:
            history.append({"iteration": k, "train_loss": float(f / X.size), "val_loss": float(loss(x, Xv, Tv)),
                            "damping": lam, "seconds": time.perf_counter() - t0})
            print(k, f"train {history[-1]['train_loss']:.3e} val {history[-1]['val_loss']:.3e} lam {lam:.1e} "
                  f"{time.perf_counter() - t0:.0f}s", flush=True)
    net = eqx.combine(unravel(x), static)
    if args.save:
        net.save(args.save)
    e = relative_energy_error(system, np.asarray(net.rollout(y_test, 2000))).max(axis=1)
    print("energy max per IC", np.array2string(e, precision=2), "max", f"{e.max():.2e}", "median",
          f"{np.median(e):.2e}")
    write_json(out_path(args, f"levenberg_marquardt_{args.system}_s{args.seed}_{args.iterations}"), args,
               {"history": history, "stalled": stalled, "energy_error_max_per_ic_2000_steps": e})


if __name__ == "__main__":
    main()
