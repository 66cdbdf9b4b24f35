"""Which held-out orbits meet the fixed set of each reversing symmetry: a reversible map has no
secular energy drift on an orbit that meets Fix(R) (a symmetric orbit), and may drift on one
that does not.

    python benchmarks/lpnet_accuracy/fixed_sets.py SYSTEM [SEED ...]

The benchmark's held-out ICs (recipes.py: 10, uniform in [-1, 1]^dim after the 40 training
ICs) integrated by heyoka over 10000 steps of h = 0.1; per R = diag(r) of
`liepoisson.systems.reversing_symmetries`, the minimum over the orbit of the distance to
Fix(R) = {y : the flipped components vanish}, relative to the orbit's mean |y|.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np

import integrators as it
from liepoisson.systems import reversing_symmetries

name = sys.argv[1]
seeds = [int(s) for s in sys.argv[2:]] or [0]
system = {"rigid_body": aa.rigid_body, **aa.SYSTEMS}[name]()
n = system.dim
for seed in seeds:
    rng = np.random.default_rng(seed)
    rng.uniform(-1, 1, size=(40, n))  # the training ICs, drawn first
    y_test = rng.uniform(-1, 1, size=(10, n))
    y = np.asarray(it.ground_truth(system, y_test, h=0.1, n_steps=10_000, seed=seed, progress=False).states)
    for r in reversing_symmetries(system):
        flipped = r < 0
        d = np.linalg.norm(y[..., flipped], axis=-1).min(axis=1) / np.linalg.norm(y, axis=-1).mean(axis=1)
        print(f"{name} seed {seed} R = {r.astype(int).tolist()}: distance to Fix(R) per IC "
              + " ".join(f"{v:.3f}" for v in d) + f"; {int(np.sum(d < 0.05))}/10 below 0.05", flush=True)
