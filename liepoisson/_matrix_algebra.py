r"""Matrix Lie algebras of any size: so(N), u(N), su(N), sp(2N, R), gl(N), sl(N), and the
semidirect products by the defining representation, se(N) = so(N) x R^N, gl(N) x R^N,
sl(N) x R^N, u(N) x C^N and su(N) x C^N (`semidirect`).

An element is an $m\times m$ matrix $X = \sum_a x_a E_a$ in a basis $E_a$ orthonormal for the
pairing $\langle A, B\rangle = \kappa\,\mathrm{Re}\,\mathrm{tr}(A^\dagger B)$ (`kappa`,
$\tfrac12$ for so(N) so that so(3)'s components are the angular momentum, 1 otherwise). The
same matrix represents a momentum $\mu \in \mathfrak g^*$ through $\mu_a = \langle M, E_a\rangle$.
With $\Pi$ the orthogonal projection onto the algebra (`coordinates`), ([the conventions
page][conventions])

$$\mathrm{ad}^*_\xi\mu \leftrightarrow \Pi[\Xi^\dagger, M], \qquad
\dot M = \Pi[\Xi^\dagger, M] \;\; (\text{body}, \Xi = \partial H/\partial\mu), \qquad
M(t) = \Pi\big(e^{t A^\dagger} M e^{-t A^\dagger}\big)$$

for the test flow of $\langle\alpha, \mu\rangle$ ($\langle\mathrm{Ad}^*_g\mu, \xi\rangle =
\langle M, gXg^{-1}\rangle$, and the projection of a conjugate of the orthogonal complement is
zero). Every algebra here but the semidirect products is closed under $X \mapsto X^\dagger$, and then $\Pi$ acts
as the identity: the flow is a conjugation, the whole spectrum of $M$ is kept and the Casimirs
are the traces of its powers. For so(N) and u(N), $\Xi^\dagger = -\Xi$ and the body equation is
$\dot M = [M, \Xi]$ (Manakov's $\dot M = [M, \Omega]$). se(N) as $(N+1)\times(N+1)$ matrices
$\begin{pmatrix}A & \sqrt2\,b\\ 0 & 0\end{pmatrix}$ (so that $(A, b)$ with
$\langle\cdot,\cdot\rangle = \tfrac12\mathrm{tr}A^\top A' + b\cdot b'$ is orthonormal): its
bracket is $([A, A'], Ab' - A'b)$, its orbits are not isospectral, and its Casimirs are given
below (`casimirs`); the other semidirect products likewise, with $b$ at unit scale.

Coordinates and matrices are converted by one scatter and one gather over the nonzero entries
of the basis, $O(m^2)$; brackets, $\mathrm{ad}^*$ and flows are matrix products, $O(m^3)$. No
structure-constant tensor is formed unless asked for (`structure_constants`, small algebras
only).
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._abstract_algebra import AbstractLieAlgebra
from ._expm import matrix_exponential
from ._inverse import gauss_newton_parameters
from ._memory import check_fits_in_memory, integer, memory_limit
from ._pfaffian import pfaffian
from ._samples import COMMON_PATH_ONLY
from ._validation import as_state

#: Largest dimension for which `structure_constants` is formed (n^3 float64: 16.8 MB at 128).
STRUCTURE_CONSTANTS_MAX_DIM = 128
#: Largest dimension for which `coadjoint_flow_parameters` (Gauss-Newton, a dense n x n
#: Jacobian per pair) is attempted.
FLOW_PARAMETERS_MAX_DIM = 400

#: The semidirect products g x R^N (C^N for u) by the defining representation, by family, and
#: the algebra g of each.
SEMIDIRECT = {"se": "so", "aff": "gl", "saff": "sl", "uaff": "u", "suaff": "su", "spaff": "sp"}
FAMILIES = ("so", "u", "su", "sp", "gl", "sl", *SEMIDIRECT)


def dagger(X: jax.Array) -> jax.Array:
    r"""$X^\dagger$ over the last two axes (the transpose of a real matrix)."""
    Xt = jnp.swapaxes(X, -1, -2)
    return jnp.conj(Xt) if jnp.iscomplexobj(X) else Xt


def _helmert(N: int) -> np.ndarray:
    """`(N, N - 1)`: orthonormal traceless diagonals, column k = (1, ..., 1, -k, 0, ...)/sqrt(k(k+1))."""
    H = np.zeros((N, N - 1))
    for k in range(1, N):
        H[:k, k - 1] = 1.0
        H[k, k - 1] = -float(k)
        H[:, k - 1] /= math.sqrt(k * (k + 1))
    return H


def _dual_coefficients(a: np.ndarray, c: np.ndarray, kappa: float) -> tuple[np.ndarray, bool]:
    r"""The coefficients $d_p$ of `coordinates`, $x_a = \mathrm{Re}\sum_p d_p X_p$: ideally
    $\kappa\,\bar c_p$, chosen among the floats next to it so that $\sum_p \mathrm{Re}(d_p c_p)$,
    the gain of `coordinates(matrix(x))`, is 1 as nearly as floats allow (exact rationals; one
    pass of +-1 ulp per entry). With $\kappa\,\bar c_p$ itself the gain of an entry
    $1/\sqrt2$ is $1 - 1.8\times10^{-16}$, a bias of one sign that a long composition of
    flows adds up (BENCHMARKS.md, "Casimirs of a long composition"). Elements with the same
    entries share the search (u(N)'s off-diagonal ones: two patterns). Also returns whether
    every gain is exactly 1 (entries +-1, +-i: the round trip is exact)."""
    c = np.asarray(c, dtype=np.complex128)
    d = kappa * np.conj(c)
    out = d.copy()
    order = np.argsort(a, kind="stable")
    bounds = np.flatnonzero(np.diff(a[order])) + 1
    found: dict[tuple[complex, ...], tuple[np.ndarray, bool]] = {}
    for entries in np.split(order, bounds):
        pattern = tuple(c[entries])
        if pattern not in found:
            found[pattern] = _best_dual(c[entries], d[entries])
        out[entries] = found[pattern][0]
    return out, all(exact for _, exact in found.values())


def _best_dual(c: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, bool]:
    """`d` moved by an ulp entry by entry where that brings sum Re(d c) nearer to 1 (exactly),
    and whether the gain is then exactly 1."""
    F = Fraction
    def term(v, w):  # Re(v w), exactly
        return F(float(v.real)) * F(float(w.real)) - F(float(v.imag)) * F(float(w.imag))

    values = [complex(v) for v in d]
    gain = sum(term(v, w) for v, w in zip(values, c))
    for i, (v, w) in enumerate(zip(values, c)):
        for candidate in (complex(np.nextafter(v.real, -np.inf), v.imag), complex(np.nextafter(v.real, np.inf), v.imag),
                          complex(v.real, np.nextafter(v.imag, -np.inf)), complex(v.real, np.nextafter(v.imag, np.inf))):
            if (candidate.real and not v.real) or (candidate.imag and not v.imag):
                continue  # an entry that is real (imaginary) stays so
            trial = gain - term(values[i], w) + term(candidate, w)
            if abs(trial - 1) < abs(gain - 1):
                values[i], gain = candidate, trial
    return np.asarray(values), gain == 1


#: An upper estimate of the bytes the construction takes per nonzero entry of the basis (the
#: Python lists `_basis` builds, then its arrays) and per basis element (its name and index).
_BYTES_PER_ENTRY = 100
_BYTES_PER_ELEMENT = 250


def _basis_size(family: str, N: int) -> tuple[int, int, int]:
    """`(m, dim, entries)` of `_basis(family, N)` in closed form (exact Python ints for any
    N): the matrix size, the dimension and the count of nonzero entries of the basis."""
    base = SEMIDIRECT.get(family, family)
    vector = 2 * N if base == "sp" else N
    diagonal = (N - 1) * (N + 2) // 2  # the traceless diagonals (_helmert): k + 2 entries each
    dim, entries = {
        "so": (N * (N - 1) // 2, N * (N - 1)),
        "u": (N * N, N + 2 * N * (N - 1)),
        "su": (N * N - 1, diagonal + 2 * N * (N - 1)),
        "gl": (N * N, N * N),
        "sl": (N * N - 1, diagonal + N * (N - 1)),
        "sp": (2 * N * N + N, 4 * N * N),
    }[base]
    if family in SEMIDIRECT:
        translations = 2 * vector if base in ("u", "su") else vector
        return vector + 1, dim + translations, entries + translations
    return vector, dim, entries


def _construction_bytes(family: str, N: int) -> int:
    """An upper estimate of the memory `MatrixLieAlgebra(family, N)` takes to build: its basis,
    `_helmert`'s dense matrix (su, sl) and one complex matrix of its size."""
    m, dim, entries = _basis_size(family, N)
    helmert = 8 * N * (N - 1) if SEMIDIRECT.get(family, family) in ("su", "sl") else 0
    return _BYTES_PER_ENTRY * entries + _BYTES_PER_ELEMENT * dim + helmert + 16 * m * m


def check_size(family: str, N: int, name: str = "N") -> None:
    """`ValueError` naming `name` (before anything is allocated) if `family`(N) would not fit
    in memory (`liepoisson._memory.memory_limit`), with the largest N that does."""
    need = _construction_bytes(family, N)
    if need <= memory_limit():
        return

    def fits(n: int) -> bool:
        return _construction_bytes(family, n) <= memory_limit()

    low = 1  # the largest N that fits: doubling, then bisection on the closed form
    while fits(2 * low):
        low *= 2
    high = 2 * low
    while high - low > 1:
        mid = (low + high) // 2
        low, high = (mid, high) if fits(mid) else (low, mid)
    m, dim, _ = _basis_size(family, N)
    check_fits_in_memory(
        need, f"{name}: {family}(N) at N = {integer(N)} (dimension {integer(dim)}, matrices {integer(m)} x "
        f"{integer(m)}) is too large to build: its basis", f"give N <= {low:,} for {family}(N) on this machine")


def _basis(family: str, N: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, float, list[str]]:
    r"""`(m, a, p, c, kappa, names)`: the basis as triples, $E_a$ has entry `c` at flat index `p`
    (row-major in an m x m matrix). A semidirect product g x V (`SEMIDIRECT`, V = R^N, C^N,
    R^{2N} for sp) is $[[A, s\,b], [0, 0]]$ in size $\dim V + 1$, g's basis first, the
    translations last ($s$ makes them unit vectors of the pairing: $\sqrt2$ for so's
    $\kappa = 1/2$)."""
    a_list: list[int] = []
    p_list: list[int] = []
    c_list: list[complex] = []
    names: list[str] = []

    def add(entries: list[tuple[int, int, complex]], name: str) -> None:
        a = len(names)
        for i, j, c in entries:
            a_list.append(a)
            p_list.append(i * m + j)
            c_list.append(c)
        names.append(name)

    r2 = 1.0 / math.sqrt(2.0)
    base = SEMIDIRECT.get(family, family)
    vector = 2 * N if base == "sp" else N  # the size of the defining representation
    m = vector + 1 if family in SEMIDIRECT else vector
    if base == "so":
        kappa = 0.5
        for i in range(N):
            for j in range(i + 1, N):
                add([(i, j, 1.0), (j, i, -1.0)], f"M{i + 1}{j + 1}")
    elif base in ("u", "su"):
        kappa = 1.0
        if base == "u":
            for i in range(N):
                add([(i, i, 1j)], f"d{i + 1}")
        else:
            H = _helmert(N)
            for k in range(N - 1):
                add([(i, i, 1j * H[i, k]) for i in range(k + 2)], f"h{k + 1}")
        for i in range(N):
            for j in range(i + 1, N):
                add([(i, j, r2), (j, i, -r2)], f"r{i + 1}{j + 1}")
                add([(i, j, 1j * r2), (j, i, 1j * r2)], f"s{i + 1}{j + 1}")
    elif base in ("gl", "sl"):
        kappa = 1.0
        if base == "gl":
            for i in range(N):
                for j in range(N):
                    add([(i, j, 1.0)], f"E{i + 1}{j + 1}")
        else:
            H = _helmert(N)
            for k in range(N - 1):
                add([(i, i, H[i, k]) for i in range(k + 2)], f"h{k + 1}")
            for i in range(N):
                for j in range(N):
                    if i != j:
                        add([(i, j, 1.0)], f"E{i + 1}{j + 1}")
    elif base == "sp":
        # sp(2N, R) = {[[a, b], [c, -a^T]] : b, c symmetric}.
        kappa = 1.0
        for i in range(N):
            for j in range(N):
                add([(i, j, r2), (N + j, N + i, -r2)], f"a{i + 1}{j + 1}")
        for i in range(N):
            add([(i, N + i, 1.0)], f"b{i + 1}{i + 1}")
            for j in range(i + 1, N):
                add([(i, N + j, r2), (j, N + i, r2)], f"b{i + 1}{j + 1}")
        for i in range(N):
            add([(N + i, i, 1.0)], f"c{i + 1}{i + 1}")
            for j in range(i + 1, N):
                add([(N + i, j, r2), (N + j, i, r2)], f"c{i + 1}{j + 1}")
    else:
        raise ValueError(f"family must be one of {FAMILIES}; got {family!r}")
    if family in SEMIDIRECT:
        scale = math.sqrt(1.0 / kappa)
        for i in range(vector):
            add([(i, vector, scale)], f"p{i + 1}")
            if base in ("u", "su"):
                add([(i, vector, 1j * scale)], f"q{i + 1}")
    return m, np.asarray(a_list), np.asarray(p_list), np.asarray(c_list), kappa, names


class MatrixLieAlgebra(AbstractLieAlgebra):
    r"""A classical matrix Lie algebra of any size, with the Lie-Poisson structure on its dual.

    **Arguments:**

    - `family`: `"so"` (so(N), $N\times N$ antisymmetric), `"u"` / `"su"` (skew-Hermitian,
      traceless for su), `"sp"` (sp(2N, R), $2N\times 2N$), `"gl"` / `"sl"` (real, traceless
      for sl), `"se"` (se(N) = so(N) x R^N, $(N+1)\times(N+1)$, coordinates
      $(M_{ij}, p_i)$), `"aff"`, `"saff"`, `"uaff"`, `"suaff"`, `"spaff"` (gl(N) x R^N,
      sl(N) x R^N, u(N) x C^N, su(N) x C^N, sp(2N) x R^{2N}: `liepoisson.semidirect`).
    - `N`: the size ($N \ge 2$; `"sp"`, `"spaff"`: $N \ge 1$, matrices $2N\times 2N$,
      $(2N+1)\times(2N+1)$).
    - `sign`: $-1$ for body (left-invariant) systems, $+1$ for spatial ones.

    The constructors `liepoisson.so(N)`, `u(N)`, `su(N)`, `sp(N)`, `gl(N)`, `sl(N)`, `se(N)` and
    `semidirect(g)` build them. `matrix(x)` and `coordinates(X)` convert between the two
    representations; the Casimirs are traces of powers and so(2k)'s Pfaffian, polynomials of
    the translations and the rest for the semidirect products (`casimirs`); the spectrum (not
    of a semidirect product) is `spectrum`.
    """

    def __init__(self, family: str, N: int, *, sign: int = -1):
        if not isinstance(family, str) or family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}; got {family!r}")
        if isinstance(N, bool) or not isinstance(N, (int, np.integer)):
            raise TypeError(f"N must be an integer; got {type(N).__name__} {N!r}")
        smallest = 1 if family in ("sp", "spaff") else 2
        if N < smallest:
            raise ValueError(f"N must be >= {smallest} for {family}(N); got {N}")
        if isinstance(sign, bool) or sign not in (-1, 1):
            raise ValueError(f"sign must be -1 (body) or +1 (spatial); got {sign!r}")
        check_size(family, int(N))
        self.family = family
        self.N = int(N)
        self.sign = int(sign)
        self.name = f"{family}{self.N}"
        m, a, p, c, kappa, names = _basis(family, self.N)
        self.size = m
        self.kappa = kappa
        self.basis_names = tuple(names)
        self.complex = SEMIDIRECT.get(family, family) in ("u", "su")
        self._dim = len(names)
        self._dtype = jnp.complex128 if self.complex else jnp.float64
        self._a = a
        self._p = p
        self._c = c if self.complex else c.real
        d, self._exact_round_trip = _dual_coefficients(a, c, kappa)
        self._d = d if self.complex else d.real

    # -- the two representations -----------------------------------------------------------
    @property
    def dim(self) -> int:
        return self._dim

    def matrix(self, x: ArrayLike) -> jax.Array:
        r"""$X = \sum_a x_a E_a$, `(..., m, m)` for `x` `(..., n)` (an element of $\mathfrak g$
        or, through the pairing, of $\mathfrak g^*$)."""
        return _matrix(self, as_state(x, "x", self.dim))

    def coordinates(self, X: ArrayLike) -> jax.Array:
        r"""$x_a = \langle X, E_a\rangle$, `(..., n)` for `X` `(..., m, m)`: the orthogonal
        projection onto the algebra, so it also takes any matrix to its nearest element."""
        X = jnp.asarray(X)
        if X.ndim < 2 or X.shape[-2:] != (self.size, self.size):
            raise ValueError(f"X must have shape (..., {self.size}, {self.size}) for {self.name}; got shape {X.shape}")
        return _coordinates(self, X)

    def _dagger(self, X: jax.Array) -> jax.Array:
        return dagger(X)

    # -- Lie algebra operations ----------------------------------------------------------------
    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        r"""$[\xi, \eta] = XY - YX$ in coordinates."""
        X = self.matrix(as_state(xi, "xi", self.dim))
        Y = self.matrix(as_state(eta, "eta", self.dim))
        return self.coordinates(X @ Y - Y @ X)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        r"""$\mathrm{ad}^*_\xi\mu \leftrightarrow [\Xi^\dagger, M]$."""
        X = self._dagger(self.matrix(as_state(xi, "xi", self.dim)))
        M = self.matrix(as_state(mu, "mu", self.dim))
        return self.coordinates(X @ M - M @ X)

    def poisson_action(self, mu: ArrayLike, xi: ArrayLike) -> jax.Array:
        r"""$\mathbb B(\mu)\,\xi = -\mathrm{sign}\cdot\mathrm{ad}^*_\xi\mu$ by two matrix products."""
        return -self.sign * self.ad_star(xi, mu)

    def poisson_tensor(self, mu: ArrayLike) -> jax.Array:
        r"""$\mathbb B(\mu)$ `(..., n, n)`, column $b$ = $\mathbb B(\mu)\,e_b$ (n products of
        $m\times m$ matrices: for moderate sizes; the dynamics never forms it)."""
        mu = as_state(mu, "mu", self.dim)
        eye = jnp.eye(self.dim)
        cols = jax.vmap(lambda e: self.poisson_action(mu, jnp.broadcast_to(e, mu.shape)), out_axes=-1)(eye)
        return cols

    def poisson_lstsq(self, mu: ArrayLike, v: ArrayLike, rcond: float = 1e-15) -> np.ndarray:
        r"""$\mathbb B(\mu)^+ v$ (NumPy). For so(N), u(N) and su(N), whose elements are normal
        matrices, in the eigenbasis of $M = Q\,\mathrm{diag}(m)\,Q^\dagger$, where
        $\mathbb B(\mu)\,\xi = v$ reads $\hat X_{jk}(m_k - m_j) = \hat T_{jk}$ with
        $\hat X = Q^\dagger\Xi^\dagger Q$, $T = -\mathrm{sign}\cdot V$: O(m^3) a state instead
        of the $n\times n$ pseudo-inverse ($n = m^2$). Pairs with $|m_k - m_j|$ below `rcond`
        times the largest are dropped (the pseudo-inverse's cut: its singular values are the
        $|m_k - m_j|$). Other families: the dense pseudo-inverse."""
        if self.family not in ("so", "u", "su"):
            return super().poisson_lstsq(mu, v, rcond)
        mu = np.asarray(as_state(mu, "mu", self.dim))
        v = np.asarray(as_state(v, "v", self.dim))
        iM = 1j * np.asarray(self.matrix(mu))
        # less its trace part (ad_M does not see it): eigenvalue gaps to the gaps' precision
        iM -= (np.trace(iM, axis1=-2, axis2=-1) / self.size)[..., None, None] * np.eye(self.size)
        lam, Q = np.linalg.eigh(iM)  # M = Q diag(-i lam) Q^dagger + its trace part
        Qh = np.conj(np.swapaxes(Q, -1, -2))
        T = Qh @ np.asarray(self.matrix(-self.sign * v)) @ Q
        gaps = lam[..., None, :] - lam[..., :, None]  # lam_k - lam_j; m_k - m_j = -i gaps
        cut = rcond * np.max(np.abs(gaps), axis=(-2, -1), keepdims=True)
        keep = np.abs(gaps) > cut
        X_hat = np.where(keep, 1j * T / np.where(keep, gaps, 1.0), 0.0)
        X = Q @ X_hat @ Qh
        return np.asarray(self.coordinates(np.asarray(self._dagger(jnp.asarray(X)))))

    @property
    def structure_constants(self) -> np.ndarray:
        r"""$C_{abd} = \langle [E_a, E_b], E_d\rangle$ (read-only), formed on first use, for
        dimensions up to `STRUCTURE_CONSTANTS_MAX_DIM`."""
        cached = self.__dict__.get("_C")
        if cached is not None:
            return cached
        n = self.dim
        if n > STRUCTURE_CONSTANTS_MAX_DIM:
            raise ValueError(
                f"{self.name} has dimension {n}: its structure-constant tensor would hold n^3 = {n**3:.3g} entries, "
                f"more than formed here (dimension <= {STRUCTURE_CONSTANTS_MAX_DIM}); its operations (bracket, "
                "ad_star, poisson_action, coadjoint_flow) work on matrices and need none"
            )
        with jax.ensure_compile_time_eval():  # concrete even when first asked for inside jit
            E = np.asarray(self.matrix(np.eye(n)))
            comm = np.einsum("aij,bjk->abik", E, E)
            comm = comm - comm.transpose(1, 0, 2, 3)
            C = np.array(self.coordinates(comm.reshape(n * n, self.size, self.size))).reshape(n, n, n)
        C[np.abs(C) < 1e2 * np.finfo(np.float64).eps] = 0.0  # exact zeros where round-off
        C.setflags(write=False)
        self.__dict__["_C"] = C
        return C

    # -- Casimirs --------------------------------------------------------------------------------
    @property
    def n_casimirs(self) -> int:
        """The index (the corank of the generic coadjoint orbit): floor(N/2) for so(N), N for u(N),
        gl(N) and sp(2N), N - 1 for su(N), sl(N), 1 + floor((N-1)/2) for se(N); 0, 1, N, N - 1, N
        for gl(N) x R^N, sl(N) x R^N, u(N) x C^N, su(N) x C^N, sp(2N) x R^{2N}."""
        return {"so": self.N // 2, "u": self.N, "su": self.N - 1, "sp": self.N,
                "gl": self.N, "sl": self.N - 1, "se": 1 + (self.N - 1) // 2,
                "aff": 0, "saff": 1, "uaff": self.N, "suaff": self.N - 1, "spaff": self.N}[self.family]

    @property
    def is_semidirect(self) -> bool:
        """Whether this is a semidirect product g x V (se, aff, saff, uaff, suaff, spaff): orbits
        not isospectral, Casimirs not traces of powers."""
        return self.family in SEMIDIRECT

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        r"""Traces of powers, real, `(..., k)`: so(N) $\tfrac12(-1)^k\mathrm{tr}\,M^{2k}$,
        $k = 1..\lfloor N/2\rfloor$ (so(3): $|\Pi|^2$), for even $N$ the last replaced by the
        Pfaffian $\mathrm{Pf}(M)$ (its square is $\det M$; its sign tells orbits apart that
        the traces confuse, and its gradient does not vanish where it does); u(N) $\mathrm{tr}\,(iM)^k$, $k = 1..N$
        (su(N): $2..N$); sp(2N) $\mathrm{tr}\,M^{2k}$, $k = 1..N$; gl(N) $\mathrm{tr}\,M^k$,
        $k = 1..N$ (sl(N): $2..N$). One matrix product per power. se(N), $\mu = (\Pi, p)$:
        $|p|^2$ and the Casimirs of the rotations about $p$, of $K = (|p|^2 - pp^\top)\Pi$
        (translations move $\Pi$ by $bp^\top - pb^\top$, which $K$ does not see):
        $\tfrac12(-1)^k\mathrm{tr}\,K^{2k}$, $k \le (N-1)/2$, and for odd $N$ the last replaced
        by the Pfaffian of $\begin{pmatrix}\Pi & p\\ -p^\top & 0\end{pmatrix}$ (invariant under
        translations as a congruence by a unimodular matrix; se(3): $-\Pi\cdot p$ in the vector
        components). The other semidirect products: `liepoisson.semidirect`."""
        return _casimirs(self, as_state(mu, "mu", self.dim))

    def _trace_casimirs(self) -> tuple[int, list[tuple[int, float]], bool]:
        r"""The Casimirs as `(q, [(k, s), ...], pfaffian_last)`:
        $C = s\,\mathrm{Re}\,\mathrm{tr}\,X^{qk}$ with $X = M$ ($iM$ for u, su) and $q = 2$ for so
        and sp (odd powers vanish), and whether a Pfaffian comes last (so(2k), module
        _pfaffian). Not for the semidirect products."""
        if self.family == "so":
            pfaffian_last = self.N % 2 == 0  # Pf(M) for tr M^N
            traces = self.N // 2 - pfaffian_last
            return 2, [(k, 0.5 * (-1) ** k) for k in range(1, traces + 1)], pfaffian_last
        if self.family == "sp":
            return 2, [(k, 1.0) for k in range(1, self.N + 1)], False
        first = 1 if self.family in ("u", "gl") else 2
        return 1, [(k, 1.0) for k in range(first, self.N + 1)], False

    def _casimir_values(self, mu: jax.Array) -> jax.Array:
        if self.is_semidirect:
            return _semidirect_casimirs(self, self.matrix(mu))
        M = self.matrix(mu)
        X = 1j * M if self.complex else M
        q, traces, pfaffian_last = self._trace_casimirs()
        step = X @ X if q == 2 else X
        out, P = [], None
        scales = dict(traces)
        for k in range(1, max(scales, default=0) + 1):
            P = step if P is None else P @ step  # step^k
            if k in scales:
                out.append(scales[k] * jnp.real(jnp.trace(P, axis1=-2, axis2=-1)))
        if pfaffian_last:
            out.append(pfaffian(M))
        return jnp.stack(out, axis=-1)

    def _casimir_gradient_values(self, mu: jax.Array) -> jax.Array:
        r"""Gradients `(..., k, n)` in closed form: with $X = cM$ and $p = qk$,
        $\partial_a\,s\,\mathrm{Re}\,\mathrm{tr}\,X^p = s\,p\,\mathrm{Re}\,\mathrm{tr}(cX^{p-1}E_a)
        = s\,p\,\langle (cX^{p-1})^\dagger, E_a\rangle/\kappa$; the Pfaffian's by its own
        derivative. (Reverse mode through the powers stores every power for every Casimir:
        BENCHMARKS.md, "Learned maps on matrix algebras".)"""
        M = self.matrix(mu)
        c = 1j if self.complex else 1.0
        X = c * M
        q, traces, pfaffian_last = self._trace_casimirs()
        step = X @ X if q == 2 else X
        out, P = [], jnp.broadcast_to(jnp.eye(self.size, dtype=X.dtype), X.shape)
        scales = dict(traces)
        for k in range(1, max(scales, default=0) + 1):
            if k > 1:
                P = P @ step  # step^(k-1)
            if k in scales:
                power = P @ X if q == 2 else P  # X^(p-1)
                out.append(scales[k] * q * k / self.kappa * self.coordinates(dagger(c * power)))
        if pfaffian_last:
            flat = mu.reshape(-1, self.dim)
            out.append(jax.vmap(jax.grad(lambda m: pfaffian(self.matrix(m))))(flat).reshape(mu.shape))
        return jnp.stack(out, axis=-2)

    def casimir_gradients(self, mu: ArrayLike) -> jax.Array:
        """Gradients of `casimirs`, `(..., k, n)`: in closed form (the semidirect products:
        reverse-mode differentiation)."""
        mu = as_state(mu, "mu", self.dim)
        grads = _casimir_gradients(self, mu.reshape(-1, self.dim))
        return grads.reshape(mu.shape[:-1] + (self.n_casimirs, self.dim))

    def spectrum(self, mu: ArrayLike) -> jax.Array:
        r"""The eigenvalues of $M$, kept by every coadjoint motion: real, ascending, of the
        Hermitian $iM$ for u(N), su(N) and of $-iM$ for so(N) (`(..., m)`); complex, of $M$ for
        the others, sorted by real then imaginary part."""
        if self.is_semidirect:
            raise ValueError(
                f"{self.name}'s coadjoint orbits are not isospectral (a translation changes the spectrum of the matrix "
                "of mu): it has no spectrum to keep; its invariants are casimirs(mu)"
            )
        M = self.matrix(as_state(mu, "mu", self.dim))
        if self.complex:
            return jnp.linalg.eigvalsh(1j * M)
        if self.family == "so":
            return jnp.linalg.eigvalsh(-1j * M.astype(jnp.complex128))
        return jnp.sort_complex(jnp.linalg.eigvals(M))

    # -- exact flows ------------------------------------------------------------------------------
    def _coadjoint_flow(self, alpha, t, mu):
        # The execution policy is read at trace time: a static argument, so that the program
        # traced for `common_path_first`'s first attempt is not reused for its second.
        return _coadjoint_flow(self, COMMON_PATH_ONLY.get(), alpha, t, mu)

    def _flow_parameters(self, mu0, mu1, t, casimir_gradients):
        if self.dim > FLOW_PARAMETERS_MAX_DIM:
            raise ValueError(
                f"coadjoint_flow_parameters on {self.name} (dimension {self.dim}): the Gauss-Newton inverse forms a "
                f"dense {self.dim} x {self.dim} Jacobian per pair and is attempted up to dimension "
                f"{FLOW_PARAMETERS_MAX_DIM}"
            )
        # A bound method: equal algebras compare equal, so the solver compiles once per algebra.
        return gauss_newton_parameters(self._flow_one, mu0, mu1, t, casimir_gradients)

    def _flow_one(self, alpha: jax.Array, t: jax.Array, mu: jax.Array) -> jax.Array:
        return self._coadjoint_flow(alpha, t, mu)

    # -- files -------------------------------------------------------------------------------------
    def definition(self) -> dict[str, Any]:
        return {"kind": "MatrixLieAlgebra", "family": self.family, "N": self.N, "sign": self.sign}

    def value_key(self) -> tuple[Any, ...]:
        return ("MatrixLieAlgebra", self.family, self.N, self.sign)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, MatrixLieAlgebra) and self.value_key() == other.value_key()

    def __hash__(self) -> int:
        return hash(self.value_key())

    def _bracket_scale(self) -> float:
        return 2.0


