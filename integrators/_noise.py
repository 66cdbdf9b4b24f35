r"""Noise laws of `observe`: the distribution of the measurement noise, each drawn with zero mean
and unit standard deviation (`observe` scales it to the standard deviation asked for)."""

from __future__ import annotations

import abc
import numbers
from typing import Any

import numpy as np

from ._choices import AbstractChoice, by_name


class AbstractNoiseLaw(AbstractChoice):
    """A distribution of zero mean and unit variance; `name` is what `observe` records in the
    metadata (and accepts as a string)."""

    @abc.abstractmethod
    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Independent draws of the law, of shape `shape`, from `rng`."""


class GaussianNoise(AbstractNoiseLaw):
    """The standard normal law."""

    name = "gaussian"

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        return rng.standard_normal(shape)


class UniformNoise(AbstractNoiseLaw):
    r"""Uniform on $[-\sqrt3, \sqrt3]$ (variance $(2\sqrt3)^2/12 = 1$)."""

    name = "uniform"

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        return rng.uniform(-np.sqrt(3.0), np.sqrt(3.0), shape)


class LaplaceNoise(AbstractNoiseLaw):
    r"""Laplace of scale $b = 1/\sqrt2$ (variance $2b^2 = 1$)."""

    name = "laplace"

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        return rng.laplace(0.0, 1.0 / np.sqrt(2.0), shape)


#: The laws by the names `observe` accepts.
NOISE_LAWS: dict[str, AbstractNoiseLaw] = {law.name: law for law in (GaussianNoise(), UniformNoise(), LaplaceNoise())}


def noise_law(law: str | AbstractNoiseLaw) -> AbstractNoiseLaw:
    """`law` as an `AbstractNoiseLaw`: an instance, or one of the names of `NOISE_LAWS`."""
    return by_name(law, NOISE_LAWS, AbstractNoiseLaw, "law")


def noise_level(noise: Any, name: str = "noise") -> float:
    """`noise` as a float: a finite real number >= 0 (a Python or NumPy number, or a 0-d
    array), or a `TypeError` naming `name` for text and booleans (`"0.01"` and `True` are not
    noise levels) and a `ValueError` for a negative or non-finite one."""
    if isinstance(noise, (bool, np.bool_, str, bytes)):
        kind = None
    elif isinstance(noise, numbers.Real):
        kind = "f"
    else:  # a 0-d array (NumPy, JAX) of a real type
        try:
            kind = np.asarray(noise).dtype.kind if np.ndim(noise) == 0 else None
        except (TypeError, ValueError):
            kind = None
    if kind not in ("i", "u", "f"):
        raise TypeError(f"{name} must be a number >= 0 (relative to the states' RMS size); got "
                        f"{type(noise).__name__} {noise!r}")
    value = float(noise)
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be a finite number >= 0 (relative to the states' RMS size); got {value}")
    return value
