r"""Real Lie algebras from structure constants and their Lie-Poisson structure on g*.

Conventions ([the conventions page][conventions]): $[e_a, e_b] = C_{abd}\,e_d$;
$\mathbb{B}(\mu)_{ab} = \mathrm{sign}\cdot C_{abd}\,\mu_d$ (body convention `sign = -1`);
$\dot\mu = \mathbb{B}(\mu)\,\partial H/\partial\mu$.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._abstract_algebra import AbstractLieAlgebra
from ._casimir_values import casimir_gradient_values, casimir_values
from ._casimirs import polynomial_casimirs
from ._coadjoint import AbstractCoadjointFlow, MatrixExponentialFlow
from ._polynomial import Polynomial
from ._structure import check_structure_constants, generic_corank
from ._validation import as_state, matrix_basis


def _warn_if_casimirs_missing(C: np.ndarray, found: int, degree: int, name: Any) -> None:
    corank = generic_corank(C)
    if found < corank:
        warnings.warn(
            f"LieAlgebra {name or ''}: found {found} polynomial Casimir(s) of degree <= {degree}, "
            f"but the Poisson tensor has generic corank {corank}, so {corank - found} independent "
            f"Casimir(s) are missing (Casimir drift will not cover them). Raise the degree searched "
            f"(LieAlgebra(C, max_casimir_degree={degree + 2})), or pass casimirs=[...] yourself if "
            "they are not polynomial (e.g. rational or logarithmic Casimirs of solvable algebras)",
            stacklevel=3,
        )


class LieAlgebra(AbstractLieAlgebra):
    r"""A real Lie algebra $\mathfrak g$ given by structure constants, with the Lie-Poisson
    structure on $\mathfrak g^*$.

    **Arguments:**

    - `structure_constants`: array `(n, n, n)`, $[e_a, e_b] = C_{abd} e_d$; validated for
      antisymmetry and the Jacobi identity.
    - `name`, `basis_names`: labels for messages, files and plots.
    - `casimirs`: polynomial Casimirs (closed forms); `None` computes a functionally
      independent polynomial basis automatically (up to `max_casimir_degree`).
    - `coadjoint_flow`: the evaluator of $\exp(t\mathbb M(\alpha))\mu$; default the matrix
      exponential, closed forms for so(3) and se(3) (`RodriguesFlow`, `SE3Flow`).
    - `sign`: $-1$ for body (left-invariant) systems, $+1$ for spatial ones.
    """

    def __init__(
        self,
        structure_constants: Any,
        name: str | None = None,
        basis_names: Sequence[str] | None = None,
        *,
        casimirs: Sequence[Polynomial] | None = None,
        coadjoint_flow: AbstractCoadjointFlow | None = None,
        sign: int = -1,
        max_casimir_degree: int = 4,
    ):
        C = check_structure_constants(structure_constants)
        n = C.shape[0]
        if isinstance(sign, bool) or sign not in (-1, 1):
            raise ValueError(f"sign must be -1 (body) or +1 (spatial); got {sign!r}")
        if basis_names is None:
            basis_names = tuple(f"e{i + 1}" for i in range(n))
        basis_names = tuple(str(b) for b in basis_names)
        if len(basis_names) != n:
            raise ValueError(f"basis_names must have {n} entries; got {len(basis_names)}")
        if casimirs is None:
            casimirs = polynomial_casimirs(C, max_degree=max_casimir_degree)
            _warn_if_casimirs_missing(C, len(casimirs), max_casimir_degree, name)
        else:
            casimirs = tuple(casimirs)
            for i, p in enumerate(casimirs):
                if not isinstance(p, Polynomial) or p.dim != n:
                    raise TypeError(f"casimirs[{i}] must be a Polynomial in {n} variables; got {p!r}")
        if coadjoint_flow is None:
            coadjoint_flow = MatrixExponentialFlow()
        if not isinstance(coadjoint_flow, AbstractCoadjointFlow):
            raise TypeError(
                f"coadjoint_flow must be an AbstractCoadjointFlow; got {type(coadjoint_flow).__name__}"
            )
        self._C = C
        self.name = "lie_algebra" if name is None else str(name)
        self.basis_names = basis_names
        self.sign = int(sign)
        self.casimir_polynomials: tuple[Polynomial, ...] = tuple(casimirs)
        self.exact_flow = coadjoint_flow
        self._casimir_gradient_polys = tuple(p.gradient() for p in self.casimir_polynomials)

    # -- basic data ----------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return self._C.shape[0]

    @property
    def structure_constants(self) -> np.ndarray:
        """$C_{abd}$ with $[e_a, e_b] = C_{abd} e_d$ (read-only)."""
        return self._C

    @property
    def n_casimirs(self) -> int:
        return len(self.casimir_polynomials)

    # -- portable definition ---------------------------------------------------------------
    def definition(self) -> dict[str, Any]:
        """Everything that defines this algebra as JSON values (saved with data sets and models
        of user systems): structure constants, name, basis names, sign, Casimir polynomials and
        the kind of coadjoint-flow evaluator. `LieAlgebra.from_definition` inverts it."""
        return {
            "name": self.name,
            "basis_names": list(self.basis_names),
            "structure_constants": self._C.tolist(),
            "sign": self.sign,
            "casimirs": [[[c, list(e)] for c, e in p.terms] for p in self.casimir_polynomials],
            "coadjoint_flow": type(self.exact_flow).__name__,
        }

    @classmethod
    def from_definition(cls, definition: Any, what: str = "definition") -> LieAlgebra:
        """The algebra of `definition()`; `ValueError` naming `what` for a malformed one. The
        closed-form evaluators (`RodriguesFlow`, `SE3Flow`) are restored; any other evaluator
        is replaced by the matrix exponential (the same exact flow)."""
        from ._coadjoint import RodriguesFlow, SE3Flow

        try:
            C = np.asarray(definition["structure_constants"], dtype=np.float64)
            n = C.shape[0]
            casimirs = tuple(
                Polynomial(n, tuple((float(c), tuple(int(k) for k in e)) for c, e in terms))
                for terms in definition["casimirs"]
            )
            flows = {"RodriguesFlow": RodriguesFlow, "SE3Flow": SE3Flow}
            flow = flows.get(definition.get("coadjoint_flow"), MatrixExponentialFlow)()
            return cls(C, definition["name"], definition["basis_names"], casimirs=casimirs,
                       coadjoint_flow=flow, sign=int(definition["sign"]))
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
            raise ValueError(f"{what} is not a valid Lie algebra definition: {type(err).__name__}: {err}") from err

    @classmethod
    def from_matrices(
        cls, basis: Any, name: str | None = None, basis_names: Sequence[str] | None = None, **kwargs: Any
    ) -> LieAlgebra:
        r"""The algebra spanned by a basis of matrices $E_a$ under the commutator:
        $[E_a, E_b] = E_aE_b - E_bE_a = C_{abd}\,E_d$, solved for $C$ by least squares.

        **Arguments:** `basis`, an array `(n, m, m)` of linearly independent real matrices whose
        commutators stay in their span (e.g. the $E_{ij} - E_{ji}$ of so(m)); `name`,
        `basis_names` and the keyword arguments of `LieAlgebra`.

        `ValueError` naming the pair whose commutator leaves the span, or when the matrices
        are dependent.
        """
        E = matrix_basis(basis, "(n, m, m)")
        n = E.shape[0]
        flat = E.reshape(n, -1).T  # (m*m, n): columns are the basis matrices
        if np.linalg.matrix_rank(flat) < n:
            raise ValueError(f"basis: the {n} matrices are linearly dependent (rank {np.linalg.matrix_rank(flat)})")
        comm = np.einsum("aij,bjk->abik", E, E)
        comm = (comm - comm.transpose(1, 0, 2, 3)).reshape(n * n, -1).T
        coeffs, *_ = np.linalg.lstsq(flat, comm, rcond=None)
        residual = np.abs(flat @ coeffs - comm).max(axis=0)
        # Exact span: the residual is round-off of the lstsq solve, a few eps x |E|^2.
        scale = max(1.0, float(np.abs(E).max()) ** 2)
        worst = int(np.argmax(residual))
        if residual[worst] > 1e3 * np.finfo(np.float64).eps * scale:
            a, b = divmod(worst, n)
            raise ValueError(
                f"basis: the commutator [E_{a}, E_{b}] is not in the span of the basis (residual "
                f"{residual[worst]:.2e}); the matrices do not span a Lie algebra"
            )
        C = coeffs.T.reshape(n, n, n)
        C[np.abs(C) < 1e3 * np.finfo(np.float64).eps * scale] = 0.0  # exact zeros where round-off
        return cls(C, name, basis_names, **kwargs)

    # -- Lie algebra operations ----------------------------------------------------------
    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        r"""$[\xi, \eta]_d = C_{abd}\,\xi_a\,\eta_b$, batched over leading axes."""
        xi = as_state(xi, "xi", self.dim)
        eta = as_state(eta, "eta", self.dim)
        return jnp.einsum("abd,...a,...b->...d", self._C, xi, eta)

    def ad(self, xi: ArrayLike) -> jax.Array:
        r"""Matrix of $\mathrm{ad}_\xi = [\xi, \cdot]$: $(\mathrm{ad}_\xi)_{db} = C_{abd}\,\xi_a$."""
        xi = as_state(xi, "xi", self.dim)
        return jnp.einsum("abd,...a->...db", self._C, xi)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        r"""$(\mathrm{ad}^*_\xi\mu)_b = \langle \mu, [\xi, e_b]\rangle = C_{abd}\,\xi_a\,\mu_d$."""
        xi = as_state(xi, "xi", self.dim)
        mu = as_state(mu, "mu", self.dim)
        return jnp.einsum("abd,...a,...d->...b", self._C, xi, mu)

    # -- Lie-Poisson structure -----------------------------------------------------------
    def poisson_tensor(self, mu: ArrayLike) -> jax.Array:
        r"""$\mathbb{B}(\mu)_{ab} = \mathrm{sign}\cdot C_{abd}\,\mu_d$, shape `(..., n, n)`."""
        mu = as_state(mu, "mu", self.dim)
        return self.sign * jnp.einsum("abd,...d->...ab", self._C, mu)

    def coadjoint_generator(self, alpha: ArrayLike) -> jax.Array:
        r"""$\mathbb{M}(\alpha)_{ad} = \mathrm{sign}\cdot C_{abd}\,\alpha_b$: $\dot\mu = \mathbb{M}(\alpha)\mu$
        is the flow of $H = \langle\alpha, \mu\rangle$."""
        alpha = as_state(alpha, "alpha", self.dim)
        return self.sign * jnp.einsum("abd,...b->...ad", self._C, alpha)

    def _coadjoint_flow(self, alpha, t, mu):
        return self.exact_flow(self._C, alpha, t, mu)

    def _coadjoint_increment(self, alpha, t, mu):
        return self.exact_flow.increment(self._C, alpha, t, mu)

    def _flow_parameters(self, mu0, mu1, t, casimir_gradients):
        return self.exact_flow.parameters(self._C, mu0, mu1, t, casimir_gradients)

    # -- Casimirs --------------------------------------------------------------------------
    def casimirs(self, mu: ArrayLike) -> jax.Array:
        """Values of the independent Casimirs, shape `(..., k)`."""
        return casimir_values(self.casimir_polynomials, as_state(mu, "mu", self.dim))

    def casimir_gradients(self, mu: ArrayLike) -> jax.Array:
        """Gradients $\\partial C_j/\\partial\\mu$, shape `(..., k, n)`."""
        return casimir_gradient_values(self._casimir_gradient_polys, as_state(mu, "mu", self.dim))

    def _bracket_scale(self) -> float:
        return max(1.0, float(np.max(np.abs(self._C))))