# Compiled once per algebra and shape (the algebra is static: equal algebras share the
# program), so that eager calls do not pay one XLA compilation per primitive.
@functools.partial(jax.jit, static_argnums=0)
def _matrix(algebra: MatrixLieAlgebra, x: jax.Array) -> jax.Array:
    batch = x.shape[:-1]
    values = jnp.asarray(algebra._c, algebra._dtype) * x[..., algebra._a]
    flat = jnp.zeros(batch + (algebra.size * algebra.size,), algebra._dtype).at[..., algebra._p].add(values)
    return flat.reshape(batch + (algebra.size, algebra.size))


@functools.partial(jax.jit, static_argnums=0)
def _coordinates(algebra: MatrixLieAlgebra, X: jax.Array) -> jax.Array:
    batch = X.shape[:-2]
    flat = X.reshape(batch + (algebra.size * algebra.size,))
    values = jnp.real(jnp.asarray(algebra._d, algebra._dtype) * flat[..., algebra._p])
    return jnp.zeros(batch + (algebra.dim,), jnp.float64).at[..., algebra._a].add(values)


@functools.partial(jax.jit, static_argnums=0)
def _casimirs(algebra: MatrixLieAlgebra, mu: jax.Array) -> jax.Array:
    return algebra._casimir_values(mu)


