r"""An LPNet's lifted step: the attitude it predicts with a phase network fitted to
configurations (`learn.fit_phase`), without one (rates at zero: the Casimir-projected
parameters' turn alone), and heyoka's (BENCHMARKS.md, "An LPNet's lifted step").

    python -m benchmarks.lpnet_phase [--trajectories 20] [--steps 50]
    python -m benchmarks.lpnet_phase --report

Protocol: the rigid body I = (2, 1, 2/3); `--trajectories` starts on |Pi| = 1 with random
attitudes, heyoka's (mu, q) every h = 0.1 for `--steps` steps; the paper's LPNet (3 x 16,
sigmoid) fitted on the alpha loss (`learn.fit`'s default optimiser), then its phase (2 x 16) by
`learn.fit_phase`; 12 held-out starts rolled out 100 steps (t = 10): the mean attitude error (the
angle of R_pred^T R_true) at t = 1, 5, 10 with the phase and with it at zero, the momentum
error, the largest spatial momentum drift, and the wall time of each fit.
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import numpy as np
from scipy.spatial.transform import Rotation

import integrators as it
import learn
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "lpnet_phase"
BODY = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))
H, TEST_STEPS, N_TEST = 0.1, 100, 12


def starts(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    y0 = rng.normal(size=(n, 3))
    return y0 / np.linalg.norm(y0, axis=1, keepdims=True), Rotation.random(n, random_state=seed + 1).as_quat()


def run(n_trajectories: int, steps: int) -> dict:
    y0, g0 = starts(n_trajectories, 0)
    data = it.ground_truth(BODY, y0, H, steps, g0=g0)
    start = time.perf_counter()
    net, _ = learn.fit(learn.LPNet(BODY, key=0), data, loss="alpha", progress=False)
    alpha_s = time.perf_counter() - start
    start = time.perf_counter()
    phased, record = learn.fit_phase(net, data, progress=False)
    phase_s = time.perf_counter() - start
    yt, gt = starts(N_TEST, 100)
    truth = it.ground_truth(BODY, yt, H, TEST_STEPS, g0=gt)
    flat = learn.AffineMLP(3, 1, (2,), key=0, output_scaling=((0.0,), (1e-300,)))  # rates ~ 0
    out = {"alpha_fit_s": alpha_s, "phase_fit_s": phase_s, "phase_loss": record.train_loss}
    for label, model in (("with phase", phased), ("phase at zero", eqx.tree_at(lambda m: m.phase, phased, flat))):
        g, mu = model.lifted_rollout(gt, yt, TEST_STEPS)
        angles = np.asarray(lp.rotation_angle(np.asarray(g), truth.configurations))
        J = np.asarray(BODY.spatial_momentum(np.asarray(g), np.asarray(mu)))
        out[label] = {f"attitude_error_t{t}": float(angles[:, round(t / H)].mean()) for t in (1, 5, 10)}
        out[label]["spatial_momentum_drift"] = float(np.abs(J - J[:, :1]).max() / np.abs(J).max())
        out["momentum_error_t10"] = float(np.linalg.norm(np.asarray(mu)[:, -1] - truth.states[:, -1], axis=1).mean())
    return out


def report(results: dict) -> None:
    print(f"alpha fit {results['alpha_fit_s']:.1f} s, phase fit {results['phase_fit_s']:.1f} s "
          f"(loss {results['phase_loss']:.3g}); momentum error at t = 10: {results['momentum_error_t10']:.3g}")
    for label in ("with phase", "phase at zero"):
        r = results[label]
        print(f"{label:>14}: attitude error t = 1, 5, 10: {r['attitude_error_t1']:.3g}, {r['attitude_error_t5']:.3g}, "
              f"{r['attitude_error_t10']:.3g} rad; spatial momentum drift {r['spatial_momentum_drift']:.2g}")


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.lpnet_phase", description=__doc__.splitlines()[0])
    parser.add_argument("--trajectories", type=int, default=20)
    parser.add_argument("--steps", type=int, default=50)
    add_output_arguments(parser, NAME)
    args = parser.parse_args()
    if args.report:
        report(saved_results(args.out))
        return
    results = run(args.trajectories, args.steps)
    write_json(args.out, args, results)
    report(results)


if __name__ == "__main__":
    main()
