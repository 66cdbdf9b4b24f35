"""The heavy top on se(3)* (angular momentum and the direction of gravity)."""

from __future__ import annotations

import numpy as np

from .._catalogue import se3
from .._validation import finite_vector, positive_float, positive_vector
from ._base import AbstractDefinedByParams, AbstractLiePoissonSystem
from ._rigid_body import _axis_term
from ._terms import CollectiveTerm


class HeavyTop(AbstractLiePoissonSystem, AbstractDefinedByParams):
    r"""Heavy top, $y = (\Pi, \Gamma)$ with $\Gamma$ the vertical in the body frame:
    $H = \tfrac12\Pi\cdot\mathbb{I}^{-1}\Pi + mgl\,\chi\cdot\Gamma$,
    $\dot\Pi = \Pi\times\Omega + mgl\,\Gamma\times\chi$, $\dot\Gamma = \Gamma\times\Omega$.
    Casimirs $|\Gamma|^2$ and $\Pi\cdot\Gamma$.

    **Arguments:** `inertia`; `mgl`, weight times the distance of the centre of mass from the
    fixed point; `center_of_mass`, the unit direction $\chi$ in the body (default $e_3$).
    """

    name = "HeavyTop"

    @property
    def group(self):
        r"""`None`: the top's configuration is a rotation $R$ with $\Gamma = R^\top e_3$ (a
        semidirect product reduced by the symmetry about the vertical), not the pose of se(3)
        that its algebra's default would give; its reconstruction is not implemented."""
        return None

    def __init__(self, inertia=(1.0, 2.0, 3.0), mgl=1.0, center_of_mass=(0.0, 0.0, 1.0)):
        self.inertia = positive_vector(inertia, "inertia", 3)
        self.mgl = positive_float(mgl, "mgl")
        chi = finite_vector(center_of_mass, "center_of_mass", 3)
        if np.linalg.norm(chi) == 0.0:
            raise ValueError("center_of_mass must be a non-zero direction; got (0, 0, 0)")
        self.center_of_mass = chi / np.linalg.norm(chi)
        self.algebra = se3()

    @property
    def params(self):
        return {
            "inertia": self.inertia.tolist(),
            "mgl": self.mgl,
            "center_of_mass": self.center_of_mass.tolist(),
        }

    @property
    def state_names(self):
        return ("Pi1", "Pi2", "Pi3", "Gamma1", "Gamma2", "Gamma3")

    def hamiltonian_components(self, y, xp):
        rot = sum(y[i] ** 2 / float(Ii) for i, Ii in enumerate(self.inertia))
        pot = sum(self.mgl * float(c) * y[3 + i] for i, c in enumerate(self.center_of_mass) if c != 0)
        return 0.5 * rot + pot

    def hamiltonian_splitting(self):
        r"""$T_i = \Pi_i^2/(2I_i)$ and the potential $mgl\,\chi\cdot\Gamma$ (a linear test
        Hamiltonian: $\Pi \mapsto \Pi - t\,mgl\,\chi\times\Gamma$)."""
        rot = tuple(_axis_term(i, 1.0 / self.inertia[i], 6, f"T{i + 1}") for i in range(3))
        form = np.zeros(6)
        form[3:] = self.mgl * self.center_of_mass
        return rot + (CollectiveTerm(form, lambda s: s[0], "V"),)