@functools.partial(jax.jit, static_argnums=0)
def _casimir_gradients(algebra: MatrixLieAlgebra, flat: jax.Array) -> jax.Array:
    if algebra.is_semidirect:
        return jax.vmap(jax.jacrev(algebra._casimir_values))(flat)
    return algebra._casimir_gradient_values(flat)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _coadjoint_flow(algebra: MatrixLieAlgebra, common_path_only: bool, alpha: jax.Array, t: jax.Array,
                    mu: jax.Array) -> jax.Array:
    r"""$e^{tA^\dagger} M e^{-tA^\dagger}$ in coordinates (body convention); `common_path_only`
    is `COMMON_PATH_ONLY`'s value when traced (`matrix_exponential` reads it)."""
    del common_path_only
    A = algebra._dagger(algebra.matrix(t[..., None] * alpha))
    M = algebra.matrix(mu)
    U = matrix_exponential(A)
    if algebra.family in ("so", "u", "su"):
        V = algebra._dagger(U)  # exp(A)^{-1} = exp(A)^dagger for a unitary group
    else:
        V = matrix_exponential(-A)
    if algebra._exact_round_trip:  # entries +-1: coordinates(matrix(mu)) is mu exactly
        out = algebra.coordinates(U @ M @ V)
    else:
        # mu plus the coordinates of the change: with the basis's irrational entries (1/sqrt2,
        # Helmert's, se's sqrt2) coordinates(matrix(mu)) is mu only up to a rounding bias of one
        # sign, which a composition of flows would add up (BENCHMARKS.md, "Casimirs of a long
        # composition"); on the change it is as small as the change
        out = mu + algebra.coordinates(U @ M @ V - M)
    return out


