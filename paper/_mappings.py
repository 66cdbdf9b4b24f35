"""The process's memory mappings, and JAX's compiled programs released before they run out.

XLA's CPU backend loads every compiled program as several memory mappings (its kernels' code
and data: BENCHMARKS.md, "The default test run"), kept while JAX's caches hold the program. Linux refuses a process more than `vm.max_map_count` of them (65,530 by default), and
XLA does not survive the refusal: a process that compiles a few thousand programs (a long
study, a test worker) then dies inside `backend_compile_and_load` (SIGSEGV or SIGABRT) at
whatever it compiles next. `release_compiled_programs` empties JAX's caches (`jax.clear_caches`)
once the mappings pass a share of the limit: the programs still needed compile again (from the
persistent compilation cache, where one is set).
"""

from __future__ import annotations

import gc
from pathlib import Path

import jax

#: Release once the mappings pass this share of `vm.max_map_count`.
SHARE = 0.75
#: ... and have grown by this share of it since the last release: not every program's mappings
#: come back (XLA pools its kernels' memory, and objects outside JAX's caches hold programs), and
#: a process that stays above `SHARE` after a release would otherwise empty the caches before
#: every call.
STEP = 0.1

_after_last_release = [0]


def mapping_count() -> int | None:
    """The number of this process's memory mappings (`None` where `/proc` does not say)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None


def mapping_limit() -> int | None:
    """`vm.max_map_count` (`None` where `/proc` does not say)."""
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return None


def release_compiled_programs(share: float = SHARE) -> bool:
    """Empty JAX's caches of compiled programs if this process holds more than `share` of the
    memory mappings Linux allows it (and `STEP` of it more than after the last release); whether
    it did. Call it where no computation is in flight
    (between a study's rows, between tests)."""
    count, limit = mapping_count(), mapping_limit()
    if count is None or limit is None or count <= max(share * limit, _after_last_release[0] + STEP * limit):
        return False
    jax.clear_caches()
    gc.collect()
    _after_last_release[0] = mapping_count() or 0
    return True
