r"""The learned spectrum of a stream operator on the quantized sphere (`learn.StreamOperator`):
the eigenvalues $\lambda_{lm}$ of an operator $L$ diagonal in the spherical harmonics $T_{lm}$
of the Hoppe-Yau Laplacian, $L\,T_{lm} = \lambda_{lm}T_{lm}$, whose inverse gives the stream
of a vorticity field, $\psi = L^{-1}\omega$, and the Hamiltonian
$H(W) = \tfrac12\langle W, L^{-1}W\rangle$. The Laplacian itself has $\lambda_{lm} = -l(l+1)$
(Euler's equations); quasi-geostrophic flow with deformation parameter $F$ (an inverse squared
deformation radius) $L = \Delta - F$, $\lambda_{lm} = -l(l+1) - F$.

The degree $l = 0$ (the multiples of the identity) is not a parameter: its stream commutes
with every $W$ and never moves the flow. Nor is one more number: adding $\kappa$ to every
inverse eigenvalue $1/\lambda_{lm}$ adds $\kappa W$ to the stream, and $[\psi + \kappa W, W]
= [\psi, W]$: the Hamiltonian is known only up to the Casimir $\tfrac\kappa2\|W\|^2$ (the
enstrophy), and the flow (the isospectral midpoint's to $O(h^2)$) cannot tell the two apart.
A spectrum per degree or per harmonic therefore holds one eigenvalue fixed (`reference`: the
gauge) and learns the others; compare a fitted spectrum with a true one in the same gauge
(`in_gauge`). On a rotating sphere (`learn.StreamOperator`'s rotation $\Omega$, $\dot W =
[\psi, W + \Omega f]$) the shift is no symmetry: it adds $\kappa\Omega[W, f]$, a turning of
the field about the axis, so the data fix every eigenvalue; hold the reference at its true
value there, or compare the fitted flows rather than the spectra."""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import positive_int


def _degrees(N: int) -> np.ndarray:
    """The degree $l$ of each harmonic index $l^2 + l + m$, `(N^2,)`."""
    return np.floor(np.sqrt(np.arange(N * N) + 0.5)).astype(np.int64)


