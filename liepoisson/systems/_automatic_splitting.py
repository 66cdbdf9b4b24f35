r"""Exact splittings derived from the Hamiltonian's expression, for any algebra.

$H = Q + \sum_k H_k$ with $Q(\mu) = \tfrac12\mu^\top A\mu + b^\top\mu$ the addends of $H$ that
are polynomials of degree at most 2 and $H_k$ the others:

- $Q$ splits by the eigen-decomposition $A = \sum_k \lambda_k v_k v_k^\top$ into
  $\tfrac{\lambda_k}{2}\langle v_k,\mu\rangle^2$ and $\langle b,\mu\rangle$: each a function of one
  linear form, so collective with an exact flow (a frozen test flow);
- an addend $H_k$ whose gradient spans the linear forms $L$ (rows, found from gradients at
  random states) is a function of $L\mu$; it is collective, with an exact flow, when the forms
  Poisson-commute ($L\mathbb B(\mu)L^\top = 0$), always the case for one form, as for
  $\varphi(\langle v,\mu\rangle)$ (a ridge term).

A function of the Casimirs ($\mathbb B\nabla H_k = 0$) is also collective: its flow is the
identity. An addend that depends on linear forms that do not commute (e.g. $\mu_1\mu_2\sin\mu_3$ on
so(3)) has no exact flow this way: then the splitting is refused with the addend named, and
`splitting=[...]` must be given.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._namespace import JAX
from .._symbolic import addends, evaluate, polynomial_degree, to_text
from ._base import AbstractPoissonSystem
from ._terms import CollectiveTerm

# Eigenvalues of A below this fraction of the largest are zero (their pieces are dropped), and
# gradient directions below it are not part of an addend's span: a few hundred roundings.
_RANK_RTOL = 1e-12


class _Quadratic:
    r"""$\varphi(s) = \tfrac{\lambda}{2}s_0^2$."""

    def __init__(self, lam: float):
        self.lam = float(lam)

    def __call__(self, s):
        return 0.5 * self.lam * s[0] ** 2


class _Linear:
    r"""$\varphi(s) = s_0$."""

    def __call__(self, s):
        return s[0]


class _Addend:
    r"""$\varphi(s) = H_k(L^\top s)$ for an addend $H_k$ that depends on $\mu$ only through
    $L\mu$ ($L$ with orthonormal rows, so $L L^\top s = s$)."""

    def __init__(self, tree: Any, forms: np.ndarray):
        self.tree, self.forms = tree, forms

    def __call__(self, s):
        m, n = self.forms.shape
        y = [sum(float(self.forms[j, i]) * s[j] for j in range(m)) for i in range(n)]
        return evaluate(self.tree, y, JAX)


def automatic_splitting(system: AbstractPoissonSystem, tree: Any) -> tuple[CollectiveTerm, ...]:
    """Exact collective pieces of the Hamiltonian with expression `tree` (see the module
    docstring); `ValueError` naming the addend that has no exact flow."""
    n = system.dim
    names = list(system.state_names)
    quadratic, others = [], []
    for a in addends(tree):
        d = polynomial_degree(a)
        (quadratic if d is not None and d <= 2 else others).append(a)
    pieces: list[CollectiveTerm] = []

    def q(y):
        return sum((evaluate(a, list(y), JAX) for a in quadratic), 0.0)

    if quadratic:
        zero = jnp.zeros(n)
        A = np.asarray(jax.hessian(q)(zero), dtype=np.float64)
        b = np.asarray(jax.grad(q)(zero), dtype=np.float64)
        A = 0.5 * (A + A.T)
        lam, V = np.linalg.eigh(A)
        big = np.max(np.abs(lam), initial=0.0)
        for k in np.argsort(-np.abs(lam)):
            if abs(lam[k]) > _RANK_RTOL * big:
                v = V[:, k]
                pieces.append(CollectiveTerm(v, _Quadratic(lam[k]), f"{lam[k]:.4g}/2 <v{len(pieces) + 1}, mu>^2"))
        if np.any(b != 0.0):
            pieces.append(CollectiveTerm(b, _Linear(), "<b, mu>"))
    rng = np.random.default_rng(0)
    y = rng.normal(size=(2 * n + 2, n))
    B = np.asarray(system.poisson_tensor(y))
    for a in others:
        g = np.asarray(jax.vmap(jax.grad(lambda z, a=a: evaluate(a, list(z), JAX)))(jnp.asarray(y)))
        if not np.all(np.isfinite(g)):
            raise ValueError(
                f"the addend {to_text(a, names)} of the Hamiltonian is not differentiable at random states; "
                "give splitting=[...] yourself"
            )
        _, s, Vt = np.linalg.svd(g, full_matrices=False)
        r = int(np.sum(s > _RANK_RTOL * max(s[0], np.finfo(np.float64).tiny)))
        if r == 0:
            continue  # a constant
        L = Vt[:r]
        # Exact iff L y is conserved: L B(y) grad = 0 (commuting forms, or B grad = 0 for a
        # function of the Casimirs, whose flow is the identity).
        rate = np.einsum("id,nde,ne->ni", L, B, g)
        if np.max(np.abs(rate)) > 1e3 * np.finfo(np.float64).eps * np.max(np.abs(B)) * np.max(np.abs(g)):
            raise ValueError(
                f"the addend {to_text(a, names)} of the Hamiltonian depends on {r} linear forms that "
                "do not Poisson-commute, so it has no exact flow by frozen test flows; give "
                "splitting=[...] yourself (pieces whose forms commute, e.g. one form each)"
            )
        pieces.append(CollectiveTerm(L, _Addend(a, L), to_text(a, names)))
    if not pieces:
        raise ValueError("the Hamiltonian is constant: there is nothing to split")
    return tuple(pieces)
