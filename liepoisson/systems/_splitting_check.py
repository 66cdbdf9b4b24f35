r"""Checks that a splitting $H = \sum_k H_k$ is what a splitting method needs: the pieces add
up to $H$ and each piece's flow is exact."""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from ._base import AbstractPoissonSystem
from ._terms import AbstractExactTerm, CollectiveTerm

_EPS = np.finfo(np.float64).eps


def _label(k: int, term: AbstractExactTerm) -> str:
    return f"piece {k} ({term.name or repr(term)})"


def check_splitting(system: AbstractPoissonSystem, terms: Any, where: str = "terms") -> tuple[AbstractExactTerm, ...]:
    r"""`terms` as a tuple of exact pieces of `system`'s Hamiltonian; raises naming `where` and the
    piece otherwise. Checked at 16 seeded random points:

    - every piece is an `AbstractExactTerm` (`TypeError`);
    - $\sum_k H_k = H$ up to a constant, to $10^3\varepsilon$ relative to the sizes of the values
      (a few dozen roundings; a wrong sum integrates another Hamiltonian at every $h$);
    - a `CollectiveTerm`'s forms are conserved by its flow, $|L_i\mathbb B(y)\alpha| \le
      10^3\varepsilon\,|L_i||\mathbb B(y)||\alpha|$ with $\alpha = L^\top\partial_s\varphi$
      (forms that Poisson-commute, or a function of the Casimirs); otherwise its frozen test
      flow is not its exact flow and a Strang splitting drops to order 1;
    - every other piece's flow conserves its own value over $t = 0.1$ to $10^3\varepsilon$
      (a necessary condition of an exact Hamiltonian flow).
    """
    try:
        terms = tuple(terms)
    except TypeError as err:
        raise TypeError(f"{where} must be a sequence of exact pieces; got {terms!r}") from err
    if not terms:
        raise TypeError(f"{where} must be a non-empty sequence of exact pieces; got {terms!r}")
    for k, t in enumerate(terms):
        if not isinstance(t, AbstractExactTerm):
            raise TypeError(
                f"{where}[{k}] must be an exact piece (CollectiveTerm, FreeRigidBodyTerm or your own "
                f"AbstractExactTerm); got {type(t).__name__}: {t!r:.80}"
            )
    y = np.random.default_rng(0).normal(size=(16, system.dim))
    H = np.asarray(system.hamiltonian(y))
    parts = np.stack([np.asarray(t.value(system, y)) for t in terms])
    diff = H - parts.sum(axis=0)
    diff = diff - diff[0]  # a constant offset does not change the flow
    scale = np.abs(H).max() + np.abs(parts).sum(axis=0).max()
    if not np.all(np.abs(diff) <= 1e3 * _EPS * scale):
        k = int(np.argmax(np.abs(diff)))
        raise ValueError(
            f"{where} must sum to the Hamiltonian of {system!r}; at y = {y[k].round(3).tolist()} "
            f"H - sum({where}) differs from its value at another point by {diff[k]:.3g} "
            f"(pieces: {[t.name or repr(t) for t in terms]})"
        )
    B = np.asarray(system.poisson_tensor(y))
    for k, t in enumerate(terms):
        if isinstance(t, CollectiveTerm):
            L = t.forms
            if L.shape[1] != system.dim:
                raise ValueError(
                    f"{where}[{k}]: {_label(k, t)} has forms of shape {L.shape}; expected (m, {system.dim})"
                )
            # The flow of phi(L y) moves L y at the rate L B(y) alpha, alpha = L^T dphi: the
            # frozen test flow is exact iff that vanishes (forms that Poisson-commute, or a
            # function of the Casimirs, B alpha = 0).
            alpha = np.asarray(t.frozen_alpha(system, jnp.asarray(y)))
            rate = np.einsum("id,nde,ne->ni", L, B, alpha)
            bound = (1e3 * _EPS * np.linalg.norm(L, axis=1)[None, :] * np.linalg.norm(B, axis=(1, 2))[:, None]
                     * np.linalg.norm(alpha, axis=1)[:, None])
            bad = np.argwhere(np.abs(rate) > bound)
            if len(bad):
                n, i = (int(v) for v in bad[0])
                raise ValueError(
                    f"{where}[{k}]: the linear forms of {_label(k, t)} do not Poisson-commute "
                    f"(d/dt <L_{i}, y> = {rate[n, i]:.3g} along its flow at y = {y[n].round(3).tolist()}), "
                    "so its frozen test flow is not its exact flow; split it into pieces whose forms "
                    "commute (e.g. one form per piece)"
                )
        else:
            z = np.asarray(t.flow(system, 0.1, y))
            v0, v1 = np.asarray(t.value(system, y)), np.asarray(t.value(system, z))
            if not np.all(np.abs(v1 - v0) <= 1e3 * _EPS * (np.abs(v0).max() + 1.0)):
                n = int(np.argmax(np.abs(v1 - v0)))
                raise ValueError(
                    f"{where}[{k}]: the flow of {_label(k, t)} does not conserve its own value "
                    f"(changed by {v1[n] - v0[n]:.3g} over t = 0.1 at y = {y[n].round(3).tolist()}), "
                    "so it is not the exact flow of that piece"
                )
    return terms