def _semidirect_casimirs(algebra: MatrixLieAlgebra, M: jax.Array) -> jax.Array:
    """The Casimirs of a semidirect product from the matrix of mu (`MatrixLieAlgebra.casimirs`),
    `(..., n_casimirs)`."""
    N = algebra.N
    if algebra.family == "se":
        return _se_casimirs(M, N)
    if algebra.family == "spaff":
        return _spaff_casimirs(M, N)
    if algebra.family == "aff":
        return jnp.zeros(M.shape[:-2] + (0,), jnp.float64)
    A = M[..., :N, :N]
    p = M[..., :N, N]  # the translations' components (unit scale: kappa = 1)
    if algebra.family == "saff":
        # det [p, A p, ..., A^(N-1) p] (SL(N) x R^N)
        columns = [p]
        for _ in range(N - 1):
            columns.append((A @ columns[-1][..., None])[..., 0])
        return jnp.linalg.det(jnp.stack(columns, axis=-1))[..., None]
    # uaff: |p|^2 and Re tr (iK)^k, k = 1..N-1, K = Q A, Q = |p|^2 - p p^dagger; suaff: k = 2..N-1
    # and K = Q (tr(Q) A - tr(QA)), which su's translations (A moved by a multiple of i less
    # than u's) do not see; a polynomial, no division by |p|
    squared = jnp.sum(jnp.real(jnp.conj(p) * p), axis=-1)
    QA = squared[..., None, None] * A - p[..., :, None] * (jnp.conj(p)[..., None, :] @ A)
    first = 1
    if algebra.family == "suaff":
        trace_QA = jnp.trace(QA, axis1=-2, axis2=-1)
        QA = ((N - 1) * squared)[..., None, None] * QA - trace_QA[..., None, None] * (
            squared[..., None, None] * jnp.eye(N) - p[..., :, None] * jnp.conj(p)[..., None, :])
        first = 2
    K = 1j * QA
    out, P = [squared], None
    for k in range(1, N):
        P = K if P is None else P @ K
        if k >= first:
            out.append(jnp.real(jnp.trace(P, axis1=-2, axis2=-1)))
    return jnp.stack(out, axis=-1)


