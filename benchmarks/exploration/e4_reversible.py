"""E4 (the charged particle) with the reversible LPNet: the paper's network (MLP 3x32 sigmoid,
test-flow parametrisation) made R-reversible, on E4's data, with a budget of E4's sweep, measured
as the sweep measures (2000 steps from the data's last point against heyoka).

    python -m benchmarks.exploration.e4_reversible [--seed 0] [--budget adam45k] [--iterations 16 64] [--out FILE]

`--budget`: a key of `paper.e4_sweep.BUDGETS` (or `smoke`, `paper.e4_sweep.SMOKE`);
`--iterations`: the fixed-point iteration counts of the rollout to measure the one fitted model
with (`Reversible.with_iterations`; 16, the default, does not converge on E4). Writes the
figures to `--out` (default `benchmarks/results/exploration/e4_reversible_{budget}_s{seed}.json`).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from benchmarks._report import write_json
from benchmarks.exploration.common import add_out_option, out_path
from paper.e4_charged_particle import HIDDEN, Y0
from paper.e4_sweep import BUDGETS, N_POINTS, PREDICTION_STEPS, SMOKE, H


def figure(x: float) -> str:
    """As E4's sweep table prints a figure."""
    if x == 0:
        return "0"
    return f"{x:.4g}" if 1e-3 <= abs(x) < 1e4 else f"{x:.2e}"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.e4_reversible",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--budget", choices=[*BUDGETS, *SMOKE], default="adam45k", help="a budget of paper.e4_sweep")
    parser.add_argument("--iterations", type=int, nargs="+", default=[16, 64],
                        help="fixed-point iterations of the rollout, one measurement each")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = lp.systems.ChargedParticle()
    # E4's sweep: one trajectory of N_POINTS states, and the reference from its last point
    data = it.ground_truth(system, Y0, h=H, n_steps=N_POINTS - 1, progress=False)
    reference = it.ground_truth(system, data.states[0, -1], h=H, n_steps=PREDICTION_STEPS, progress=False)
    model = learn.Reversible(learn.LPNet(system, hidden=HIDDEN, activation="sigmoid", key=args.seed,
                                         parametrisation=learn.TestFlowParametrisation(system)), symmetry="auto")
    t0 = time.perf_counter()
    net, rec = learn.fit(model, data, optimiser={**BUDGETS, **SMOKE}[args.budget], seed=args.seed,
                         validation_fraction=0.2, progress=False)
    seconds = time.perf_counter() - t0
    rows = []
    for k in args.iterations:
        m = net.with_iterations(k)
        y = np.asarray(m.rollout(reference.states[:, 0], PREDICTION_STEPS, nonfinite="return"))
        f = it.rollout_figures(m, y, reference.states, integrals={"integral": system.angular_integral},
                               defect_points=200, defect_seed=0)
        integral = f.integral_error_max["integral"]
        trajectory = (figure(f.error_final) if f.diverged_at_step is None
                      else f"diverged at step {f.diverged_at_step}")
        print(f"E4 reversible LPNet {args.budget} seed {args.seed}, R = {net.symmetry}, {k} iterations: loss "
              f"{rec.train_loss:.2e} / val {rec.val_loss:.2e}, max energy error {f.energy_error_max:.3e}, max integral "
              f"error {integral:.3e}, trajectory error (t=200) {trajectory}, fit {seconds:.0f} s", flush=True)
        rows.append({"iterations": k, "energy_error_max": f.energy_error_max, "integral_error_max": integral,
                     "trajectory_error_final": f.error_final, "diverged_at_step": f.diverged_at_step,
                     "poisson_defect_max": f.poisson_defect_max})
    write_json(out_path(args, f"e4_reversible_{args.budget}_s{args.seed}"), args, {
        "symmetry": net.symmetry, "train_loss": rec.train_loss, "val_loss": rec.val_loss, "fit_s": seconds,
        "rollouts": rows})


if __name__ == "__main__":
    main()
