"""Any Lie algebra, end to end: four algebras outside the catalogue, from structure constants
(or a matrix basis) and a Hamiltonian formula to trained LPNets and G-LPNets.

    python -m benchmarks.any_algebra [--epochs 20000] [--bfgs 1000] [--lbfgs 5000] [--seed 0] [--h 0.1]
                                     [--only NAME ...] [--epoch-cost-epochs 1000 11000]
                                     [--out benchmarks/results/any_algebra.json]

Per algebra (and for the catalogue's so(3) rigid body, the reference trained alike): the
Casimirs found (degrees), the observed orders of the automatic splitting (Strang, TripleJump)
against heyoka, then LPNet (3x16); where the system has reversing and sign symmetries the
reversible equivariant LPNet, `learn.Reversible(learn.LPNet(network=learn.GroupAveraged(...)))`
(3x16, Adam `--epochs` then L-BFGS-B `--lbfgs`); G-LPNet and the unstructured MLP baseline
(3x16); and `learn.fit_splitting` (a Strang G-LPNet with linear terms, its pieces then composed
by TripleJump and refitted, BFGS `--bfgs` per stage), trained on the same 2000 pairs at h = 0.1
and rolled out 2000 steps from 10 held-out initial conditions, beside the classical Strang
splitting of the exact H at that h: training loss, max relative energy error, Casimir drift (in
units of the size of the Casimir's terms, `casimir_drift`), Poisson defect, training time. Then
the per-epoch cost of the LPNet on a generic algebra (so(4), matrix exponential path) against
the so(3) closed form at equal data and width. Writes the rows to `--out` (JSON).

`tests/` import `SYSTEMS` and `casimir_drift` from this module; the exploration scripts
(`benchmarks.exploration`) take the systems from here.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import itertools
import multiprocessing
import time
from pathlib import Path

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from benchmarks._report import default_out, write_json
from liepoisson.systems import LiePoissonSystem, RigidBody, reversing_symmetries, sign_symmetries
from paper._systems import diamond

H_STEP = 0.1


def filiform5() -> LiePoissonSystem:
    """5-dim nilpotent (filiform): [e1, e2] = e3, [e1, e3] = e4, [e1, e4] = e5; Casimirs of
    degree 1, 2 and 3."""
    C = np.zeros((5, 5, 5))
    for a, b, d in ((0, 1, 2), (0, 2, 3), (0, 3, 4)):
        C[a, b, d], C[b, a, d] = 1.0, -1.0
    inertia = (1.0, 1.5, 2.0, 2.5, 3.0)
    return LiePoissonSystem(
        lp.LieAlgebra(C, "filiform5"),
        lambda m, xp: sum(0.5 * m[i] ** 2 / inertia[i] for i in range(5)) + 0.1 * xp.cos(m[0]),
        name="filiform5 body",
    )


def so4() -> LiePoissonSystem:
    """6-dim compact semisimple, from the matrices E_ij - E_ji of so(4)."""
    basis = []
    for i, j in itertools.combinations(range(4), 2):
        E = np.zeros((4, 4))
        E[i, j], E[j, i] = 1.0, -1.0
        basis.append(E)
    inertia = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5)
    return LiePoissonSystem(
        lp.LieAlgebra.from_matrices(basis, "so4"),
        lambda m, xp: sum(0.5 * m[i] ** 2 / inertia[i] for i in range(6)) + 0.1 * xp.cos(m[0]),
        name="so4 body",
    )


def sl3() -> LiePoissonSystem:
    """8-dim simple, non-compact, Casimirs tr X^2 and tr X^3 (cubic), from the matrices
    E_ij (i != j), diag(1, -1, 0), diag(0, 1, -1)."""
    basis = []
    for i, j in itertools.permutations(range(3), 2):
        E = np.zeros((3, 3))
        E[i, j] = 1.0
        basis.append(E)
    basis += [np.diag([1.0, -1.0, 0.0]), np.diag([0.0, 1.0, -1.0])]
    inertia = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5)
    return LiePoissonSystem(
        lp.LieAlgebra.from_matrices(basis, "sl3"),
        lambda m, xp: sum(0.5 * m[i] ** 2 / inertia[i] for i in range(8)),
        name="sl3 body",
    )


def rigid_body() -> RigidBody:
    """The catalogue's so(3) rigid body, I = diag(1, 2, 3) (closed-form flows): the reference
    row, trained with the same recipe as the others."""
    return RigidBody(inertia=(1.0, 2.0, 3.0))


SYSTEMS = {"diamond": diamond, "filiform5": filiform5, "so4": so4, "sl3": sl3}


def casimir_drift(y: np.ndarray, system) -> float:
    """max_t |C(y_t) - C(y_0)| per trajectory in units of the size of the Casimir's terms there,
    max_t |y_t|_inf^degree (at least 1): a Casimir whose value is near zero (tr X^3 of sl(3), the
    filiform cubic) is no denominator for a relative drift."""
    algebra = system.algebra
    C = np.asarray(algebra.casimirs(y))  # (n_traj, n_t, k)
    degrees = np.array([p.degree for p in algebra.casimir_polynomials])
    size = np.max(np.abs(y), axis=(-2, -1))[:, None] ** degrees[None, :]  # (n_traj, k)
    return float(np.max(np.abs(C - C[:, :1]).max(axis=1) / np.maximum(size, 1.0)))


def _timed_fit(model, data, **kw):
    t0 = time.perf_counter()
    fitted, record = learn.fit(model, data, progress=False, **kw)
    return fitted, record, time.perf_counter() - t0


def reversible_equivariant_lpnet(system, hidden=(16, 16, 16), key=0) -> learn.Reversible:
    """The LPNet recipe that meets 1e-3 on the compact algebras (BENCHMARKS.md, "LPNet
    accuracy"): alpha averaged over the system's sign symmetries, reversible under the first of
    its reversing symmetries (and so under all of them)."""
    network = learn.GroupAveraged(learn.AffineMLP(system.dim, system.dim, hidden, key=key), sign_symmetries(system))
    return learn.Reversible(learn.LPNet(system, network=network), symmetry="auto")


def _timed_fit_splitting(system, data, bfgs, seed):
    t0 = time.perf_counter()
    fitted, records = learn.fit_splitting(system, data, iterations=bfgs, key=seed, seed=seed, progress=False)
    return fitted, records[-1], time.perf_counter() - t0


MODELS = ("lpnet", "reversible_equivariant", "glpnet", "fit_splitting", "mlp")


def study(system: LiePoissonSystem, epochs: int, bfgs: int, seed: int, h: float = H_STEP,
          lbfgs: int = 5000, models: tuple[str, ...] = MODELS) -> list[dict]:
    """The rows of one system's table (dicts; `table_line` prints one), for the learned maps
    named in `models` (of `MODELS`) and the classical Strang splitting of the exact H."""
    rng = np.random.default_rng(seed)
    y_train = rng.uniform(-1.0, 1.0, size=(40, system.dim))
    y_test = rng.uniform(-1.0, 1.0, size=(10, system.dim))
    degrees = sorted(p.degree for p in system.algebra.casimir_polynomials)
    orders = {
        name: it.convergence(lambda h, m=method: m(system, h=h), system, y_test[:2], t_final=2.0,
                             hs=[0.2, 0.1, 0.05, 0.025]).order
        for name, method in (("Strang", it.splitting.Strang), ("TripleJump", it.splitting.TripleJump))
    }
    data = it.ground_truth(system, y_train, h=h, n_steps=50, seed=seed, progress=False)
    chosen, models = set(models), {}
    if "lpnet" in chosen:
        models["LPNet 3x16"] = _timed_fit(learn.LPNet(system, hidden=(16, 16, 16), key=seed), data,
                                          epochs=epochs, seed=seed)
    if "reversible_equivariant" in chosen and reversing_symmetries(system) and sign_symmetries(system):
        models[f"LPNet 3x16 rev. equiv., + L-BFGS-B {lbfgs}"] = _timed_fit(
            reversible_equivariant_lpnet(system, key=seed), data,
            seed=seed, optimiser=[learn.Adam(epochs), learn.KeepIfBetter(learn.ScipyLBFGSB(lbfgs))])
    if "glpnet" in chosen:
        models["G-LPNet"] = _timed_fit(learn.GLPNet(system, key=seed), data, seed=seed,
                                       optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(bfgs))))
    if "fit_splitting" in chosen:
        models["G-LPNet TripleJump"] = _timed_fit_splitting(system, data, bfgs, seed)
    if "mlp" in chosen:
        models["MLP 3x16"] = _timed_fit(learn.MLPBaseline(system, hidden=(16, 16, 16), key=seed), data,
                                        epochs=epochs, seed=seed)
    # The classical Strang splitting of the exact H at the same h: what a learned map is up against.
    maps = {**{k: v[0] for k, v in models.items()}, "Strang (exact H)": it.splitting.Strang(system, h)}
    cmp = it.compare(maps, system, y_test, t_final=2000 * h, n_outputs=200)
    rows = []
    for row in cmp.rows:
        model = maps[row.label]
        _, record, seconds = models.get(row.label, (model, None, None))
        y = np.asarray(model.rollout(y_test, 2000, save_every=10, nonfinite="return"))
        finite = np.argmax(~np.isfinite(y).any(axis=(0, 2))) or None  # up to the first non-finite output
        drift = casimir_drift(y[:, :finite], system)
        rows.append({
            "system": system.name, "dim": system.dim, "casimir_degrees": degrees, "order_strang": orders["Strang"],
            "order_triple_jump": orders["TripleJump"], "model": row.label,
            "train_loss": None if record is None else record.train_loss, "energy_error_max": row.energy_error_max,
            "casimir_drift_per_size": drift, "poisson_defect_max": row.poisson_defect_max, "train_s": seconds,
        })
    return rows


def table_line(row: dict) -> str:
    """One row of the printed table (BENCHMARKS.md, "Any Lie algebra", quotes from it)."""
    loss, seconds = row["train_loss"], row["train_s"]
    return (f"| {row['system']} ({row['dim']}) | {row['casimir_degrees']} | {row['order_strang']:.2f} / "
            f"{row['order_triple_jump']:.2f} | {row['model']} | {'—' if loss is None else f'{loss:.2e}'} "
            f"| {row['energy_error_max']:.2e} | {row['casimir_drift_per_size']:.1e} | {row['poisson_defect_max']:.1e} "
            f"| {'—' if seconds is None else f'{seconds:.0f}'} |")


def _study_by_name(name: str, epochs: int, bfgs: int, seed: int, h: float, lbfgs: int,
                   models: tuple[str, ...] = MODELS) -> list[dict]:
    return study({"rigid_body": rigid_body, **SYSTEMS}[name](), epochs, bfgs, seed, h, lbfgs, models)


def per_epoch_seconds(system, n_traj: int = 40, hidden=(16, 16, 16), short: int = 1000, long: int = 11_000) -> float:
    """Seconds per Adam epoch of an LPNet (full batch, 40 x 50 = 2000 pairs at h = 0.1): the
    difference of two fits of `short` and `long` epochs (same compiled chunk of 1000 epochs),
    best of two, so compilation and set-up cancel."""
    y0 = np.random.default_rng(0).uniform(-1.0, 1.0, size=(n_traj, system.dim))
    data = it.ground_truth(system, y0, h=H_STEP, n_steps=50, progress=False)
    model = learn.LPNet(system, hidden=hidden, key=0)

    def run(epochs):
        t0 = time.perf_counter()
        learn.fit(model, data, epochs=epochs, validation_fraction=0.0, progress=False)
        return time.perf_counter() - t0

    run(short)
    return (min(run(long) for _ in range(2)) - min(run(short) for _ in range(2))) / (long - short)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.any_algebra", description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=20_000, help="Adam epochs of LPNet and MLP")
    parser.add_argument("--bfgs", type=int, default=1000, help="BFGS iterations of the G-LPNet")
    parser.add_argument("--lbfgs", type=int, default=5000,
                        help="L-BFGS-B iterations of the reversible equivariant LPNet, after Adam")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--h", type=float, default=H_STEP, help="time step of the data and the maps")
    parser.add_argument("--only", nargs="+", choices=["rigid_body", *SYSTEMS, "epoch_cost"],
                        help="run only these rows (default: all, then the per-epoch cost)")
    parser.add_argument("--models", nargs="+", choices=MODELS, default=list(MODELS),
                        help="train only these learned maps (default: all)")
    parser.add_argument("--epoch-cost-epochs", type=int, nargs=2, default=(1000, 11_000), metavar=("SHORT", "LONG"),
                        help="the two fits whose difference is the per-epoch cost")
    parser.add_argument("--out", type=Path, default=default_out("any_algebra"), help="JSON file written")
    args = parser.parse_args(argv)
    only = set(args.only or ["rigid_body", *SYSTEMS, "epoch_cost"])
    print(f"h = {args.h}, 2000 training pairs (40 x 50 steps), rollouts of 2000 steps from 10 held-out "
          f"initial conditions; LPNet/MLP: Adam {args.epochs} epochs; G-LPNet: BFGS {args.bfgs} "
          f"(warm start); G-LPNet TripleJump: learn.fit_splitting, BFGS {args.bfgs} per stage; reversible "
          f"equivariant LPNet: Adam {args.epochs} + L-BFGS-B {args.lbfgs}; seed {args.seed}\n")
    print("| system (dim) | Casimir degrees | Strang / TripleJump order | model | train loss "
          "| max rel. energy error | max Casimir drift / size | max Poisson defect | train [s] |")
    print("|---|---|---|---|---|---|---|---|---|")
    # Each system in a fresh process: a long run of compilations (heyoka and XLA both JIT
    # through LLVM) exhausted the process's memory mappings (vm.max_map_count, 65530 here).
    context = multiprocessing.get_context("spawn")
    results = {"rows": []}
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=context, max_tasks_per_child=1) as pool:
        for name in ("rigid_body", *SYSTEMS):
            if name in only:
                for row in pool.submit(_study_by_name, name, args.epochs, args.bfgs, args.seed, args.h,
                                       args.lbfgs, tuple(args.models)).result():
                    print(table_line(row), flush=True)
                    results["rows"].append(row)
    if "epoch_cost" in only:
        short, long = args.epoch_cost_epochs
        closed = per_epoch_seconds(RigidBody(inertia=(1.0, 2.0, 3.0)), short=short, long=long)
        generic = per_epoch_seconds(so4(), short=short, long=long)
        print(f"\nLPNet 3x16 per Adam epoch, 2000 pairs: so(3) closed form {1e3 * closed:.3f} ms, "
              f"so(4) generic {1e3 * generic:.3f} ms, ratio {generic / closed:.2f}")
        results["epoch_cost"] = {"so3_closed_form_s": closed, "so4_generic_s": generic, "ratio": generic / closed}
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
