"""Strang-stage fit, composed by TripleJump, refit: python benchmarks/glpnet_ablation/strang_then_triple_jump.py SYSTEM sigmoid ITERATIONS [lt]
(lt: linear_term=True)."""
import sys
import time

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np

import integrators as it
import learn

name = sys.argv[1]; act = sys.argv[2]; LT = len(sys.argv) > 4; iters = int(sys.argv[3])
system = {"rigid_body": aa.rigid_body, **aa.SYSTEMS}[name]()
n = system.dim
rng = np.random.default_rng(0)
y_train = rng.uniform(-1, 1, size=(40, n)); y_test = rng.uniform(-1, 1, size=(10, n))
data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=0, progress=False)
t0 = time.perf_counter()
s1, r1 = learn.fit(learn.GLPNet(system, n_modules=n, key=0, symmetric=True, activation=act, linear_term=LT), data, seed=0,
                   progress=False, optimiser=learn.QuasiNewton(iters, "bfgs", warm_start=True))
t1 = time.perf_counter() - t0
tj = s1.composed(it.splitting.TripleJump)
Y = np.asarray(data.states); X0 = Y[:, :-1].reshape(-1, n); X1 = Y[:, 1:].reshape(-1, n)
mse = lambda m: float(np.mean((np.asarray(m.rollout(X0, 1))[:, -1] - X1) ** 2))
print("strang-fit loss", r1.train_loss, "tj init mse", mse(tj), flush=True)
t0 = time.perf_counter()
s2, r2 = learn.fit(tj, data, seed=0, progress=False, optimiser=learn.QuasiNewton(iters, "bfgs", warm_start=False))
t2 = time.perf_counter() - t0
maps = {"strangfit": s1, "tj": s2, "strang": it.splitting.Strang(system, 0.1), "TJ exact": it.splitting.TripleJump(system, 0.1)}
cmp = it.compare(maps, system, y_test, t_final=200.0, n_outputs=200)
print(name, act, iters, f"loss1={r1.train_loss:.2e} loss2={r2.train_loss:.2e}", " ".join(f"{r.label}:E={r.energy_error_max:.2e}" for r in cmp.rows), f"{t1:.0f}+{t2:.0f}s", flush=True)