def _finite_values(values: ArrayLike, name: str, size: int | None = None) -> np.ndarray:
    """`values` as a finite, nonzero float64 1-D array (of `size` entries if given), or a
    `TypeError`/`ValueError` naming `name`."""
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a 1-D array of real numbers; got {values!r}") from err
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers; got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.ndim != 1 or (size is not None and arr.size != size):
        expected = f"({size},)" if size is not None else "1-D"
        raise ValueError(f"{name} must have shape {expected}; got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr) | (arr == 0))
    if bad.size:
        raise ValueError(f"{name} must be finite and nonzero (an eigenvalue of L; L^-1 divides by it); "
                         f"{name}[{bad[0]}] = {arr[bad[0]]}")
    return arr


class AbstractSpectrum(eqx.Module):
    r"""The eigenvalues $\lambda_{lm}$, $l \ge 1$, of a stream operator $L$ diagonal in the
    quantized spherical harmonics; its array leaves are what a fit moves. `kind` names it in
    files (`learn.StreamOperator`'s hyperparameters)."""

    kind: ClassVar[str]

    @abc.abstractmethod
    def eigenvalues(self, N: int) -> jax.Array:
        r"""$\lambda_{lm}$ for every harmonic index $l^2 + l + m$ of size N, `(N^2,)` (entry 0,
        the degree 0, is not used)."""

    @classmethod
    @abc.abstractmethod
    def laplacian(cls, N: int) -> AbstractSpectrum:
        r"""The spectrum of this kind equal to the Hoppe-Yau Laplacian's, $-l(l+1)$."""

    def inverse(self, N: int) -> jax.Array:
        r"""$\mu_{lm} = 1/\lambda_{lm}$, `(N^2,)`, with $\mu_{00} = 0$ (the multiplier of
        $L^{-1}$: `liepoisson.internals.harmonic_multiplier`)."""
        lam = self.eigenvalues(N)
        safe = jnp.where(jnp.arange(N * N) == 0, 1.0, lam)
        return jnp.where(jnp.arange(N * N) == 0, 0.0, 1.0 / safe)

    def check_size(self, N: int, name: str = "spectrum") -> None:
        """`ValueError` naming `name` if this spectrum is not one of size N."""

    @abc.abstractmethod
    def values(self) -> np.ndarray:
        """What the spectrum reports: its eigenvalues (per degree, per harmonic) or its family's
        parameter."""

    @abc.abstractmethod
    def standard_errors(self, leaf_errors: AbstractSpectrum) -> np.ndarray:
        """The standard errors of `values()` from those of this spectrum's array leaves (a
        spectrum of the same kind holding them), by the delta method."""

    def in_gauge_of(self, values: ArrayLike) -> ArrayLike:
        """`values` (as `values()` reports them) moved into this spectrum's gauge, the same flow
        on a sphere at rest; a spectrum without a gauge returns them as given (`with_values`
        checks them)."""
        return values

    @abc.abstractmethod
    def with_values(self, values: ArrayLike) -> AbstractSpectrum:
        """The spectrum of this kind and size whose `values()` are `values` (what is held
        fixed, held as here): a hypothesis to compare a fitted one with."""


def in_gauge(eigenvalues: ArrayLike, reference: int, value: float) -> np.ndarray:
    r"""`eigenvalues` `(k,)` moved to the gauge whose entry `reference` is `value`: the inverse
    eigenvalues shifted by one constant, $1/\lambda'_i = 1/\lambda_i - 1/\lambda_r + 1/v$ (the
    same flow: module docstring)."""
    eigenvalues = np.asarray(eigenvalues, dtype=np.float64)
    return 1.0 / (1.0 / eigenvalues - 1.0 / eigenvalues[reference] + 1.0 / value)


class AbstractGaugedSpectrum(AbstractSpectrum):
    """Inverse eigenvalues, all but the one at `reference` learned (`inverse_values`); the one
    at `reference` held at `reference_inverse` (the gauge: module docstring), an array that a
    fit does not move (`learn.fit_stream_operator`; an array, not a static number, so that
    spectra of other gauges share one compiled rollout)."""

    inverse_values: jax.Array
    reference_inverse: jax.Array
    reference: int = eqx.field(static=True)

    def __init__(self, values: ArrayLike, reference: int = 0):
        values = _finite_values(values, "values")
        if isinstance(reference, (bool, np.bool_)) or not isinstance(reference, (int, np.integer)) \
                or not 0 <= reference < values.size:
            raise ValueError(f"reference must be an index of values, 0..{values.size - 1}; got {reference!r}")
        self.reference = int(reference)
        self.reference_inverse = jnp.asarray(1.0 / values[reference])
        self.inverse_values = jnp.asarray(np.delete(1.0 / values, reference))

    def _all_inverse(self) -> jax.Array:
        r = self.reference
        fixed = jnp.reshape(self.reference_inverse, (1,))
        return jnp.concatenate([self.inverse_values[:r], fixed, self.inverse_values[r:]])

    def eigenvalues(self, N: int) -> jax.Array:
        return 1.0 / self.inverse(N).at[0].set(1.0)

    def values(self) -> np.ndarray:
        """The eigenvalues, the fixed one included."""
        return 1.0 / np.asarray(self._all_inverse())

    def standard_errors(self, leaf_errors: AbstractGaugedSpectrum) -> np.ndarray:
        r"""Of the eigenvalues, by the delta method ($\sigma_\lambda = \lambda^2\sigma_\mu$); 0 at
        the fixed one."""
        errors = np.insert(np.asarray(leaf_errors.inverse_values), self.reference, 0.0)
        return errors * self.values() ** 2

    def in_gauge_of(self, values: ArrayLike) -> np.ndarray:
        held = self.values()
        return in_gauge(_finite_values(values, "values", held.size), self.reference, float(held[self.reference]))

    def with_values(self, values: ArrayLike) -> AbstractGaugedSpectrum:
        """The same gauge: `values[reference]` must be the held eigenvalue (a hypothesis in
        another gauge: `learn.in_gauge` first)."""
        held = self.values()
        values = _finite_values(values, "values", held.size)
        r, v = self.reference, float(held[self.reference])
        if not np.isclose(values[r], v, rtol=1e-12, atol=0.0):
            raise ValueError(f"values[{r}] must be the held eigenvalue {v!r} (the gauge); got {float(values[r])!r}: "
                             f"move the values into this gauge with learn.in_gauge(values, {r}, {v!r})")
        return eqx.tree_at(lambda s: s.inverse_values, self, jnp.asarray(np.delete(1.0 / values, self.reference)))

    def _check_count(self, expected: int, what: str, name: str, N: int) -> None:
        got = self.inverse_values.shape[0] + 1
        if got != expected:
            raise ValueError(f"{name} must hold {expected} eigenvalues ({what}) for N = {N}; got {got}")


class DegreeSpectrum(AbstractGaugedSpectrum):
    r"""One eigenvalue per degree: $\lambda_{lm} = \lambda_l$, `values` $(\lambda_1, \dots,
    \lambda_{N-1})$ `(N - 1,)` (an isotropic operator: every rotation of the sphere commutes
    with it, as with the Laplacian and $\Delta - F$). Held, and fitted, as inverse eigenvalues
    $\mu_l = 1/\lambda_l$, on which the flow depends almost linearly over short times; the one
    of degree `reference_degree` (default 1) is held fixed (the gauge: module docstring)."""

    kind: ClassVar[str] = "degree"

    def __init__(self, values: ArrayLike, reference_degree: int = 1):
        if isinstance(reference_degree, (bool, np.bool_)) or not isinstance(reference_degree, (int, np.integer)):
            raise TypeError(f"reference_degree must be an integer degree >= 1; got {reference_degree!r}")
        super().__init__(values, int(reference_degree) - 1)

    def inverse(self, N: int) -> jax.Array:
        l = _degrees(N)
        return jnp.where(l == 0, 0.0, self._all_inverse()[np.maximum(l - 1, 0)])

    @classmethod
    def laplacian(cls, N: int) -> DegreeSpectrum:
        l = np.arange(1, positive_int(N, "N", minimum=2))
        return cls(-(l * (l + 1.0)))

    def check_size(self, N: int, name: str = "spectrum") -> None:
        self._check_count(N - 1, f"degrees 1..{N - 1}", name, N)


class HarmonicSpectrum(AbstractGaugedSpectrum):
    r"""One eigenvalue per harmonic: `values` $\lambda_{lm}$ for the indices $l^2 + l + m =
    1..N^2 - 1$ `(N^2 - 1,)` (an operator that need not commute with rotations); held, and
    fitted, as inverses, the one at `values[reference]` fixed (default 1, $(l, m) = (1, 0)$:
    the gauge, module docstring)."""

    kind: ClassVar[str] = "harmonic"

    def __init__(self, values: ArrayLike, reference: int = 1):
        super().__init__(values, reference)

    def inverse(self, N: int) -> jax.Array:
        return jnp.concatenate([jnp.zeros(1), self._all_inverse()])

    @classmethod
    def laplacian(cls, N: int) -> HarmonicSpectrum:
        l = _degrees(positive_int(N, "N", minimum=2))[1:]
        return cls(-(l * (l + 1.0)))

    def check_size(self, N: int, name: str = "spectrum") -> None:
        self._check_count(N * N - 1, "every (l, m), l >= 1", name, N)


class QuasiGeostrophicSpectrum(AbstractSpectrum):
    r"""The quasi-geostrophic family $L = \Delta_N - F$: $\lambda_{lm} = -l(l+1) - F$, one
    parameter `F` (the inverse squared deformation radius, in units of the sphere's radius;
    $F = 0$ is Euler's equations). The true family of a quasi-geostrophic flow: fitted to it,
    the limit a spectrum per degree is compared with."""

    F: jax.Array
    kind: ClassVar[str] = "quasi-geostrophic"

    def __init__(self, F: ArrayLike = 0.0):
        if isinstance(F, (bool, np.bool_, str, bytes)) or np.ndim(F) != 0:
            raise TypeError(f"F must be a real number; got {F!r}")
        value = float(F)
        if not np.isfinite(value) or value <= -2.0:
            raise ValueError(f"F must be finite and > -2 (so that every eigenvalue -l(l+1) - F, l >= 1, is "
                             f"negative); got {value}")
        self.F = jnp.asarray(value)

    def eigenvalues(self, N: int) -> jax.Array:
        l = _degrees(N).astype(np.float64)
        return -(l * (l + 1.0)) - self.F

    @classmethod
    def laplacian(cls, N: int) -> QuasiGeostrophicSpectrum:
        positive_int(N, "N", minimum=2)
        return cls(0.0)

    def values(self) -> np.ndarray:
        """$(F,)$."""
        return np.asarray(self.F).reshape(1)

    def standard_errors(self, leaf_errors: QuasiGeostrophicSpectrum) -> np.ndarray:
        return np.asarray(leaf_errors.F).reshape(1)

    def with_values(self, values: ArrayLike) -> QuasiGeostrophicSpectrum:
        """`values` $(F,)$."""
        try:
            arr = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise TypeError(f"values must be (F,), one real number; got {values!r}") from err
        if arr.shape not in ((), (1,)):
            raise ValueError(f"values must be (F,), one real number; got shape {arr.shape}")
        return QuasiGeostrophicSpectrum(float(arr.reshape(-1)[0]))


#: The spectra by `kind`.
SPECTRA: dict[str, type[AbstractSpectrum]] = {
    s.kind: s for s in (DegreeSpectrum, HarmonicSpectrum, QuasiGeostrophicSpectrum)}


def spectrum_of(value: Any, N: int, name: str = "spectrum") -> AbstractSpectrum:
    """`value` as a spectrum of size N: an `AbstractSpectrum` (checked), or a kind of `SPECTRA`
    (`"degree"`, `"harmonic"`, `"quasi-geostrophic"`), the Laplacian's of that kind."""
    if isinstance(value, AbstractSpectrum):
        value.check_size(N, name)
        return value
    if isinstance(value, str) and value in SPECTRA:
        return SPECTRA[value].laplacian(N)
    raise TypeError(f"{name} must be a learn.AbstractSpectrum (DegreeSpectrum, HarmonicSpectrum, "
                    f"QuasiGeostrophicSpectrum) or one of {sorted(SPECTRA)}; got {value!r}")
