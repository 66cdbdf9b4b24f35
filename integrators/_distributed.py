"""Dask (`dask.distributed`) as the optional engine for scale-out: the one module that imports
it. Work is split into independent tasks; the client keeps a bounded window of them in flight
and handles each result as it arrives (writes it to disk), so its memory stays bounded."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

_EXTRA = (
    "this needs Dask's distributed scheduler, an optional extra of liepoisson: "
    "pip install 'liepoisson[dask]' (in a checkout: pip install -e \".[dask]\")"
)


def require_distributed():
    """The `distributed` module, or an `ImportError` naming the extra to install."""
    try:
        import distributed
    except ImportError as err:
        raise ImportError(_EXTRA) from err
    return distributed


def check_client(client: Any, name: str = "client") -> Any:
    """`client` if it is a `dask.distributed.Client` (or None); otherwise `TypeError`."""
    if client is None:
        return None
    distributed = require_distributed()
    if not isinstance(client, distributed.Client):
        raise TypeError(
            f"{name} must be a dask.distributed.Client or None (no Dask); got {type(client).__name__}. "
            "Make one with dask.distributed.Client(LocalCluster()) or Client('tcp://scheduler:8786')"
        )
    return client


def n_workers(client: Any) -> int:
    """Number of workers the scheduler knows now (at least 1)."""
    return max(1, len(client.scheduler_info().get("workers", {})))


def map_unordered(
    fn: Callable[..., Any],
    items: Iterable[tuple[Any, tuple[Any, ...]]],
    *,
    client: Any = None,
    window: int | None = None,
    shared: tuple[Any, ...] = (),
) -> Iterator[tuple[Any, Any]]:
    """Yield `(key, fn(*shared, *args))` for each `(key, args)` of `items`, as they finish.

    Without a client: in this process, in order. With a client: on its workers, at most
    `window` tasks in flight (default twice the workers), `shared` arguments sent to every
    worker once (`client.scatter(..., broadcast=True)`: one copy per worker, which lets a
    worker reuse what it compiled for them). A task's exception is raised here, after the
    tasks in flight are cancelled.
    """
    if client is None:
        for key, args in items:
            yield key, fn(*shared, *args)
        return
    distributed = require_distributed()
    shared_futures = [client.scatter(s, broadcast=True, hash=False) for s in shared]
    window = window or 2 * n_workers(client)
    items = iter(items)
    keys: dict[Any, Any] = {}
    pool = distributed.as_completed()

    def submit_next() -> bool:
        try:
            key, args = next(items)
        except StopIteration:
            return False
        future = client.submit(fn, *shared_futures, *args, pure=False)
        keys[future] = key
        pool.add(future)
        return True

    for _ in range(window):
        if not submit_next():
            break
    try:
        for future in pool:
            result = future.result()  # raises the task's exception
            key = keys.pop(future)
            future.release()
            submit_next()
            yield key, result
    finally:
        for future in keys:
            future.cancel()
