"""Why the LPNet of benchmarks/any_algebra.py misses 1e-3 on the compact algebras: one system,
one recipe, several seeds, on the benchmark's data (40 ICs x 50 pairs at h = 0.1, uniform in
[-1, 1]^dim; 10 held-out ICs).

    python benchmarks/lpnet_accuracy/recipes.py SYSTEM RECIPE [SEED ...]

RECIPE: words joined by "_": adam (Adam 20000 only, the benchmark's), lbfgs (then L-BFGS-B
5000 iterations; lbfgsN: N), norm (normalise=True), dense (10x the trajectories, 400 x 50 pairs), wN (hidden width N
instead of 16), skip (a linear skip in the parameter network, alpha(y) = MLP(y) + L y, L
trained from zero), rev (the reversible LPNet, reversing="auto"), eq (equivariant=True: alpha
averaged over the system's sign symmetries), long (also the held-out ICs over 10000 steps), e.g.
adam_lbfgs30000_skip or adam_lbfgs_rev_eq_long.
Prints per seed: train / validation loss, the one-step RMS error at the held-out ICs' first
steps, the max relative energy error over 2000 steps from the held-out ICs and from 10 of the
training ICs.
"""
import sys
import time

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
import any_algebra as aa
import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import learn


class SkipLPNet(learn.LPNet):
    """alpha(y) = MLP(y) + L y (exploration only: not saved, not in the library)."""

    skip: jax.Array

    def __init__(self, system, **kw):
        super().__init__(system, **kw)
        self.skip = jnp.zeros((self.parametrisation.n_params, system.dim))

    def alpha(self, y):
        return self.network(y) + self.skip @ y


name, recipe = sys.argv[1], sys.argv[2]
words = recipe.split("_")
width = next((int(w[1:]) for w in words if w[0] == "w" and w[1:].isdigit()), 16)
seeds = [int(s) for s in sys.argv[3:]] or [0]
if "skip" in words and "eq" in words:
    sys.exit("skip overrides alpha, so it would drop the equivariant average: use one or the other")
system = {"rigid_body": aa.rigid_body, **aa.SYSTEMS}[name]()
n = system.dim
for seed in seeds:
    rng = np.random.default_rng(seed)
    y_train = rng.uniform(-1, 1, size=(40, n))
    y_test = rng.uniform(-1, 1, size=(10, n))
    if "dense" in words:
        y_train = np.concatenate([y_train, rng.uniform(-1, 1, size=(360, n))])
    data = it.ground_truth(system, y_train, h=0.1, n_steps=50, seed=seed, progress=False)
    test = it.ground_truth(system, y_test, h=0.1, n_steps=50, seed=seed, progress=False)
    stages = [learn.Adam(20_000)]
    lbfgs = next((int(w[5:] or 5000) for w in words if w.startswith("lbfgs")), 0)
    if lbfgs:
        stages.append(learn.QuasiNewton(lbfgs, "lbfgsb"))
    t0 = time.perf_counter()
    model = (SkipLPNet if "skip" in words else learn.LPNet)(
        system, hidden=(width,) * 3, key=seed, reversing="auto" if "rev" in words else None,
        **({"equivariant": True} if "eq" in words else {}))
    net, rec = learn.fit(model, data, optimiser=stages, seed=seed, normalise="norm" in words, progress=False)
    seconds = time.perf_counter() - t0
    y = np.asarray(test.states)
    pred = np.asarray(net.rollout(y[:, 0], 1))[:, -1]
    rms = float(np.sqrt(np.mean((pred - y[:, 1]) ** 2)))
    energy = {}
    for label, y0 in (("held-out", y_test), ("train", y_train[:10])):
        row = it.compare({"lpnet": net}, system, y0, t_final=200.0, n_outputs=200).rows[0]
        energy[label] = row.energy_error_max
    if "long" in words:
        row = it.compare({"lpnet": net}, system, y_test, t_final=1000.0, n_outputs=200).rows[0]
        energy["held-out, 10000 steps"] = row.energy_error_max
    print(f"{name} {recipe} seed {seed}: loss {rec.train_loss:.2e} / val {rec.val_loss:.2e}, one-step RMS at "
          f"held-out ICs {rms:.2e}, max energy error held-out {energy['held-out']:.2e}, train ICs "
          f"{energy['train']:.2e}"
          + (f", held-out over 10000 steps {energy['held-out, 10000 steps']:.2e}" if "long" in words else "")
          + f", {seconds:.0f} s", flush=True)
