"""E1's protocol on any system of benchmarks/any_algebra.py: one trajectory of 1000 points at
h = 0.1 (80/20 split), an LPNet 3x16 trained by Adam then L-BFGS-B, rolled out 10,000 steps from
the trajectory's end point (on the training orbit, as in E1).

    python benchmarks/lpnet_accuracy/one_trajectory.py SYSTEM [ADAM] [LBFGS] [SEED ...]

Prints per seed the train / validation loss and the max relative energy error of the rollout.
The IC: E1's Pi0 = (1/sqrt2, -1/sqrt2, 1) for the rigid body, else uniform in [-1, 1]^dim
(numpy seed 0).
"""
import sys
import time

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np

import integrators as it
import learn

name = sys.argv[1]
adam = int(sys.argv[2]) if len(sys.argv) > 2 else 20_000
lbfgs = int(sys.argv[3]) if len(sys.argv) > 3 else 5000
seeds = [int(s) for s in sys.argv[4:]] or [0]
system = {"rigid_body": aa.rigid_body, **aa.SYSTEMS}[name]()
y0 = (np.array([2**-0.5, -(2**-0.5), 1.0]) if name == "rigid_body"
      else np.random.default_rng(0).uniform(-1, 1, size=system.dim))
data = it.ground_truth(system, y0[None], h=0.1, n_steps=999, progress=False)
end = np.asarray(data.states)[:, -1]
for seed in seeds:
    stages = [learn.Adam(adam)] + ([learn.QuasiNewton(lbfgs, "lbfgsb")] if lbfgs else [])
    t0 = time.perf_counter()
    net, rec = learn.fit(learn.LPNet(system, hidden=(16, 16, 16), key=seed), data, optimiser=stages, seed=seed,
                         progress=False)
    seconds = time.perf_counter() - t0
    row = it.compare({"lpnet": net}, system, end, t_final=1000.0, n_outputs=500).rows[0]
    print(f"{name} one trajectory, Adam {adam} + L-BFGS-B {lbfgs}, seed {seed}: loss {rec.train_loss:.2e} / val "
          f"{rec.val_loss:.2e}, max energy error over 10,000 steps {row.energy_error_max:.2e}, {seconds:.0f} s",
          flush=True)