def _spaff_casimirs(M: jax.Array, N: int) -> jax.Array:
    r"""sp(2N) x R^{2N}'s Casimirs from the matrix of mu, `(..., N)`. With $S = -JA$ (symmetric:
    $A = JS$), $u = Jp$: $c = p^\top Sp$, and the invariants of the quadratic form $S$ on
    $V_0 = \{x : u^\top x = 0\} \ni p$ (a translation adds $\mathrm{sym}(uv^\top)$ to $S$,
    zero there), reduced modulo $p$ by its Schur complement $T = cS - (Sp)(Sp)^\top$ ($Tp = 0$)
    and carried to the whole space by $\tilde P = c + wu^\top$, $w = -JSp$ ($\tilde Px = cx$
    on $V_0$, $\tilde Pw = 0$): $\mathrm{tr}\,L^{2k}$, $k = 1..N-1$, $L = -J\tilde P^\top
    T\tilde P$, whose spectrum is $c^2$ times that of $J^{-1}T$ on the symplectic space
    $V_0/p$ (the sp(2N-2) that fixes $p$), and zeros. A polynomial: no division."""
    m = 2 * N
    J = jnp.asarray(np.block([[np.zeros((N, N)), np.eye(N)], [-np.eye(N), np.zeros((N, N))]]))
    A = M[..., :m, :m]
    p = M[..., :m, m]
    S = -J @ A
    Sp = (S @ p[..., None])[..., 0]
    c = jnp.sum(p * Sp, axis=-1)
    out = [c]
    if N > 1:
        T = c[..., None, None] * S - Sp[..., :, None] * Sp[..., None, :]
        u = p @ J.T  # J p
        w = -(Sp @ J.T)  # -J S p
        Pt = c[..., None, None] * jnp.eye(m) + w[..., :, None] * u[..., None, :]
        L = -J @ jnp.swapaxes(Pt, -1, -2) @ T @ Pt
        L2, P = L @ L, None
        for _ in range(1, N):
            P = L2 if P is None else P @ L2
            out.append(jnp.trace(P, axis1=-2, axis2=-1))
    return jnp.stack(out, axis=-1)


