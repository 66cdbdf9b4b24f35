"""Named Lie algebras: structure constants, closed-form Casimirs and fast coadjoint flows."""

from __future__ import annotations

import numpy as np

from ._abstract_algebra import AbstractLieAlgebra
from ._algebra import LieAlgebra
from ._coadjoint import DirectSumFlow, RodriguesFlow, SE3Flow
from ._direct_sum import DirectSum
from ._polynomial import Polynomial


def levi_civita() -> np.ndarray:
    eps = np.zeros((3, 3, 3))
    for a, b, c in [(0, 1, 2), (1, 2, 0), (2, 0, 1)]:
        eps[a, b, c] = 1.0
        eps[b, a, c] = -1.0
    return eps


def _quadratic(dim: int, pairs: dict[tuple[int, int], float]) -> Polynomial:
    terms = []
    for (i, j), c in pairs.items():
        e = [0] * dim
        e[i] += 1
        e[j] += 1
        terms.append((c, tuple(e)))
    return Polynomial(dim, tuple(terms))


def so3(sign: int = -1) -> LieAlgebra:
    r"""so(3), $[e_a, e_b] = \epsilon_{abc} e_c$; Casimir $|\Pi|^2$; Rodrigues flow."""
    return LieAlgebra(
        levi_civita(),
        name="so3",
        basis_names=("Pi1", "Pi2", "Pi3"),
        casimirs=[_quadratic(3, {(0, 0): 1.0, (1, 1): 1.0, (2, 2): 1.0})],
        coadjoint_flow=RodriguesFlow(),
        sign=sign,
    )


def se3_structure_constants() -> np.ndarray:
    r"""se(3) = so(3) ⋉ R^3, $[(A_1,b_1),(A_2,b_2)] = (A_1\times A_2,\ A_1\times b_2 - A_2\times b_1)$."""
    eps = levi_civita()
    C = np.zeros((6, 6, 6))
    C[:3, :3, :3] = eps
    C[:3, 3:, 3:] = eps  # [e_a, f_j] = eps_ajk f_k
    C[3:, :3, 3:] = eps  # [f_i, e_b] = eps_ibk f_k
    return C


def se3(sign: int = -1) -> LieAlgebra:
    r"""se(3), $\mu = (\Pi, p)$; Casimirs $|p|^2$ and $\Pi\cdot p$; closed-form flow."""
    return LieAlgebra(
        se3_structure_constants(),
        name="se3",
        basis_names=("Pi1", "Pi2", "Pi3", "p1", "p2", "p3"),
        casimirs=[
            _quadratic(6, {(3, 3): 1.0, (4, 4): 1.0, (5, 5): 1.0}),
            _quadratic(6, {(0, 3): 1.0, (1, 4): 1.0, (2, 5): 1.0}),
        ],
        coadjoint_flow=SE3Flow(),
        sign=sign,
    )


def se2(sign: int = -1) -> LieAlgebra:
    r"""se(2), basis $(e_\theta, e_x, e_y)$: $[e_\theta, e_x] = e_y$, $[e_\theta, e_y] = -e_x$;
    Casimir $\mu_x^2 + \mu_y^2$."""
    C = np.zeros((3, 3, 3))
    C[0, 1, 2], C[1, 0, 2] = 1.0, -1.0
    C[0, 2, 1], C[2, 0, 1] = -1.0, 1.0
    return LieAlgebra(
        C,
        name="se2",
        basis_names=("mu_theta", "mu_x", "mu_y"),
        casimirs=[_quadratic(3, {(1, 1): 1.0, (2, 2): 1.0})],
        sign=sign,
    )


def sl2(sign: int = -1) -> LieAlgebra:
    r"""sl(2, R), basis $(h, e, f)$: $[h, e] = 2e$, $[h, f] = -2f$, $[e, f] = h$;
    Casimir $\mu_h^2 + 4\mu_e\mu_f$ (the inverse Killing form)."""
    C = np.zeros((3, 3, 3))
    C[0, 1, 1], C[1, 0, 1] = 2.0, -2.0
    C[0, 2, 2], C[2, 0, 2] = -2.0, 2.0
    C[1, 2, 0], C[2, 1, 0] = 1.0, -1.0
    return LieAlgebra(
        C,
        name="sl2",
        basis_names=("mu_h", "mu_e", "mu_f"),
        casimirs=[_quadratic(3, {(0, 0): 1.0, (1, 2): 4.0})],
        sign=sign,
    )


def heisenberg(sign: int = -1) -> LieAlgebra:
    r"""Heisenberg algebra, basis $(x, y, z)$: $[x, y] = z$, $z$ central; Casimir $\mu_z$."""
    C = np.zeros((3, 3, 3))
    C[0, 1, 2], C[1, 0, 2] = 1.0, -1.0
    return LieAlgebra(
        C,
        name="heisenberg",
        basis_names=("mu_x", "mu_y", "mu_z"),
        casimirs=[Polynomial(3, ((1.0, (0, 0, 1)),))],
        sign=sign,
    )


def direct_sum(*algebras: AbstractLieAlgebra, name: str | None = None) -> AbstractLieAlgebra:
    r"""$\mathfrak g_1 \oplus \dots \oplus \mathfrak g_k$. Of `LieAlgebra`s: a `LieAlgebra` with
    block structure constants, the union of the Casimirs, and a blockwise coadjoint flow keeping
    each summand's fast path. With a `MatrixLieAlgebra` (or a sum) among them: a `DirectSum`,
    every operation blockwise, no structure-constant tensor formed."""
    if not algebras:
        raise ValueError("direct_sum needs at least one algebra; got none")
    for i, g in enumerate(algebras):
        if not isinstance(g, AbstractLieAlgebra):
            raise TypeError(f"direct_sum arguments must be Lie algebras; argument {i} is {type(g).__name__}")
    if not all(isinstance(g, LieAlgebra) for g in algebras):
        return DirectSum(algebras, name)
    signs = {g.sign for g in algebras}
    if len(signs) != 1:
        raise ValueError("direct_sum needs summands with the same sign convention")
    n = sum(g.dim for g in algebras)
    C = np.zeros((n, n, n))
    casimirs, names, start = [], [], 0
    for g in algebras:
        m = g.dim
        C[start : start + m, start : start + m, start : start + m] = g.structure_constants
        casimirs += [p.shifted(start, n) for p in g.casimir_polynomials]
        names += [f"{g.name}.{b}" for b in g.basis_names]
        start += m
    flow = DirectSumFlow(
        [g.exact_flow for g in algebras],
        [g.dim for g in algebras],
        [g.structure_constants for g in algebras],
        n_casimirs=[g.n_casimirs for g in algebras],
    )
    return LieAlgebra(
        C,
        name=name or "+".join(g.name for g in algebras),
        basis_names=names,
        casimirs=casimirs,
        coadjoint_flow=flow,
        sign=signs.pop(),
    )
