"""One data set in seconds, milliseconds, hours and with its states x 1e3, fitted by
`learn.fit_splitting` (default families): the mean state error at t = 2 s against heyoka,
converted back to the data's first units (BENCHMARKS.md, "Units").

    python -m benchmarks.units [noise]
"""

from __future__ import annotations

import sys
import time

import numpy as np

import integrators as it
import learn
import liepoisson as lp


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    noise = float(argv[0]) if argv else 0.0
    body = lp.systems.RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0))
    rng = np.random.default_rng(3)
    y0 = rng.normal(size=(5, 3))
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    data = it.observe(body, y0, it.uneven_times(5, 6, steps=(0.05, 0.3), seed=3), noise=noise, seed=3)
    test = rng.normal(size=(4, 3))
    test /= np.linalg.norm(test, axis=1, keepdims=True)
    reference = it.ground_truth(body, test, 0.02, 100).states[:, -1]
    for name, per_second, size in (("s", 1.0, 1.0), ("ms", 1e3, 1.0), ("h", 1 / 3600, 1.0), ("x1e3", 1.0, 1e3)):
        scaled = it.Observations(body, [t * per_second for t in data.times], [y * size for y in data.states])
        start = time.perf_counter()
        net, records = learn.fit_splitting(body, scaled, validation_fraction=0.0, progress=False)
        seconds = time.perf_counter() - start
        final = np.asarray(net.with_h(0.02 * per_second).rollout(test * size, 100))[:, -1] / size
        error = np.mean(np.linalg.norm(final - reference, axis=-1))
        family = records[-1].stages[-1].details["family"]
        print(f"{name:5s} state error at t = 2 s {error:.3e}  family {family}  fit {seconds:.1f} s", flush=True)


if __name__ == "__main__":
    main()
