import gc
import os
import shutil
import tempfile

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)

# The suite's time goes into compiling (hundreds of small programs, most run for milliseconds):
# XLA's CPU backend compiles them without LLVM's optimisation passes, measured 236-251 s ->
# 206 s for the default run on 2 cores, every test passing. The results are the same IEEE
# arithmetic (XLA's CPU fast-math is off at every level); only how fast the code runs differs,
# and no test here measures speed (benchmarks/ does, with the default flags). Set in the
# environment before JAX's first computation, so the processes the tests spawn inherit it; a
# run that sets the option itself (XLA_FLAGS=--xla_backend_optimization_level=2) keeps its own.
_XLA_OPT = "--xla_backend_optimization_level"
if _XLA_OPT not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_XLA_OPT}=0".strip()

# CI runs on 2 cores: keep property-based tests small but meaningful.
settings.register_profile(
    "ci",
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=True,
)
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

EPS = np.finfo(np.float64).eps



# One JAX compilation cache per test run, shared by the pytest-xdist workers (which inherit the
# variable from the controlling process): the suite's many small fits compile the same programs
# again and again, and a cache hit skips XLA. Removed when the run ends, unless the caller set
# the variable (.ci/run: one cache for the default run and the slow one, which compiles many of
# the same programs), in which case the caller owns it.
_CACHE_VAR = "LIEPOISSON_TEST_JAX_CACHE"
_OWN_CACHE = os.environ.get("PYTEST_XDIST_WORKER") is None and not os.environ.get(_CACHE_VAR)
if _OWN_CACHE:
    os.environ[_CACHE_VAR] = tempfile.mkdtemp(prefix="liepoisson-tests-jax-cache-")
jax.config.update("jax_compilation_cache_dir", os.environ[_CACHE_VAR])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
# The same for the processes the tests spawn (the paper's worker processes, a Dask cluster):
# JAX reads its options from these variables when it is imported.
os.environ["JAX_COMPILATION_CACHE_DIR"] = os.environ[_CACHE_VAR]
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"


# Tracing and compiling create many short-lived objects (jaxprs, MLIR, pytrees): Python's cyclic
# collector ran ~20 times a second, its full collections walking everything the run keeps
# alive (modules, compiled functions). Young objects are collected less often (gen0 at 10,000
# allocations instead of 700) and what collection built is left out of full collections:
# measured ~2% of a worker's time, the same peak memory.
gc.set_threshold(10_000, 10, 10)


def pytest_collection_finish(session):
    gc.collect()
    gc.freeze()


def pytest_sessionfinish(session, exitstatus):
    if _OWN_CACHE:
        shutil.rmtree(os.environ[_CACHE_VAR], ignore_errors=True)


# A worker compiles thousands of programs, each held by JAX's caches as a few dozen memory
# mappings: past Linux's vm.max_map_count (65,530) XLA dies in the next compilation (the slow
# suite's workers crashed so, SIGSEGV or SIGABRT in `backend_compile_and_load`, at 66% and 88% of
# the run, in the same two tests each time, never alone: issue 63). Released after each long
# test once past the share of the limit `paper._mappings` sets (the default run's workers live
# a few minutes and never came near it).
def pytest_runtest_teardown(item, nextitem):
    if item.get_closest_marker("slow") is not None:
        from paper._mappings import release_compiled_programs

        release_compiled_programs()


# A test that kills its pytest-xdist worker anyway runs once more, in the fresh worker that
# replaces it; a second crash fails it. Only crashes are rerun: a test that fails fails.
_CRASHED: set[str] = set()


@pytest.hookimpl(optionalhook=True)
def pytest_handlecrashitem(crashitem, report, sched):
    if crashitem not in _CRASHED:
        _CRASHED.add(crashitem)
        sched.mark_test_pending(crashitem)
        report.outcome = "rerun"


def pytest_report_teststatus(report, config):
    if report.outcome == "rerun":
        return "rerun", "R", ("RERUN", {"yellow": True})
    return None


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _CRASHED:
        terminalreporter.write_line(f"rerun after crashing their worker: {', '.join(sorted(_CRASHED))}",
                                    yellow=True)
