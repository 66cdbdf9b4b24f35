"""The OpenBLAS under JAX's CPU LAPACK kernels (SciPy's), limited to one thread; and the
kernels of the OpenBLAS libraries loaded (`openblas_kernels`: what data's bits depend on).

JAX on CPU calls LAPACK (LU, Cholesky, tridiagonal solves) through SciPy's OpenBLAS. With its
default threads that library's workers, left spinning after each call, slow the XLA operations
that follow, and a forward-mode Jacobian of a batch of isospectral steps (the LU of each Cayley
transform, called from XLA's threads) deadlocked (BENCHMARKS.md, "Zeitlin's model" and "W2
`--full`: seven systems": the figures). Nothing here applies when the user set
`OPENBLAS_NUM_THREADS`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any


def _scipy_openblas() -> tuple[Any, list[str]]:
    """`(controller, paths)`: threadpoolctl's controller and the OpenBLAS libraries to limit:
    SciPy's, found by its location (its package or the `scipy.libs` beside it), or every
    OpenBLAS where none is found there (a conda or system OpenBLAS, shared with NumPy)."""
    import scipy
    import scipy.linalg.cython_lapack
    from threadpoolctl import ThreadpoolController

    controller = ThreadpoolController()
    package = os.path.dirname(os.path.abspath(scipy.__file__))
    places = (package + os.sep, package + ".libs" + os.sep)
    openblas = [info for info in controller.info() if info["internal_api"] == "openblas"]
    paths = [info["filepath"] for info in openblas if os.path.abspath(info["filepath"]).startswith(places)]
    if not paths:
        paths = [info["filepath"] for info in openblas]
    if not any(info["num_threads"] != 1 for info in openblas if info["filepath"] in paths):
        paths = []  # already serial
    return controller, paths


def serial_lapack() -> None:
    """Limit JAX's LAPACK (SciPy's OpenBLAS) to one thread for the rest of the process (SciPy's
    own `scipy.linalg` calls run on one thread too): what every isospectral method applies
    when it is built, since its steps run later. Not cached: a `threadpool_limits` block that
    ends restores the threads, so each build checks again."""
    if "OPENBLAS_NUM_THREADS" in os.environ:
        return
    controller, paths = _scipy_openblas()
    if paths:
        controller.select(filepath=paths).limit(limits=1)


@contextlib.contextmanager
def serial_lapack_block() -> Iterator[None]:
    """`serial_lapack` for the duration of a `with` block, the threads restored after it (a
    fit's loop: the user's own SciPy calls after it keep their threads)."""
    if "OPENBLAS_NUM_THREADS" in os.environ:
        yield
        return
    controller, paths = _scipy_openblas()
    if not paths:
        yield
        return
    with controller.select(filepath=paths).limit(limits=1):
        yield


def openblas_kernels() -> list[str]:
    """The kernels (`architecture`: `Haswell`, `SkylakeX`, ...) of the OpenBLAS libraries this
    process has loaded (NumPy's, SciPy's), sorted, each once; empty if none is loaded or
    threadpoolctl cannot tell. Matrix products round differently in each kernel, so the same
    seeds make other bits of data on a machine where OpenBLAS chose another (`OPENBLAS_CORETYPE`
    chooses it)."""
    import numpy  # noqa: F401 (its OpenBLAS loaded)
    from threadpoolctl import threadpool_info

    return sorted({str(info["architecture"]) for info in threadpool_info()
                   if info.get("internal_api") == "openblas" and info.get("architecture")})
