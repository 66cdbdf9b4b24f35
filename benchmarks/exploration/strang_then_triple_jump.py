"""The data-driven splitting, stage by stage: a Strang G-LPNet (one module per basis direction)
fitted by BFGS from the identity warm start, its pieces composed by TripleJump, refitted.

    python -m benchmarks.exploration.strang_then_triple_jump --system SYSTEM [--activation sigmoid]
        [--iterations 1000] [--linear-term] [--untied] [--out FILE]

The second stage is, by default, `learn.GLPNet(system, terms=strang.terms, method=TripleJump)`:
the same learned pieces composed by TripleJump, which with `--linear-term` is
`learn.fit_splitting`. `--untied` builds instead the one Strang network of 3n - 2 modules equal
to the TripleJump of the fitted Strang step, in which every copy of a module has its own weights
from then on (what `GLPNet.composed(TripleJump)` did before commit 4efcbec; the figures of
this script in BENCHMARKS.md, "G-LPNet ablation", were measured that way). Prints the losses of
both stages and the energy errors over 2000 steps from the 10 held-out ICs of the Strang stage,
the refit, and the classical Strang and TripleJump splittings of the exact H; writes them to
`--out` (default `benchmarks/results/exploration/strang_then_triple_jump_SYSTEM_ACTIVATION_ITERATIONS[_lt][_untied].json`).
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    H,
    add_out_option,
    add_system_option,
    initial_conditions,
    out_path,
    training_data,
)


def palindrome(n_modules: int, gammas: np.ndarray) -> tuple[list[int], list[float]]:
    r"""Modules and weights of the Strang network equal to $S_{\gamma_r h}\circ\cdots\circ
    S_{\gamma_1 h}$ for a Strang step $S$ of `n_modules` modules: the flows (module, time in
    units of $h$) of the composition, adjacent flows of one module merged, are a palindrome
    whose first half (run over $h/2$: weight $2\tau$) and centre (run over $h$: weight $\tau$)
    are the new modules."""
    half = list(range(n_modules - 1))
    flows: list[list] = []
    for g in gammas:
        for s, tau in [(s, 0.5 * g) for s in half] + [(n_modules - 1, g)] + [(s, 0.5 * g) for s in reversed(half)]:
            if flows and flows[-1][0] == s:
                flows[-1][1] += tau
            else:
                flows.append([s, tau])
    centre = len(flows) // 2
    return [s for s, _ in flows[: centre + 1]], [2.0 * tau for _, tau in flows[:centre]] + [flows[centre][1]]


def untied_composition(strang: learn.GLPNet, method) -> learn.GLPNet:
    """The Strang G-LPNet equal to `method` (a composition of Strang steps) of `strang`'s step,
    with a module of its own for every flow: module s run over gamma h / 2 is module s with
    (a_s, b_s, e_s) scaled by gamma."""
    t = strang.terms
    modules, weights = palindrome(t.n_modules, np.asarray(method.coefficients))
    src, w = jnp.asarray(modules), jnp.asarray(weights)
    terms = learn.RidgeTerms(t.dim, len(modules), [t.order[m] for m in modules], activation=t.activation,
                             full_vectors=t.full_vectors, linear_term=t.linear_term)
    terms = eqx.tree_at(lambda r: (r.a, r.c, r.b), terms, (t.a[src] * w, t.c[src], t.b[src] * w))
    if t.linear_term:
        terms = eqx.tree_at(lambda r: r.e, terms, t.e[src] * w)
    return learn.GLPNet(strang.system, terms=terms, method=it.splitting.Strang, h=strang.h)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.strang_then_triple_jump",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser)
    parser.add_argument("--activation", choices=["sigmoid", "identity", "tanh"], default="sigmoid")
    parser.add_argument("--iterations", type=int, default=1000, help="BFGS iterations per stage")
    parser.add_argument("--linear-term", action="store_true", help="a linear term in each module's rate")
    parser.add_argument("--untied", action="store_true",
                        help="every copy of a module its own weights in the refit (the old GLPNet.composed)")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    n = system.dim
    y_train, y_test = initial_conditions(n, 0)
    data = training_data(system, y_train, 0)
    X0, X1 = data.pairs()
    t0 = time.perf_counter()
    net = learn.GLPNet(system, n, key=0, method=it.splitting.Strang, activation=args.activation,
                       linear_term=args.linear_term)
    s1, r1 = learn.fit(net, data, seed=0, progress=False,
                       optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(args.iterations))))
    t1 = time.perf_counter() - t0
    tj = (untied_composition(s1, it.splitting.TripleJump) if args.untied
          else learn.GLPNet(system, terms=s1.terms, method=it.splitting.TripleJump, h=s1.h))
    mse = float(np.mean((np.asarray(tj.rollout(X0, 1))[:, -1] - X1) ** 2))
    print("strang-fit loss", r1.train_loss, "tj init mse", mse, flush=True)
    t0 = time.perf_counter()
    s2, r2 = learn.fit(tj, data, seed=0, progress=False,
                       optimiser=learn.KeepIfBetter(learn.ScipyBFGS(args.iterations)))
    t2 = time.perf_counter() - t0
    maps = {"strangfit": s1, "tj": s2, "strang": it.splitting.Strang(system, H),
            "TJ exact": it.splitting.TripleJump(system, H)}
    cmp = it.compare(maps, system, y_test, t_final=200.0, n_outputs=200)
    print(args.system, args.activation, args.iterations, f"loss1={r1.train_loss:.2e} loss2={r2.train_loss:.2e}",
          " ".join(f"{r.label}:E={r.energy_error_max:.2e}" for r in cmp.rows), f"{t1:.0f}+{t2:.0f}s", flush=True)
    name = (f"strang_then_triple_jump_{args.system}_{args.activation}_{args.iterations}"
            f"{'_lt' if args.linear_term else ''}{'_untied' if args.untied else ''}")
    write_json(out_path(args, name), args, {
        "strang_stage": {"train_loss": r1.train_loss, "val_loss": r1.val_loss, "fit_s": t1},
        "triple_jump_initial_mse": mse, "n_modules_refit": tj.n_modules,
        "refit": {"train_loss": r2.train_loss, "val_loss": r2.val_loss, "fit_s": t2},
        "energy_error_max": {r.label: r.energy_error_max for r in cmp.rows}})


if __name__ == "__main__":
    main()
