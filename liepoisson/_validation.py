"""Input checks shared by every public function: shapes, dtypes, finiteness."""

from __future__ import annotations

import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike


def is_traced(x: Any) -> bool:
    """True if `x` is a JAX tracer (inside `jit`, `vmap` or `grad`): values unknown."""
    return isinstance(x, jax.core.Tracer)


def as_state(x: Any, name: str, dim: int, *, min_ndim: int = 1) -> jax.Array:
    """Return `x` as a float64 array of shape `(..., dim)`.

    Raises `TypeError` for non-numeric input and `ValueError` for a wrong last axis or
    non-finite values (the finiteness check is skipped for traced values, whose content is
    unknown at trace time).
    """
    if isinstance(x, (str, bytes)) or x is None:
        raise TypeError(f"{name} must be an array of shape (..., {dim}); got {type(x).__name__}")
    if not is_traced(x):
        try:
            arr = np.asarray(x)
        except Exception as err:  # ragged lists and the like
            raise TypeError(f"{name} must be an array of shape (..., {dim}); got {x!r}") from err
        if arr.dtype == object or not (
            np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_
        ):
            raise TypeError(f"{name} must be a real numeric array; got dtype {arr.dtype}")
        if np.iscomplexobj(arr):
            raise TypeError(f"{name} must be real; got dtype {arr.dtype}")
        if arr.ndim < min_ndim or arr.shape[-1] != dim:
            raise ValueError(
                f"{name} must have shape (..., {dim}) (last axis = dimension {dim}); "
                f"got shape {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise ValueError(
                f"{name} must be finite; found {arr[tuple(bad)]} at index {tuple(int(i) for i in bad)}"
            )
        return jnp.asarray(arr, dtype=jnp.float64)
    if x.ndim < min_ndim or x.shape[-1] != dim:
        raise ValueError(f"{name} must have shape (..., {dim}); got shape {x.shape}")
    return jnp.asarray(x, dtype=jnp.float64)


def as_scalar_time(t: Any, name: str = "t") -> jax.Array:
    """Return a time (scalar or array broadcastable against the batch) as float64."""
    if isinstance(t, (str, bytes)) or t is None:
        raise TypeError(f"{name} must be a real number or array; got {type(t).__name__}")
    if not is_traced(t):
        arr = np.asarray(t)
        if not (np.issubdtype(arr.dtype, np.number)) or np.iscomplexobj(arr):
            raise TypeError(f"{name} must be real; got dtype {arr.dtype}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite; got {t!r}")
        return jnp.asarray(arr, dtype=jnp.float64)
    return jnp.asarray(t, dtype=jnp.float64)


def positive_float(x: Any, name: str) -> float:
    """A finite, strictly positive Python float (step sizes, masses, tolerances)."""
    if (isinstance(x, bool) or not isinstance(x, numbers.Real)) and not (
        isinstance(x, np.ndarray) and x.ndim == 0
    ):
        raise TypeError(f"{name} must be a positive real number; got {type(x).__name__} {x!r}")
    value = float(x)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be finite and > 0; got {value!r}")
    return value


def _vector(x: Any, name: str, dim: int, what: str, broadcast: bool) -> np.ndarray:
    """`x` as a float64 vector `(dim,)` (a scalar repeated if `broadcast`), not yet checked
    for values; `what` says what its entries must be."""
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be {dim} {what}; got {x!r}") from err
    if broadcast and arr.shape == ():
        arr = np.full(dim, float(arr))
    if arr.shape != (dim,):
        raise ValueError(f"{name} must have shape ({dim},); got shape {arr.shape}")
    return arr


def positive_vector(x: Any, name: str, dim: int) -> np.ndarray:
    """A finite vector with strictly positive entries (principal moments of inertia, masses);
    a scalar stands for `dim` equal entries."""
    arr = _vector(x, name, dim, "positive numbers", broadcast=True)
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be finite and > 0 componentwise; got {arr.tolist()}")
    return arr


def finite_vector(x: Any, name: str, dim: int) -> np.ndarray:
    """A finite real vector of a given length (fixed parameters of a system)."""
    arr = _vector(x, name, dim, "real numbers", broadcast=False)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    return arr


