"""Where the experiments' independent trainings (seeds, a baseline, a G-LPNet) run: in threads
of this process, one per core (the default, `--scheduler threads`); here, one after the other
(`--scheduler none`); in worker processes on this machine, one per core (`--scheduler
processes`); or on a Dask cluster (`--scheduler [ADDRESS]`).

Threads are the default because the experiments' small networks keep about one core busy a
training (XLA splits only large products), so two trainings at once use the second core:
on 2 cores the main job is faster so, every figure identical (BENCHMARKS.md, "Quick-profile
budgets"): a training's result does not depend on what runs beside it; its `wall_time_s` does.
Worker processes pay a JAX runtime and compilations each, and two of them at once each took
more than twice as long as one alone (the same section): they pay off with more cores or a
cluster."""

from __future__ import annotations

import concurrent.futures
import contextlib
import contextvars
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from integrators.internals import map_unordered, require_distributed

#: Environment variable read when `--scheduler` is not given.
ENV = "LIEPOISSON_SCHEDULER"
#: Seconds to wait for a remote scheduler to answer.
CONNECT_TIMEOUT = 30.0

#: `scheduler`'s spec for worker processes on this machine.
PROCESSES = "processes"
#: `scheduler`'s spec for threads of this process, one per core.
THREADS = "threads"

_client: Any = None
_pool: concurrent.futures.ProcessPoolExecutor | None = None
_threads: concurrent.futures.ThreadPoolExecutor | None = None


def cores() -> int:
    """The cores this process may run on (`taskset`, a container's CPU set: its affinity), not
    the machine's: a process pinned to one core of two gets one worker, not two that share it."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):  # no affinity on this platform (macOS, Windows)
        return os.cpu_count() or 1


@contextlib.contextmanager
def scheduler(spec: str | None) -> Iterator[str | None]:
    """Within the block, `submit` and `map_trainings` run where `spec` says: `"local"`, a
    `LocalCluster` sized to the machine (one single-threaded worker per core), a scheduler
    address such as `tcp://10.0.0.5:8786`, or `"processes"`: worker processes on this machine,
    one per core, without Dask; `None`/`""`/`"none"`: this process. Yields a description."""
    global _client, _pool, _threads
    if spec is None or spec.strip().lower() in ("", "none"):
        yield None
        return
    if spec.strip().lower() == THREADS:
        workers = cores()
        with concurrent.futures.ThreadPoolExecutor(workers) as pool:
            _threads = pool
            try:
                yield f"{workers} thread{'' if workers == 1 else 's'} of this process"
            finally:
                _threads = None
        return
    if spec.strip().lower() == PROCESSES:
        try:
            import cloudpickle  # noqa: F401
        except ImportError as err:
            raise ImportError("worker processes send the trainings by cloudpickle: pip install 'liepoisson[paper]'") \
                from err
        workers = cores()
        # spawn, not fork: a forked JAX runtime deadlocks
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            _pool = pool
            try:
                yield f"{workers} worker process{'' if workers == 1 else 'es'} on this machine"
            finally:
                _pool = None
        return
    distributed = require_distributed()
    with contextlib.ExitStack() as stack:
        if spec.strip().lower() == "local":
            cluster = stack.enter_context(distributed.LocalCluster(
                n_workers=cores(), threads_per_worker=1, processes=True, dashboard_address=None))
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
    """Whether trainings run elsewhere now (worker processes or a Dask cluster): their
    progress bars would interleave, so callers turn them off."""
    return _client is not None or _pool is not None or _threads is not None


class _Done:
    """The result of a task run here, as a future holds it."""

    def __init__(self, value: Any):
        self._value = value

    def result(self) -> Any:
        return self._value


def _call(payload: bytes) -> Any:
    import cloudpickle

    fn, args = cloudpickle.loads(payload)
    return fn(*args)


def submit(fn: Callable[..., Any], *args: Any) -> Any:
    """Start `fn(*args)` where trainings run now; returns an object whose `.result()` is its
    value (raising its exception). Here (no scheduler) it runs at once. In worker processes
    `fn` and `args` travel by cloudpickle (closures and lambdas included); with Dask, as Dask
    sends them."""
    if _pool is not None:
        import cloudpickle

        return _pool.submit(_call, cloudpickle.dumps((fn, args)))
    if _threads is not None:  # in this thread's context (JAX's configuration is context-local)
        return _threads.submit(contextvars.copy_context().run, fn, *args)
    if _client is not None:
        return _client.submit(fn, *args, pure=False)
    return _Done(fn(*args))


def map_trainings(fn: Callable[..., Any], items: Sequence[tuple[Any, ...]]) -> list[Any]:
    """`[fn(*args) for args in items]`, where trainings run now (results in order)."""
    if _pool is not None or _threads is not None:
        return [f.result() for f in [submit(fn, *args) for args in items]]
    results = dict(map_unordered(fn, enumerate(items), client=_client))
    return [results[i] for i in range(len(items))]
