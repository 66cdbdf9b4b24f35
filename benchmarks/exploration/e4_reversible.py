"""E4 (the charged particle) with the reversible LPNet: the paper's network (MLP 3x32 sigmoid,
test-flow parametrisation) made R-reversible, on E4's data, with a budget of E4's sweep, measured
as the sweep measures (2000 steps from the data's last point against heyoka).

    python benchmarks/lpnet_accuracy/e4_reversible.py SEED [BUDGET] [ITERATIONS] [eq]

BUDGET: a key of `paper.e4_sweep.BUDGETS` (default adam45k); ITERATIONS: of the fixed-point
iteration in the rollout (default 64; 16, the LPNet default, does not converge here); eq:
equivariant=True (alpha averaged over the sign symmetries, here {id, -id}, which makes the step
reversible under both of the particle's reversing symmetries).
"""
import sys
import time

import learn
import liepoisson as lp
from paper import e4_sweep as sweep

seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
budget = sys.argv[2] if len(sys.argv) > 2 else "adam45k"
iterations = int(sys.argv[3]) if len(sys.argv) > 3 else 64
equivariant = len(sys.argv) > 4 and sys.argv[4] == "eq"
system = lp.systems.ChargedParticle()
model = learn.LPNet(system, hidden=sweep.HIDDEN, activation="sigmoid", key=seed,
                    parametrisation=learn.TestFlowParametrisation(system), reversing="auto",
                    equivariant=equivariant)
t0 = time.perf_counter()
net, rec = learn.fit(model, sweep._data(None), optimiser=sweep.BUDGETS[budget], seed=seed,
                     validation_fraction=0.2, progress=False)
seconds = time.perf_counter() - t0
for k in (16, iterations):
    m = sweep._evaluate(net.with_fixed_point_iterations(k), None)
    print(f"E4 reversible{' equivariant' if equivariant else ''} LPNet {budget} seed {seed}, R = {net.reversing}, {k} iterations: loss {rec.train_loss:.2e} / "
          f"val {rec.val_loss:.2e}, max energy error {m['energy_rel_err_max']:.3e}, max integral error "
          f"{m['integral_rel_err_max']:.3e}, trajectory error (t=200) {sweep._trajectory_error(m)}, fit {seconds:.0f} s",
          flush=True)
