r"""Reversing symmetries: sign flips $R = \mathrm{diag}(r)$, $r\in\{\pm1\}^n$, with

- $\mathbb B(Ry) = -R\,\mathbb B(y)\,R$ (an anti-Poisson map),
- $H(Ry) = H(y)$ and $C(Ry) = C(y)$ for every Casimir $C$ (it maps each symplectic leaf to
  itself),

so that the flow is $R$-reversible, $R\circ\varphi_t\circ R = \varphi_{-t}$. The free rigid
body has three (flip one component of $\Pi$); $R = -\mathrm{id}$ is anti-Poisson for every
Lie-Poisson bracket but maps a leaf of so(3)* to itself with no fixed point, which gives a
reversible map no hold on its dynamics, so it is not one of them: the fixed set of $R$ must meet
a generic leaf in half its dimension, i.e. $R$ flips exactly half the rank of $\mathbb B$.

Sign symmetries (`sign_symmetries`): sign flips $S$ that are Poisson maps with $H\circ S = H$,
so that $S\circ\varphi_t = \varphi_t\circ S$; the product of two reversing symmetries is one.
A reversible map has no secular energy drift on the orbits that meet the fixed set of its $R$;
which orbits those are depends on $R$ (on the rigid body, an orbit circling the axis of the
flipped component never meets it), and a map that also commutes with the sign symmetries is
reversible under every $RS$ at once (an LPNet with a `learn.GroupAveraged` network).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from ._base import AbstractPoissonSystem

_EPS = np.finfo(np.float64).eps
_MAX_CANDIDATES = 20_000
_MAX_SIGN_DIM = 12  # 4095 candidate flips, probed at 8 states: arrays of a few MB


def _probes(system: AbstractPoissonSystem, n: int = 8) -> np.ndarray:
    """`n` seeded random regular states of `system` (standard normal components)."""
    y = np.random.default_rng(0).normal(size=(4 * n, system.dim))
    bad = system.singular(y)
    if bad is not None:
        y = y[~np.asarray(bad)]
    return y[:n]


def _rank(system: AbstractPoissonSystem, y: np.ndarray) -> int:
    """The generic rank of $\\mathbb B$: its largest numerical rank at the probe points."""
    return int(np.linalg.matrix_rank(np.asarray(system.poisson_tensor(y))).max())


def _violations(system: AbstractPoissonSystem, signs: np.ndarray, y: np.ndarray, reversing: bool = True) -> list[str]:
    """What keeps each sign vector of `signs` `(k, dim)` from being a reversing symmetry (with
    `reversing=False`: a symmetry, `sign_symmetries`) at the probe points `y`: one message per
    candidate, empty where it is one. Tolerances are $10^3\\varepsilon$ relative to the sizes
    of the values: a sign flip changes only the order of a few dozen roundings."""
    n = len(signs)
    Ry = signs[:, None, :] * y[None]  # (k, p, dim)
    B, BR = np.asarray(system.poisson_tensor(y)), np.asarray(system.poisson_tensor(Ry))
    flipped = signs[:, None, :, None] * B[None] * signs[:, None, None, :]
    sign = 1.0 if reversing else -1.0
    poisson = np.abs(BR + sign * flipped).max(axis=(1, 2, 3)) <= 1e3 * _EPS * max(np.abs(B).max(), 1.0)
    H, HR = np.asarray(system.hamiltonian(y)), np.asarray(system.hamiltonian(Ry))
    energy = np.abs(HR - H[None]).max(axis=1) <= 1e3 * _EPS * max(np.abs(H).max(), 1.0)
    if reversing:
        C, CR = np.asarray(system.casimirs(y)), np.asarray(system.casimirs(Ry))
        leaves = (np.abs(CR - C[None]).max(axis=(1, 2), initial=0.0)
                  <= 1e3 * _EPS * max(np.abs(C).max(initial=0.0), 1.0))
    else:
        leaves = np.ones(n, bool)  # a symmetry may carry a leaf to another one
    bracket = "it is not anti-Poisson, B(Ry) != -R B(y) R" if reversing else "it is not Poisson, B(Sy) != S B(y) S"
    image = "Ry" if reversing else "Sy"
    out = []
    for i in range(n):
        why = [text for ok, text in ((poisson[i], bracket),
                                     (energy[i], f"H({image}) != H(y)"),
                                     (leaves[i], "it changes a Casimir, C(Ry) != C(y)")) if not ok]
        out.append("; ".join(why))
    return out


def reversing_symmetries(system: AbstractPoissonSystem) -> list[np.ndarray]:
    r"""Every sign flip $R = \mathrm{diag}(r)$ that is a reversing symmetry of `system` (module
    docstring), as sign vectors `r` of shape `(dim,)`, in lexicographic order of the flipped
    components; checked at 8 seeded random states. Empty when there is none (e.g. a
    Hamiltonian with a term odd in every admissible flip)."""
    y = _probes(system)
    k = _rank(system, y) // 2
    if k == 0:
        return []
    if math.comb(system.dim, k) > _MAX_CANDIDATES:
        raise ValueError(
            f"{system!r} has {math.comb(system.dim, k)} candidate sign flips (dimension {system.dim}, "
            f"{k} flipped components); too many to search: pass the signs yourself "
            "(check_reversing_symmetry checks them)"
        )
    flips = list(itertools.combinations(range(system.dim), k))
    signs = np.ones((len(flips), system.dim))
    for i, f in enumerate(flips):
        signs[i, list(f)] = -1.0
    return [s for s, why in zip(signs, _violations(system, signs, y)) if not why]


def sign_symmetries(system: AbstractPoissonSystem) -> list[np.ndarray]:
    r"""Every sign flip $S = \mathrm{diag}(s) \ne \mathrm{id}$ that is a symmetry of `system`:
    a Poisson map, $\mathbb B(Sy) = S\,\mathbb B(y)\,S$, with $H(Sy) = H(y)$, so that the
    flow commutes with it, $S\circ\varphi_t = \varphi_t\circ S$ (checked at 8 seeded
    random states). With the identity they form a group; the product of two reversing
    symmetries is one of them. The free rigid body has three (the half-turns about its axes,
    flipping two components of $\Pi$). Sign vectors `(dim,)`, ordered by the number of
    flipped components, then lexicographically; empty when there is none. All $2^n - 1$ flips
    are tried, so `dim` is at most 12."""
    if system.dim > _MAX_SIGN_DIM:
        raise ValueError(
            f"{system!r} has 2^{system.dim} candidate sign flips; too many to search (dimension at most "
            f"{_MAX_SIGN_DIM}): pass the symmetries you know, e.g. learn.GroupAveraged(network, [s1, s2]) in an "
            "LPNet, which checks them (check_sign_symmetry)"
        )
    y = _probes(system)
    flips = [f for k in range(1, system.dim + 1) for f in itertools.combinations(range(system.dim), k)]
    signs = np.ones((len(flips), system.dim))
    for i, f in enumerate(flips):
        signs[i, list(f)] = -1.0
    return [s for s, why in zip(signs, _violations(system, signs, y, reversing=False)) if not why]


def _sign_vector(system: AbstractPoissonSystem, signs: Any, name: str) -> np.ndarray:
    """`signs` as a float vector of +1/-1 of length `system.dim`, or `TypeError`/`ValueError`
    naming `name`."""
    try:
        r = np.asarray(signs, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a vector of +1/-1 of length {system.dim}; got {signs!r}") from err
    if r.shape != (system.dim,) or not np.all(np.abs(r) == 1.0):
        raise ValueError(f"{name} must be a vector of +1/-1 of length {system.dim}; got {np.asarray(signs).tolist()}")
    return r


def check_sign_symmetry(system: AbstractPoissonSystem, signs: Any, name: str = "symmetry") -> np.ndarray:
    """`signs` as a float sign vector `(dim,)` if $S = \\mathrm{diag}$(`signs`) is a symmetry
    of `system` (Poisson, $H\\circ S = H$; `sign_symmetries`) at 8 seeded random states, else
    `ValueError` saying which condition fails (`TypeError` for a non-numeric value)."""
    r = _sign_vector(system, signs, name)
    why = _violations(system, r[None], _probes(system), reversing=False)[0]
    if why:
        raise ValueError(f"{name} = {r.astype(int).tolist()} is not a symmetry of {system!r}: {why}")
    return r


def reversing_symmetry(system: AbstractPoissonSystem) -> np.ndarray:
    """The first of `reversing_symmetries(system)`; `ValueError` when there is none."""
    found = reversing_symmetries(system)
    if not found:
        raise ValueError(
            f"{system!r} has no reversing symmetry that flips signs of components (a sign flip R "
            "with B(Ry) = -R B(y) R, H(Ry) = H(y), C(Ry) = C(y), flipping half the rank of B); "
            "use a map without one (e.g. learn.LPNet(system), not wrapped in learn.Reversible)"
        )
    return found[0]


def check_reversing_symmetry(system: AbstractPoissonSystem, signs: Any, name: str = "reversing") -> np.ndarray:
    """`signs` as a float sign vector `(dim,)` if $R = \\mathrm{diag}$(`signs`) is a reversing
    symmetry of `system` at 8 seeded random states (module docstring), else `ValueError`
    saying which condition fails (`TypeError` for a non-numeric value)."""
    r = _sign_vector(system, signs, name)
    y = _probes(system)
    why = _violations(system, r[None], y)[0]
    if why:
        raise ValueError(f"{name} = {r.astype(int).tolist()} is not a reversing symmetry of {system!r}: {why}")
    k, flipped = _rank(system, y) // 2, int(np.sum(r < 0))
    if flipped != k:
        raise ValueError(
            f"{name} = {r.astype(int).tolist()} flips {flipped} components; a reversing symmetry whose "
            f"fixed set meets a leaf in half its dimension flips {k} (half the rank of B) here"
        )
    return r