def matrix_basis(x: Any, shape: str) -> np.ndarray:
    """A basis of matrices: a finite float64 array of at least one square matrix (the argument
    `basis` of `LieAlgebra.from_matrices` and `MatrixGroup`; `shape` names its axes)."""
    try:
        basis = np.array(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"basis must be an array {shape} of real matrices; got {type(x).__name__}") from err
    if basis.ndim != 3 or basis.shape[1] != basis.shape[2] or basis.shape[0] < 1:
        raise ValueError(f"basis must be an array {shape} of square matrices, at least one; got shape {basis.shape}")
    if not np.all(np.isfinite(basis)):
        raise ValueError("basis must be finite; got NaN or inf entries")
    return basis


def positive_int(x: Any, name: str, minimum: int = 1) -> int:
    """An integer >= `minimum` (an integral float such as `1e5` is accepted)."""
    if isinstance(x, bool) or not isinstance(x, (numbers.Integral, np.integer)):
        if isinstance(x, float) and x.is_integer():
            x = int(x)
        else:
            raise TypeError(f"{name} must be an integer >= {minimum}; got {type(x).__name__} {x!r}")
    if int(x) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {int(x)}")
    return int(x)


def fraction(x: Any, name: str) -> float:
    """A number in [0, 1)."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        raise TypeError(f"{name} must be a number in [0, 1); got {type(x).__name__} {x!r}")
    value = float(x)
    if not (0.0 <= value < 1.0):
        raise ValueError(f"{name} must be in [0, 1); got {value!r}")
    return value


def states(x: Any, name: str, dim: int) -> np.ndarray:
    """A finite float64 numpy array of shape `(..., dim)` (host-side preparation; `as_state`
    is the JAX-side twin that also accepts traced values)."""
    if is_traced(x):
        raise TypeError(f"{name} must be a concrete array here, not a traced JAX value")
    return np.asarray(as_state(x, name, dim))


def pairs(
    y0: Any, y1: Any, dim: int, names: tuple[str, str] = ("y0", "y1")
) -> tuple[np.ndarray, np.ndarray]:
    """Two finite state arrays of the same shape `(..., dim)`."""
    y0 = states(y0, names[0], dim)
    y1 = states(y1, names[1], dim)
    if y0.shape != y1.shape:
        raise ValueError(
            f"{names[0]} and {names[1]} must have the same shape; got {y0.shape} and {y1.shape}"
        )
    return y0, y1


def nonzero_time(t: Any, name: str = "t") -> float:
    """A finite, non-zero real scalar (a time that may run backwards)."""
    if is_traced(t):
        raise TypeError(f"{name} must be a concrete real number here, not a traced JAX value")
    arr = np.asarray(t) if isinstance(t, (np.ndarray, jax.Array, np.generic)) else None
    real = isinstance(t, numbers.Real) and not isinstance(t, bool)
    if arr is not None:
        real = arr.shape == () and np.issubdtype(arr.dtype, np.number) and not np.iscomplexobj(arr)
    if not real:
        raise TypeError(f"{name} must be a real scalar; got {type(t).__name__} {t!r}")
    value = float(t)
    if not np.isfinite(value) or value == 0.0:
        raise ValueError(f"{name} must be finite and non-zero; got {value!r}")
    return value


def broadcast_batch(dim: int, **batches: tuple[int, ...]) -> tuple[int, ...]:
    """The broadcast of the named batch shapes (e.g. `alpha=alpha.shape[:-1], mu=...,
    t=t.shape`); `ValueError` naming them all if they do not broadcast."""
    try:
        return tuple(np.broadcast_shapes(*batches.values()))
    except ValueError:
        given = ", ".join(f"{k} {v}" for k, v in batches.items())
        raise ValueError(
            f"the batch shapes of {given} do not broadcast (states and parameters have shape "
            f"(..., {dim}), times shape (...), and their leading axes broadcast together)"
        ) from None


def pinv_apply(B: ArrayLike, v: ArrayLike, rcond: float) -> np.ndarray:
    r"""$B^+ v$ for stacks `B` `(..., n, n)`, `v` `(..., n)` (NumPy; singular values below `rcond`
    times the largest dropped): the dense minimum-norm least squares of `poisson_lstsq`."""
    return np.einsum("...ab,...b->...a", np.linalg.pinv(np.asarray(B), rcond=rcond), np.asarray(v))