def _se_casimirs(M: jax.Array, N: int) -> jax.Array:
    """se(N)'s Casimirs from the matrix of mu (`MatrixLieAlgebra.casimirs`), `(..., 1 + (N-1)//2)`."""
    Pi = M[..., :N, :N]
    p = M[..., :N, N] / math.sqrt(2.0)
    squared = jnp.sum(p * p, axis=-1)
    out = [squared]
    rotations = (N - 1) // 2
    pfaffian_last = N % 2 == 1 and rotations > 0
    traces = rotations - pfaffian_last
    if traces:
        K = squared[..., None, None] * Pi - p[..., :, None] * (p[..., None, :] @ Pi)  # (|p|^2 - p p^T) Pi
        K2, P = K @ K, None
        for k in range(1, traces + 1):
            P = K2 if P is None else P @ K2
            out.append(0.5 * (-1) ** k * jnp.trace(P, axis1=-2, axis2=-1))
    if pfaffian_last:
        bordered = jnp.concatenate([
            jnp.concatenate([Pi, p[..., :, None]], axis=-1),
            jnp.concatenate([-p[..., None, :], jnp.zeros(p.shape[:-1] + (1, 1), M.dtype)], axis=-1),
        ], axis=-2)
        out.append(pfaffian(bordered))
    return jnp.stack(out, axis=-1)


