r"""Zeitlin's model: 2D Euler equations on the sphere as a Lie-Poisson system on u(N)*."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._matrix_algebra import u
from .._quantized_sphere import (
    harmonics_to_matrix,
    hbar,
    matrix_to_harmonics,
    solve_poisson,
    vorticity_on_grid,
)
from .._validation import as_state, positive_int
from ._base import AbstractDefinedByParams, AbstractLiePoissonSystem


class Zeitlin(AbstractLiePoissonSystem, AbstractDefinedByParams):
    r"""Euler's equations of an ideal fluid on the sphere, quantized (Zeitlin 1991, 2004;
    Modin & Viviani 2020): the vorticity is a skew-Hermitian $N\times N$ matrix $W$, the stream
    matrix $P = \Delta_N^{-1}W$ (the Hoppe-Yau Laplacian), and

    $$\dot W = \tfrac1\hbar[P, W], \qquad \hbar = \frac{2}{\sqrt{N^2-1}}, \qquad
    H(W) = \frac{\mathrm{tr}(PW)}{2\hbar} \ge 0,$$

    in physical time (the continuum's $\dot\omega = \{\psi, \omega\}$ as $N\to\infty$). A
    Lie-Poisson system on u(N)* (`liepoisson.u(N)`, dimension $N^2$; its body velocity is
    $\Xi = -P/\hbar$); the Casimirs $\mathrm{tr}(iW)^k$, $k = 1..N$, are the quantized
    enstrophies, and the spectrum of $iW$ is kept. quflow's energy is $\hbar H/N$, its time
    unit ("qtime") $\hbar$.

    **Arguments:** `N` >= 2, the matrix size (spherical harmonics up to degree $N - 1$).
    """

    name = "Zeitlin"

    def __init__(self, N: int = 16):
        self.algebra = u(positive_int(N, "N", minimum=2))
        self.hbar = hbar(self.algebra.N)

    @property
    def N(self) -> int:
        return self.algebra.N

    @property
    def params(self) -> dict[str, Any]:
        return {"N": self.N}

    # -- the matrices -----------------------------------------------------------------------------
    def stream_matrix(self, W: jax.Array) -> jax.Array:
        r"""$P = \Delta_N^{-1}W$, traceless, for `W` `(..., N, N)`."""
        W = jnp.asarray(W)
        if W.ndim == 2:
            return solve_poisson(W)
        flat = W.reshape((-1, self.N, self.N))
        return jax.vmap(solve_poisson)(flat).reshape(W.shape)

    def velocity_matrix(self, W: jax.Array) -> jax.Array:
        r"""$B(W) = P/\hbar$: $\dot W = [B, W]$ (the isospectral integrators)."""
        return self.stream_matrix(W) / self.hbar

    # -- the Hamiltonian --------------------------------------------------------------------------
    def hamiltonian(self, y: ArrayLike) -> jax.Array:
        y = as_state(y, "y", self.dim)
        W = self.algebra.matrix(y)
        P = self.stream_matrix(W)
        return jnp.real(jnp.sum(P * jnp.swapaxes(W, -1, -2), axis=(-2, -1))) / (2 * self.hbar)

    def hamiltonian_gradient(self, y: ArrayLike) -> jax.Array:
        r"""$\partial H/\partial\mu \leftrightarrow \Xi = -P/\hbar$ (closed form)."""
        y = as_state(y, "y", self.dim)
        return self.algebra.coordinates(-self.velocity_matrix(self.algebra.matrix(y)))

    def _hessian(self) -> np.ndarray:
        """$K$ with $H = \\tfrac12 y^\\top K y$ (dense `(n, n)`, formed on first use)."""
        cached = self.__dict__.get("_K")
        if cached is None:
            with jax.ensure_compile_time_eval():  # concrete even when first asked for inside jit
                cached = np.asarray(jax.vmap(self.hamiltonian_gradient)(jnp.eye(self.dim)))
            cached = 0.5 * (cached + cached.T)
            cached[np.abs(cached) < 1e-14 * np.abs(cached).max()] = 0.0
            self.__dict__["_K"] = cached
        return cached

    def hamiltonian_components(self, y, xp):
        """$\\tfrac12 y^\\top K y$ on the components (symbolic use and heyoka: moderate N)."""
        K = self._hessian()
        terms = [0.5 * float(K[a, b]) * y[a] * y[b] for a, b in zip(*np.nonzero(K))]
        if hasattr(xp, "sum") and not isinstance(y[0], (jax.Array, np.ndarray, float)):
            return xp.sum(terms)
        return sum(terms)

    def hamiltonian_splitting(self):
        """No pieces (`()`): no splitting of the Zeitlin Hamiltonian into exactly solvable pieces
        is known here; integrate with `integrators.IsospectralMidpoint`."""
        return ()

    # -- heyoka --------------------------------------------------------------------------------------
    def heyoka_system(self) -> list[tuple[Any, Any]]:
        r"""$\dot\mu$ = coordinates of $[P, W]/\hbar$ as heyoka expressions in the $N^2$
        components: the products written entry by entry (the expression grows like $N^3$).
        `integrators.ground_truth` compiles it in heyoka's compact mode (its size, from N = 3);
        how long that takes for each N: BENCHMARKS.md, "heyoka ground truth of Zeitlin's
        model"."""
        import heyoka as hy

        g, N, n = self.algebra, self.N, self.dim
        ys = list(hy.make_vars(*[f"y{i}" for i in range(n)]))
        eye = np.eye(n)
        Wmap = np.asarray(g.matrix(eye)).reshape(n, N * N)  # column a: the entries of E_a
        Pmap = np.asarray(jax.vmap(self.velocity_matrix)(g.matrix(eye))).reshape(n, N * N)
        Pmap = np.where(np.abs(Pmap) > 1e-14 * np.abs(Pmap).max(), Pmap, 0.0)  # round-off of the solve: no terms

        def linear(coeffs: np.ndarray) -> tuple[Any, Any]:
            re = [float(c) * ys[a] for a, c in enumerate(coeffs.real) if c != 0.0]
            im = [float(c) * ys[a] for a, c in enumerate(coeffs.imag) if c != 0.0]
            return (hy.sum(re) if re else None), (hy.sum(im) if im else None)

        W = [linear(Wmap[:, p]) for p in range(N * N)]
        P = [linear(Pmap[:, p]) for p in range(N * N)]

        def product(x, y, sign):  # the terms of sign * x * y, complex, as (re, im) lists
            (xr, xi), (yr, yi) = x, y
            re, im = [], []
            if xr is not None and yr is not None:
                re.append(sign * (xr * yr))
            if xi is not None and yi is not None:
                re.append(-sign * (xi * yi))
            if xr is not None and yi is not None:
                im.append(sign * (xr * yi))
            if xi is not None and yr is not None:
                im.append(sign * (xi * yr))
            return re, im

        C = {}
        for p in np.unique(g._p):
            i, j = divmod(int(p), N)
            re, im = [], []
            for k in range(N):
                for x, y, sign in ((P[i * N + k], W[k * N + j], 1.0), (W[i * N + k], P[k * N + j], -1.0)):
                    r, s = product(x, y, sign)
                    re += r
                    im += s
            C[int(p)] = (hy.sum(re) if re else hy.expression(0.0), hy.sum(im) if im else hy.expression(0.0))
        rhs: list[list[Any]] = [[] for _ in range(n)]
        for a, p, c in zip(g._a, g._p, g._c):
            cr, ci = C[int(p)]
            # mu_a = kappa Re(conj(c) C_p)
            if np.real(c) != 0.0:
                rhs[a].append(float(g.kappa * np.real(c)) * cr)
            if np.imag(c) != 0.0:
                rhs[a].append(float(g.kappa * np.imag(c)) * ci)
        return [(v, hy.sum(r) if r else hy.expression(0.0)) for v, r in zip(ys, rhs)]

    # -- fields on the sphere ------------------------------------------------------------------------
    def state_from_harmonics(self, omega: ArrayLike) -> np.ndarray:
        r"""The state of the vorticity field $\omega = \sum_{lm}\omega_{lm}Y^r_{lm}$ (real
        coefficients `(N^2,)`, index $l^2 + l + m$, quflow's convention)."""
        return np.asarray(self.algebra.coordinates(harmonics_to_matrix(omega, self.N)))

    def harmonics(self, y: ArrayLike) -> np.ndarray:
        r"""The real spherical-harmonic coefficients $\omega_{lm}$ of the state `y`."""
        y = np.asarray(as_state(y, "y", self.dim))
        if y.ndim != 1:
            raise ValueError(f"y must be one state of shape ({self.dim},); got shape {y.shape}")
        return matrix_to_harmonics(np.asarray(self.algebra.matrix(y)))

    def random_state(self, seed: int = 0, *, lmax: int | None = None, decay: float = 1.0) -> np.ndarray:
        r"""A random vorticity field: Gaussian coefficients up to degree `lmax` (default
        $\min(N-1, 10)$), damped by $(l(l+1))^{-\mathrm{decay}/2}$, no circulation
        ($\omega_{00} = 0$), unit $L^2$ norm (as quflow's `random_shr`)."""
        lmax = min(self.N - 1, 10) if lmax is None else positive_int(lmax, "lmax")
        if lmax > self.N - 1:
            raise ValueError(f"lmax must be <= N - 1 = {self.N - 1}; got {lmax}")
        if not np.isfinite(decay) or decay < 0:
            raise ValueError(f"decay must be a finite number >= 0; got {decay!r}")
        rng = np.random.default_rng(seed)
        omega = np.zeros(self.N * self.N)
        for l in range(1, lmax + 1):
            idx = np.arange(l * l, (l + 1) ** 2)
            omega[idx] = rng.normal(size=idx.size) / (l * (l + 1)) ** (decay / 2)
        norm = np.linalg.norm(omega)
        if not norm > 0:
            raise ValueError(f"decay={decay!r} damps every coefficient to zero; use a smaller one")
        return self.state_from_harmonics(omega / norm)

    def vorticity(self, y: ArrayLike, n_theta: int | None = None, n_phi: int | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r"""The vorticity field of state `y` on a colatitude-longitude grid:
        `(theta, phi, values)`, `values` `(n_theta, n_phi)`."""
        y = np.asarray(as_state(y, "y", self.dim))
        if y.ndim != 1:
            raise ValueError(f"y must be one state of shape ({self.dim},); got shape {y.shape}")
        for name, value in (("n_theta", n_theta), ("n_phi", n_phi)):
            if value is not None:
                positive_int(value, name)
        return vorticity_on_grid(np.asarray(self.algebra.matrix(y)), n_theta, n_phi)
