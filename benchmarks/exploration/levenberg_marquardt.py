"""Exploration: Levenberg-Marquardt on the weights of a so(4) LPNet saved by per_ic.py (seed 0
data), then the max energy error per held-out IC over 2000 steps. Not a library optimiser: a
dense Jacobian by forward mode (13 s per iteration on 2 cores here).

    python benchmarks/lpnet_accuracy/levenberg_marquardt.py MODEL.h5 ITERATIONS
"""
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import any_algebra as aa
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

import integrators as it
import learn
from learn._data import prepare
from liepoisson import vmap_samples

system = aa.so4(); n = system.dim
seed = 0
src = sys.argv[1]; iters = int(sys.argv[2])
rng = np.random.default_rng(seed)
y_train = rng.uniform(-1, 1, size=(40, n)); y_test = rng.uniform(-1, 1, size=(10, n))
data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=seed, progress=False)
net = learn.LPNet.load(src, system)
pairs = prepare(data, system, None, 0.2, seed, conserves_casimirs=True)
X, T = jnp.asarray(pairs.y0), jnp.asarray(pairs.y1)
Xv, Tv = jnp.asarray(pairs.y0_val), jnp.asarray(pairs.y1_val)
params, static = eqx.partition(net, eqx.is_inexact_array)
x0, unravel = ravel_pytree(params)
print("params", x0.size, "pairs", X.shape, flush=True)

def resid(x, X, T):
    m = eqx.combine(unravel(x), static)
    return (vmap_samples(m.training_prediction)(X, T) - T).ravel()

@jax.jit
def normal(x):
    r = resid(x, X, T)
    J = jax.jacfwd(resid)(x, X, T)
    return r @ r, J.T @ J, J.T @ r

loss = jax.jit(lambda x, X, T: jnp.mean(resid(x, X, T) ** 2))
x = x0; lam = 1e-3
t0 = time.perf_counter()
f, A, g = normal(x)
print("initial", f / X.size, loss(x, Xv, Tv), f"{time.perf_counter()-t0:.1f}s", flush=True)
for k in range(iters):
    D = jnp.diag(A)
    while True:
        step = jnp.linalg.solve(A + lam * jnp.diag(D + 1e-12 * jnp.max(D)), -g)
        xn = x + step
        fn = float(jnp.sum(resid(xn, X, T) ** 2))
        if np.isfinite(fn) and fn < f:
            x = xn; lam = max(lam / 3, 1e-12); break
        lam *= 4
        if lam > 1e12: break
    if lam > 1e12: print("stalled"); break
    f, A, g = normal(x)
    if k % 10 == 0 or k == iters - 1:
        print(k, f"train {f / X.size:.3e} val {float(loss(x, Xv, Tv)):.3e} lam {lam:.1e} {time.perf_counter()-t0:.0f}s", flush=True)
net = eqx.combine(unravel(x), static)
net.save(f"so4_lm_{iters}.h5")
ref = np.asarray(it.ground_truth(system, y_test, h=0.1, n_steps=2000, seed=seed, progress=False).states)
Y = np.asarray(net.rollout(y_test, 2000))
H = np.asarray(system.hamiltonian(Y)); H0 = H[:, :1]
e = np.abs(H - H0) / np.abs(H0)
print("energy max per IC", np.array2string(e.max(axis=1), precision=2), "max", f"{e.max():.2e}", "median", f"{np.median(e.max(axis=1)):.2e}")