def so(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""so(N), $N\times N$ antisymmetric matrices, basis $E_{ij} - E_{ji}$ ($i < j$), pairing
    $\tfrac12\mathrm{tr}(A^\top B)$: the components of $\mu$ are the entries $M_{ij}$, $i<j$."""
    return MatrixLieAlgebra("so", N, sign=sign)


def u(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""u(N), $N\times N$ skew-Hermitian matrices (dimension $N^2$), pairing
    $\mathrm{Re}\,\mathrm{tr}(A^\dagger B)$."""
    return MatrixLieAlgebra("u", N, sign=sign)


def su(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""su(N), traceless skew-Hermitian matrices (dimension $N^2 - 1$)."""
    return MatrixLieAlgebra("su", N, sign=sign)


def sp(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""sp(2N, R), $2N\times 2N$ Hamiltonian matrices $[[a, b], [c, -a^\top]]$, $b, c$
    symmetric (dimension $2N^2 + N$)."""
    return MatrixLieAlgebra("sp", N, sign=sign)


def gl(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""gl(N, R), all real $N\times N$ matrices (dimension $N^2$)."""
    return MatrixLieAlgebra("gl", N, sign=sign)


def sl(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""sl(N, R), traceless real $N\times N$ matrices (dimension $N^2 - 1$)."""
    return MatrixLieAlgebra("sl", N, sign=sign)


def se(N: int, sign: int = -1) -> MatrixLieAlgebra:
    r"""se(N) = so(N) x R^N, the Euclidean algebra as $(N+1)\times(N+1)$ matrices, coordinates
    $\mu = (M_{ij}\ (i<j), p_1..p_N)$ (dimension $N(N+1)/2$): the rigid body in a fluid and
    the heavy top of N dimensions. No structure-constant tensor; Casimirs `casimirs`."""
    return MatrixLieAlgebra("se", N, sign=sign)


def semidirect(algebra: MatrixLieAlgebra) -> MatrixLieAlgebra:
    r"""$\mathfrak g \ltimes V$, $V$ the defining representation, column vectors: $\mathbb R^N$
    for so(N) (se(N)), gl(N) (the affine algebra), sl(N) (the special affine algebra),
    $\mathbb C^N$ for u(N), su(N), $\mathbb R^{2N}$ for sp(2N); matrices
    $\begin{pmatrix}A & s\,b\\ 0 & 0\end{pmatrix}$ of size $\dim V + 1$, coordinates
    $\mu = (\text{g's}, p)$ (u, su: $p_i$, $q_i$ the real and imaginary parts), the same sign.
    Casimirs (`casimirs`): se(N)'s;
    none for aff(N) (a Frobenius algebra: an open orbit); $\det[p, Ap, \ldots, A^{N-1}p]$ for
    sl(N) (SL(N) keeps volumes, and a translation moves $A$ by $pb^\top$ less its trace,
    which adds to $A^kp$ only combinations of lower powers); $|p|^2$ and
    $\mathrm{Re}\,\mathrm{tr}(iK)^k$, $K = (|p|^2 - pp^\dagger)A$, $k = 1..N-1$, for u(N)
    (the unitary group of the complement of $p$, as for se); for su(N), $|p|^2$ and
    $\mathrm{Re}\,\mathrm{tr}(iK)^k$, $k = 2..N-1$, $K = Q(\mathrm{tr}(Q)A - \mathrm{tr}(QA))$,
    $Q = |p|^2 - pp^\dagger$ (su's translations move $A$ by a multiple of $i$ less than u's,
    which $K$ does not see); for sp(2N) x R^{2N} ($(2N+1)\times(2N+1)$), $p^\top S p$
    ($S = -JA$) and the traces of powers of the form $S$ reduced to the symplectic space
    $\{x : (Jp)^\top x = 0\}/p$ (module function `_spaff_casimirs`)."""
    if not isinstance(algebra, MatrixLieAlgebra):
        raise TypeError(f"algebra must be a liepoisson.MatrixLieAlgebra (so, gl, sl, u, su or sp); got "
                        f"{type(algebra).__name__}")
    family = {base: name for name, base in SEMIDIRECT.items()}.get(algebra.family)
    if family is None:
        raise ValueError(
            f"semidirect products with the defining representation are built for so, gl, sl, u, su and sp; got "
            f"{algebra.name}, itself a semidirect product"
        )
    check_size(family, algebra.N, "algebra")
    return MatrixLieAlgebra(family, algebra.N, sign=algebra.sign)
