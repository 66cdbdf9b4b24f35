"""One G-LPNet variant trained like benchmarks/any_algebra.py: python benchmarks/glpnet_ablation/variants.py SYSTEM VARIANT [ITERATIONS]."""
import sys
import time

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
import any_algebra as aa
import numpy as np

import integrators as it
import learn

name = sys.argv[1]; variant = sys.argv[2]; iters = int(sys.argv[3]) if len(sys.argv) > 3 else 1000
system = {"rigid_body": aa.rigid_body, **aa.SYSTEMS}[name]()
n = system.dim
rng = np.random.default_rng(0)
y_train = rng.uniform(-1, 1, size=(40, n)); y_test = rng.uniform(-1, 1, size=(10, n))
data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=0, progress=False)
kw = {}
if variant == "default": pass
elif variant == "sym": kw = {"symmetric": True}
elif variant == "tj":  # palindrome representing a triple jump of Strang
    order = list(range(n)) + list(range(n - 2, -1, -1)) + list(range(1, n))
    kw = {"symmetric": True, "n_modules": len(order), "order": order}
elif variant == "tj_full":
    order = list(range(n)) + list(range(n - 2, -1, -1)) + list(range(1, n))
    kw = {"symmetric": True, "n_modules": len(order), "order": order, "full_vectors": True}
elif variant == "sym3":  # 3 sweeps
    order = list(range(n)) * 3
    kw = {"symmetric": True, "n_modules": len(order), "order": order}
elif variant == "id":
    kw = {"activation": "identity"}
elif variant == "idsym":
    kw = {"activation": "identity", "symmetric": True}
elif variant == "idtj":
    order = list(range(n)) + list(range(n - 2, -1, -1)) + list(range(1, n))
    kw = {"symmetric": True, "n_modules": len(order), "order": order, "activation": "identity"}
elif variant == "def3":
    kw = {"n_modules": 3 * n}
net = learn.GLPNet(system, key=0, **kw)
t0 = time.perf_counter()
fitted, rec = learn.fit(net, data, seed=0, progress=False, optimiser=learn.QuasiNewton(iters, "bfgs", warm_start=True))
t = time.perf_counter() - t0
cmp = it.compare({"g": fitted, "strang": it.splitting.Strang(system, 0.1)}, system, y_test, t_final=200.0, n_outputs=200)
print(name, variant, iters, f"M={fitted.n_modules} loss={rec.train_loss:.2e}", " ".join(f"{r.label}:E={r.energy_error_max:.2e}" for r in cmp.rows), f"{t:.0f}s", flush=True)
