"""The state loss of classical splittings of the exact H on the benchmark's training pairs: python benchmarks/glpnet_ablation/classical_loss.py SYSTEM."""
import sys

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np

import integrators as it

name = sys.argv[1]
system = {"rigid_body": aa.rigid_body, **aa.SYSTEMS}[name]()
n = system.dim
rng = np.random.default_rng(0)
y_train = rng.uniform(-1, 1, size=(40, n))
data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=0, progress=False)
Y = np.asarray(data.states)  # (n_traj, n_t, dim)
X0 = Y[:, :-1].reshape(-1, n); X1 = Y[:, 1:].reshape(-1, n)
for M in (it.splitting.Strang, it.splitting.TripleJump, it.splitting.Yoshida6 if hasattr(it.splitting, "Yoshida6") else None):
    if M is None: continue
    m = M(system, 0.1)
    P = np.asarray(m.rollout(X0, 1))[:, -1]
    print(M.__name__, "mse", np.mean((P - X1) ** 2))
