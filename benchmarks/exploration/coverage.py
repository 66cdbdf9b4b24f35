"""How far the held-out so(4) trajectories (10 ICs, t = 200) pass from the training states of
recipes.py (40 ICs x 50 pairs at h = 0.1), and with 360 more ICs ("dense"), for seeds 0-2.

    python benchmarks/lpnet_accuracy/coverage.py
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np
from scipy.spatial import cKDTree

import integrators as it

system = aa.so4()
n = system.dim
for seed in (0, 1, 2):
    rng = np.random.default_rng(seed)
    y_train = rng.uniform(-1, 1, size=(40, n))
    y_test = rng.uniform(-1, 1, size=(10, n))
    data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=seed, progress=False)
    pts = np.asarray(data.states).reshape(-1, n)
    tree = cKDTree(pts)
    long = it.ground_truth(system, y_test, h=0.1, n_steps=2000, seed=seed, progress=False)
    Y = np.asarray(long.states)
    d, _ = tree.query(Y.reshape(-1, n))
    d = d.reshape(Y.shape[:2])
    dtr, _ = tree.query(pts, k=2)
    print(f"seed {seed}: NN distance inside training set median {np.median(dtr[:,1]):.3f}; held-out long trajectories: "
          f"median {np.median(d):.3f}, max per IC {np.round(d.max(1),2)}, max |y| {np.abs(Y).max():.2f} vs train {np.abs(pts).max():.2f}")
    dense = rng.uniform(-1, 1, size=(360, n))
    dd = it.ground_truth(system, dense, h=0.1, n_steps=50, seed=seed, progress=False)
    tree2 = cKDTree(np.concatenate([pts, np.asarray(dd.states).reshape(-1, n)]))
    d2, _ = tree2.query(Y.reshape(-1, n))
    print(f"   with dense data: median {np.median(d2):.3f}, max {d2.max():.2f}")
