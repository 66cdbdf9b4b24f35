r"""Exact data: each family's residuals against its map's own discretisation error
(BENCHMARKS.md, "Exact data: families explained within the step's error").

    python -m benchmarks.exact_data [--systems NAME ...] [--noise 0] [--families quadratic ...]
    python -m benchmarks.exact_data --report

Protocol: W2's observations of each system (`paper.w2_observations`, regular sampling, noise
`--noise`), each of `--families` fitted alone by `learn.fit_splitting(families=[family])`
(Levenberg-Marquardt, 200 steps at most); its sum of squared residuals (SSR) and
`discretisation_ssr` (the predictions at the data's sub-steps against twice as many), their
ratio, and the fit's wall time. A family that holds the Hamiltonian fits exact data within its
discretisation error (ratio below 1); one that misses structure, or noise, puts it far above.
"""

from __future__ import annotations

import argparse
import time

import learn
from learn._training._observed import discretisation_ssr
from paper import w2_observations as w2

from ._report import add_output_arguments, saved_results, write_json

NAME = "exact_data"


def run(systems: list[str], noise: float, families: list[str]) -> dict:
    by_name = {f.name: f for f in learn.FAMILIES}
    protocols = w2.protocols()
    out: dict = {}
    for system in systems:
        protocol = protocols[system]
        data = w2.observations(protocol, noise, "regular")
        for name in families:
            start = time.perf_counter()
            net, records = learn.fit_splitting(protocol.system, data, families=[by_name[name]],
                                               validation_fraction=0.0, progress=False)
            details = records[-1].stages[-1].details
            problem = learn.TrajectoryLoss().problem(net, data, h=None, validation_fraction=0.0, seed=0,
                                                     normalise=False)
            # the fitted starts are not in the returned map: the floor at the observed starts
            # differs from the fit's by far less than the ratios compared (noise 0)
            floor = discretisation_ssr(problem, problem.y0)
            out[f"{system}, {name}"] = {"ssr": details["ssr"], "discretisation_ssr": floor,
                                        "ratio": details["ssr"] / floor, "fit_s": time.perf_counter() - start}
            print(f"{system}, {name}: SSR {details['ssr']:.3e}, discretisation {floor:.3e}, "
                  f"ratio {details['ssr'] / floor:.3g}", flush=True)
    return out


def report(results: dict) -> None:
    for key, r in results.items():
        print(f"{key}: SSR {r['ssr']:.3e}, discretisation {r['discretisation_ssr']:.3e}, ratio {r['ratio']:.3g}, "
              f"fit {r['fit_s']:.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exact_data", description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", default=list(w2.protocols()))
    parser.add_argument("--noise", type=float, default=0.0)
    parser.add_argument("--families", nargs="+", default=["quadratic", "quadratic, any axes"])
    add_output_arguments(parser, NAME)
    args = parser.parse_args()
    if args.report:
        report(saved_results(args.out))
        return
    results = run(args.systems, args.noise, args.families)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
