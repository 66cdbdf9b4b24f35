"""Where the experiments' independent trainings (seeds, step sizes) run: here, one after the
other (the default), or on a Dask cluster (`python -m paper ... --scheduler`)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from integrators.internals import map_unordered, require_distributed

#: Environment variable read when `--scheduler` is not given.
ENV = "LIEPOISSON_SCHEDULER"
#: Seconds to wait for a remote scheduler to answer.
CONNECT_TIMEOUT = 30.0

_client: Any = None


@contextlib.contextmanager
def scheduler(spec: str | None) -> Iterator[str | None]:
    """Within the block, `map_trainings` runs on the cluster `spec` names: `"local"`, a
    `LocalCluster` sized to the machine (one single-threaded worker per core), or a scheduler
    address such as `tcp://10.0.0.5:8786`; `None`/`""`/`"none"`: no Dask. Yields a description."""
    global _client
    if spec is None or spec.strip().lower() in ("", "none"):
        yield None
        return
    distributed = require_distributed()
    with contextlib.ExitStack() as stack:
        if spec.strip().lower() == "local":
            cluster = stack.enter_context(distributed.LocalCluster(
                n_workers=os.cpu_count() or 1, threads_per_worker=1, processes=True, dashboard_address=None))
            client = stack.enter_context(distributed.Client(cluster))
        else:
            try:
                client = stack.enter_context(distributed.Client(spec, timeout=CONNECT_TIMEOUT))
            except OSError as err:
                raise ValueError(f"--scheduler {spec!r}: cannot reach a Dask scheduler there ({err})") from err
        n = len(client.scheduler_info().get("workers", {}))
        _client = client
        try:
            yield f"Dask scheduler {client.scheduler.address} with {n} worker(s)"
        finally:
            _client = None


def on_cluster() -> bool:
    """Whether trainings run on a Dask cluster now."""
    return _client is not None


def map_trainings(fn: Callable[..., Any], items: Sequence[tuple[Any, ...]]) -> list[Any]:
    """`[fn(*args) for args in items]`, on the cluster when there is one (results in order)."""
    results = dict(map_unordered(fn, enumerate(items), client=_client))
    return [results[i] for i in range(len(items))]
