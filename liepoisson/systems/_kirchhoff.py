"""Kirchhoff's equations of an underwater vehicle on se(3)*."""

from __future__ import annotations

import numpy as np

from .._catalogue import se3
from .._validation import positive_vector
from ._base import AbstractDefinedByParams, AbstractLiePoissonSystem
from ._rigid_body import _axis_term
from ._terms import CollectiveTerm


class Kirchhoff(AbstractLiePoissonSystem, AbstractDefinedByParams):
    r"""Neutrally buoyant body (centres of gravity and buoyancy coincide):
    $H = \tfrac12\Pi\cdot\mathbb{I}^{-1}\Pi + \tfrac12 p\cdot\mathbb{M}^{-1}p$ on se(3)*,
    $\dot\Pi = \Pi\times\Omega + p\times v$, $\dot p = p\times\Omega$
    ($\Omega = \mathbb{I}^{-1}\Pi$, $v = \mathbb{M}^{-1}p$). Casimirs $|p|^2$, $\Pi\cdot p$.

    **Arguments:** `inertia` and `mass`, principal values (paper: both diag(1, 2, 1)).
    """

    name = "Kirchhoff"

    def __init__(self, inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0)):
        self.inertia = positive_vector(inertia, "inertia", 3)
        self.mass = positive_vector(mass, "mass", 3)
        self.algebra = se3()

    @property
    def params(self):
        return {"inertia": self.inertia.tolist(), "mass": self.mass.tolist()}

    def hamiltonian_components(self, y, xp):
        I, M = (float(v) for v in self.inertia), (float(v) for v in self.mass)
        rot = sum(y[i] ** 2 / Ii for i, Ii in enumerate(I))
        tra = sum(y[3 + i] ** 2 / Mi for i, Mi in enumerate(M))
        return 0.5 * (rot + tra)

    def hamiltonian_splitting(self):
        r"""$T_i = \Pi_i^2/(2I_i)$ (rotations about $e_i$) and the translational energy
        $\sum_i p_i^2/(2m_i)$ (one exact shear $\Pi \mapsto \Pi - t\,v\times p$; the $p_i$ commute)."""
        rot = tuple(_axis_term(i, 1.0 / self.inertia[i], 6, f"T{i + 1}") for i in range(3))
        forms = np.zeros((3, 6))
        forms[:, 3:] = np.eye(3)
        m = tuple(float(v) for v in self.mass)
        kin = CollectiveTerm(
            forms, lambda s: 0.5 * (s[0] ** 2 / m[0] + s[1] ** 2 / m[1] + s[2] ** 2 / m[2]), "P"
        )
        return rot + (kin,)
