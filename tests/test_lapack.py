"""JAX's CPU LAPACK (SciPy's OpenBLAS) on one thread: for a block, and restored after it."""

import os

import numpy as np
import pytest
from threadpoolctl import ThreadpoolController

from integrators.internals import serial_lapack_block


def _openblas_threads(controller):
    return [info["num_threads"] for info in controller.info() if info["internal_api"] == "openblas"]


def test_serial_lapack_block_limits_openblas_and_restores_it(monkeypatch):
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    import scipy.linalg.cython_lapack

    controller = ThreadpoolController()
    if not _openblas_threads(controller):
        pytest.skip("no OpenBLAS in this process (SciPy built on another BLAS)")
    # start from two threads whatever an earlier test left (the isospectral methods limit them)
    with controller.select(internal_api="openblas").limit(limits=2):
        assert set(_openblas_threads(ThreadpoolController())) == {2}
        with serial_lapack_block():
            # SciPy's (under its package or scipy.libs), where JAX's LAPACK kernels run; NumPy's
            # own OpenBLAS, if it has one, keeps its threads
            scipy_dir = os.path.dirname(scipy.__file__)
            inside = {info["filepath"]: info["num_threads"] for info in ThreadpoolController().info()
                      if info["internal_api"] == "openblas"}
            ours = [n for path, n in inside.items() if path.startswith((scipy_dir + os.sep, scipy_dir + ".libs"))]
            if ours:
                assert set(ours) == {1}
            else:  # a conda or system OpenBLAS, shared with NumPy: every one limited
                assert set(inside.values()) == {1}
            # and LAPACK still answers: a Cholesky of a small SPD matrix
            A = np.array([[4.0, 2.0], [2.0, 3.0]])
            L = np.linalg.cholesky(A)
            np.testing.assert_allclose(L @ L.T, A, rtol=0, atol=16 * np.finfo(float).eps)  # entries O(4): a few roundings
        assert set(_openblas_threads(ThreadpoolController())) == {2}


def test_serial_lapack_block_leaves_a_users_setting_alone(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    import scipy.linalg.cython_lapack  # noqa: F401

    controller = ThreadpoolController()
    if not _openblas_threads(controller):
        pytest.skip("no OpenBLAS in this process")
    with controller.select(internal_api="openblas").limit(limits=2), serial_lapack_block():
        assert set(_openblas_threads(ThreadpoolController())) == {2}
