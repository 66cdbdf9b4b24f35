"""The reversible so(4) LPNet per held-out initial condition: energy error over 2000 steps, the
distance of the exact trajectory to the nearest training state, and the one-step error along it.

    python -m benchmarks.exploration.per_ic [--system so4] [--seed 0] [--adam 20000] [--lbfgs 5000]
        [--extra-ics 0] [--width 16] [--symmetry auto|INDEX] [--equivariant] [--save MODEL.h5] [--out FILE]

Data as recipes.py (40 ICs x 50 pairs at h = 0.1 in [-1, 1]^dim, plus `--extra-ics` more),
Adam then L-BFGS-B; `--symmetry`: the reversing symmetry, `auto` (the first of
`liepoisson.systems.reversing_symmetries`) or an index into that list; `--equivariant`: the
network averaged over the sign symmetries. `--save` writes the fitted model (read back by
`learn.Reversible.load`; levenberg_marquardt.py refines it). Also prints the energy error per IC
over 2000 and over 10000 steps. Writes the figures to `--out` (default
`benchmarks/results/exploration/per_ic_SYSTEM_s{seed}_lb{lbfgs}_d{extra}_w{width}_r{symmetry}[_eq].json`).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial import cKDTree

import integrators as it
import learn
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    H,
    add_out_option,
    add_system_option,
    initial_conditions,
    lpnet,
    out_path,
    relative_energy_error,
    training_data,
)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.per_ic", description=__doc__.splitlines()[0])
    add_system_option(parser, default="so4")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--adam", type=int, default=20_000, help="Adam epochs")
    parser.add_argument("--lbfgs", type=int, default=5000, help="L-BFGS-B iterations after Adam")
    parser.add_argument("--extra-ics", type=int, default=0, help="training ICs beyond the benchmark's 40")
    parser.add_argument("--width", type=int, default=16, help="hidden width (3 layers)")
    parser.add_argument("--symmetry", default="auto", help="'auto' or an index into reversing_symmetries(system)")
    parser.add_argument("--equivariant", action="store_true", help="the network averaged over the sign symmetries")
    parser.add_argument("--save", help="write the fitted model to this HDF5 file")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    n = system.dim
    symmetry = "auto" if args.symmetry == "auto" else int(args.symmetry)
    y_train, y_test = initial_conditions(n, args.seed, args.extra_ics)
    data = training_data(system, y_train, args.seed)
    t0 = time.perf_counter()
    net, rec = learn.fit(lpnet(system, width=args.width, key=args.seed, symmetry=symmetry, equivariant=args.equivariant),
                         data, optimiser=[learn.Adam(args.adam), learn.KeepIfBetter(learn.ScipyLBFGSB(args.lbfgs))], seed=args.seed,
                         progress=False)
    seconds = time.perf_counter() - t0
    r = [int(v) for v in net.symmetry]
    print(f"R = {r}{', equivariant' if args.equivariant else ''}: loss {rec.train_loss:.2e} val {rec.val_loss:.2e}, "
          f"{seconds:.0f} s", flush=True)
    if args.save:
        net.save(args.save)
    tree = cKDTree(np.asarray(data.states).reshape(-1, n))
    ref = np.asarray(it.ground_truth(system, y_test, h=H, n_steps=2000, seed=args.seed, progress=False).states)
    e = relative_energy_error(system, np.asarray(net.rollout(y_test, 2000)))
    d, _ = tree.query(ref.reshape(-1, n))
    d = d.reshape(ref.shape[:2])
    one = np.asarray(net.rollout(ref[:, :-1].reshape(-1, n), 1))[:, -1].reshape(ref[:, 1:].shape) - ref[:, 1:]
    one = np.linalg.norm(one, axis=-1)
    H0 = np.asarray(system.hamiltonian(y_test))
    per_ic = []
    for i in range(len(y_test)):
        print(f"IC {i}: H0 {H0[i]:.3f}, energy err max {e[i].max():.2e} (at step {e[i].argmax()}), at 500 "
              f"{e[i, :500].max():.2e}, coverage NN dist median {np.median(d[i]):.3f} max {d[i].max():.3f}, one-step "
              f"err along exact traj median {np.median(one[i]):.1e} max {one[i].max():.1e}")
        per_ic.append({"H0": H0[i], "energy_error_max": e[i].max(), "at_step": int(e[i].argmax()),
                       "energy_error_max_500_steps": e[i, :500].max(), "nn_distance_median": np.median(d[i]),
                       "nn_distance_max": d[i].max(), "one_step_error_median": np.median(one[i]),
                       "one_step_error_max": one[i].max()})
    E = relative_energy_error(system, np.asarray(net.rollout(y_test, 10_000)))
    e2000, e10000 = E[:, :2001].max(axis=1), E.max(axis=1)
    print("max energy error per IC over 2000 steps: " + " ".join(f"{v:.1e}" for v in e2000))
    print("max energy error per IC over 10000 steps: " + " ".join(f"{v:.1e}" for v in e10000))
    name = (f"per_ic_{args.system}_s{args.seed}_lb{args.lbfgs}_d{args.extra_ics}_w{args.width}_r{args.symmetry}"
            f"{'_eq' if args.equivariant else ''}")
    write_json(out_path(args, name), args, {
        "symmetry": r, "train_loss": rec.train_loss, "val_loss": rec.val_loss, "fit_s": seconds, "per_ic": per_ic,
        "energy_error_max_2000_steps": e2000, "energy_error_max_10000_steps": e10000,
    })


if __name__ == "__main__":
    main()
