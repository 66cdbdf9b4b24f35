r"""Wall time per step of a step map, measured so that maps of equal work measure equal."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Iterator

import jax
import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import positive_float, positive_int, states

from ._step_map import AbstractStepMap, check_h


@dataclasses.dataclass(frozen=True)
class StepTiming:
    r"""What `step_timing` measured: `seconds_per_step` (of one trajectory: the fastest run
    divided by $n_\text{steps} \cdot n_\text{traj}$), the `n_steps` and `n_trajectories` of each
    timed run, and the wall time of every run in `run_seconds`."""

    seconds_per_step: float
    n_steps: int
    n_trajectories: int
    run_seconds: tuple[float, ...]


def step_timing(
    step_map: AbstractStepMap,
    y0s: ArrayLike,
    *,
    min_seconds: float = 0.05,
    repeats: int = 5,
    outputs: int = 1,
) -> StepTiming:
    r"""The wall time of one step of `step_map` on one trajectory, as the minimum over
    `repeats` runs of its compiled rollout of `y0s` over $n$ steps, divided by $n \cdot
    n_\text{traj}$.

    A warm-up run compiles; $n$ then grows until one run lasts at least `min_seconds`, so that
    the fixed cost of a call (dispatch, validation, copying the outputs) is a small part of
    it. The minimum, not the mean: the load of a shared machine only ever adds time, so the
    fastest of several runs is the one closest to the map's own cost, and maps that do the
    same work (e.g. the axis orderings of a splitting) measure the same. XLA's flop count of
    a step (`step_map.cost().flops`) is the machine-independent figure beside it.

    **Arguments:** `step_map`, an `AbstractStepMap` with a step size; `y0s` `(n_traj, dim)` or
    `(dim,)`, finite (the trajectories stepped together, vectorised as in `rollout`);
    `min_seconds` > 0, the shortest run timed; `repeats` >= 1; `outputs` >= 1, how many states
    each timed rollout saves besides `y0s`: passing the number a study already rolled out
    with (`compare` passes its `n_outputs`) reuses the program it compiled.

    **Returns:** a `StepTiming`.
    """
    if not isinstance(step_map, AbstractStepMap):
        raise TypeError(f"step_map must be an integrators.AbstractStepMap; got {type(step_map).__name__}")
    check_h(step_map)
    y0s = states(y0s, "y0s", step_map.system.dim).reshape(-1, step_map.system.dim)
    min_seconds = positive_float(min_seconds, "min_seconds")
    repeats = positive_int(repeats, "repeats")
    outputs = positive_int(outputs, "outputs")

    def run(every: int) -> float:
        start = time.perf_counter()
        jax.block_until_ready(step_map.rollout(y0s, outputs * every, save_every=every, nonfinite="return"))
        return time.perf_counter() - start

    # save_every >= 2 throughout: the spacing of the outputs is then traced, one program for every n.
    every = 2
    run(every)  # compiles
    seconds = run(every)
    while seconds < min_seconds:
        every = math.ceil(every * min(100.0, 1.2 * min_seconds / max(seconds, 1e-6)))
        seconds = run(every)
    runs = (seconds, *(run(every) for _ in range(repeats - 1)))
    n_steps = outputs * every
    return StepTiming(
        seconds_per_step=float(np.min(runs)) / (n_steps * len(y0s)),
        n_steps=n_steps,
        n_trajectories=len(y0s),
        run_seconds=tuple(float(t) for t in runs),
    )


#: The JAX monitoring events `counted_compilations` counts, by the name it reports them under.
_COMPILE_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "traces",
    "/jax/core/compile/backend_compile_duration": "compilations",
}


@contextlib.contextmanager
def counted_compilations() -> Iterator[dict[str, int]]:
    """`{"traces": n, "compilations": m}` within the block: the programs JAX traced (a hit of
    the compilation cache is traced too) and those XLA compiled, jitted functions and the small
    programs of eager operations alike (JAX's monitoring events)."""
    seen = dict.fromkeys(_COMPILE_EVENTS.values(), 0)

    def listener(event: str, *args, **kwargs) -> None:
        name = _COMPILE_EVENTS.get(event)
        if name is not None:
            seen[name] += 1

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield seen
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
