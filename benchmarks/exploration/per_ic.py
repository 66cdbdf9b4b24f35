"""The reversible so(4) LPNet per held-out initial condition: energy error over 2000 steps, the
distance of the exact trajectory to the nearest training state, and the one-step error along it.

    python benchmarks/lpnet_accuracy/per_ic.py SEED LBFGS_ITERATIONS EXTRA_ICS WIDTH [R] [eq]

Data as recipes.py (40 ICs x 50 pairs at h = 0.1 in [-1, 1]^6, plus EXTRA_ICS more), Adam 20000
then L-BFGS-B; R: which of `reversing_symmetries` (an index; default "auto", the first); eq:
equivariant=True. The fitted model is saved to so4_rev_s*.h5 in the working directory. Also
prints the energy error per IC over 2000 and over 10000 steps.
"""
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np
from scipy.spatial import cKDTree

import integrators as it
import learn
from liepoisson.systems import reversing_symmetries

system = aa.so4(); n = system.dim
seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
lb = int(sys.argv[2]) if len(sys.argv) > 2 else 5000
dense = int(sys.argv[3]) if len(sys.argv) > 3 else 0
width = int(sys.argv[4]) if len(sys.argv) > 4 else 16
which = sys.argv[5] if len(sys.argv) > 5 else "auto"
equivariant = len(sys.argv) > 6 and sys.argv[6] == "eq"
reversing = "auto" if which == "auto" else reversing_symmetries(system)[int(which)]
rng = np.random.default_rng(seed)
y_train = rng.uniform(-1, 1, size=(40, n)); y_test = rng.uniform(-1, 1, size=(10, n))
if dense:
    y_train = np.concatenate([y_train, rng.uniform(-1, 1, size=(dense, n))])
data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=seed, progress=False)
t0 = time.perf_counter()
net, rec = learn.fit(learn.LPNet(system, hidden=(width,) * 3, key=seed, reversing=reversing, equivariant=equivariant), data,
                     optimiser=[learn.Adam(20_000), learn.QuasiNewton(lb, "lbfgsb")], seed=seed, progress=False)
print(f"R = {[int(r) for r in net.reversing]}{', equivariant' if equivariant else ''}: loss {rec.train_loss:.2e} "
      f"val {rec.val_loss:.2e}, {time.perf_counter()-t0:.0f} s", flush=True)
net.save(f"so4_rev_s{seed}_lb{lb}_d{dense}_w{width}_r{which}{'_eq' if equivariant else ''}.h5")
tree = cKDTree(np.asarray(data.states).reshape(-1, n))
ref = np.asarray(it.ground_truth(system, y_test, h=0.1, n_steps=2000, seed=seed, progress=False).states)
Y = np.asarray(net.rollout(y_test, 2000))
H = np.asarray(system.hamiltonian(Y)); H0 = H[:, :1]
e = np.abs(H - H0) / np.abs(H0)
d, _ = tree.query(ref.reshape(-1, n)); d = d.reshape(ref.shape[:2])
one = np.asarray(net.rollout(ref[:, :-1].reshape(-1, n), 1))[:, -1].reshape(ref[:, 1:].shape) - ref[:, 1:]
for i in range(10):
    print(f"IC {i}: H0 {H0[i,0]:.3f}, energy err max {e[i].max():.2e} (at step {e[i].argmax()}), at 500 {e[i,:500].max():.2e}, "
          f"coverage NN dist median {np.median(d[i]):.3f} max {d[i].max():.3f}, one-step err along exact traj median {np.median(np.linalg.norm(one[i],axis=-1)):.1e} max {np.linalg.norm(one[i],axis=-1).max():.1e}")
long = np.asarray(net.rollout(y_test, 10_000))
E = np.asarray(system.hamiltonian(long))
E = np.abs(E - E[:, :1]) / np.abs(E[:, :1])
print("max energy error per IC over 2000 steps: " + " ".join(f"{v:.1e}" for v in E[:, :2001].max(axis=1)))
print("max energy error per IC over 10000 steps: " + " ".join(f"{v:.1e}" for v in E.max(axis=1)))
