r"""An LPNet that learns from what instruments record of a body (gyroscope rates, attitudes):
the momenta latent, read out as body velocities by a learned linear map."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators.internals import check_h, check_state

from ._base import AbstractBodyMap, AbstractCasimirConservingMap
from ._lpnet import LPNet
from ._mlp import AffineMLP
from ._plus_affine import PlusAffine


class BodyLPNet(AbstractBodyMap, AbstractCasimirConservingMap):
    r"""An LPNet step $\mu_{n+1} = \exp(h\,\alpha(\mu_n))\cdot\mu_n$ on latent momenta, with the
    body velocity read out linearly, $\xi = K\mu$ ($K$ learned, symmetric: the inverse inertia
    up to the scale the data fix), so that it can be fitted on gyroscope rates and attitudes
    (`learn.BodyLoss`) like a G-LPNet. Every step keeps the Casimirs of the latent momenta (a
    coadjoint motion), but an LPNet has no Hamiltonian: its energy is not kept, and nothing
    ties $\alpha$ to $K$ but the fit.

    The configuration moves with the read-out velocity at the step's midpoint,
    $g_{n+1} = g_n\exp(h\,K(\mu_n + \mu_{n+1})/2)$ (second order; what a gyroscope integrates).

    **Arguments:** `lpnet`, a `learn.LPNet` (its parametrisation the test flow); `readout`,
    $K$ `(dim, dim)` (default the identity). `BodyLPNet.at_quadratic(system, A, b)` builds one
    at a quadratic $\tfrac12\mu^\top A\mu + b^\top\mu$ (e.g. `learn.weak_form_quadratic(data)`'s,
    the least squares of body observations): $K = A$ and $\alpha(\mu) = A\mu + b$ plus a
    network that starts at zero, the Lie-Euler step of that quadratic.
    """

    lpnet: LPNet
    readout: jax.Array

    def __init__(self, lpnet: LPNet, readout: Any = None):
        if not isinstance(lpnet, LPNet):
            raise TypeError(f"lpnet must be a learn.LPNet; got {type(lpnet).__name__}")
        dim = lpnet.system.dim
        K = np.eye(dim) if readout is None else np.asarray(readout, dtype=np.float64)
        if K.shape != (dim, dim) or not np.all(np.isfinite(K)):
            raise ValueError(f"readout must be a finite ({dim}, {dim}) matrix; got shape {K.shape}")
        self.lpnet = lpnet
        self.readout = jnp.asarray(0.5 * (K + K.T))

    @classmethod
    def at_quadratic(cls, system, A: Any, b: Any, *, hidden=(16, 16), activation: str = "tanh",
                     key: int = 0, h: float | None = None) -> BodyLPNet:
        """A `BodyLPNet` at the quadratic $(A, b)$ (see the class)."""
        A = np.asarray(A, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64)
        if A.shape != (system.dim, system.dim) or b.shape != (system.dim,):
            raise ValueError(f"A must have shape ({system.dim}, {system.dim}) and b ({system.dim},); got {A.shape} "
                             f"and {b.shape}")
        network = PlusAffine(AffineMLP(system.dim, system.dim, hidden, activation, key=key, init="zero"),
                             shift=b, linear=A)
        return cls(LPNet(system, network=network, h=h), A)

    @property
    def system(self):
        return self.lpnet.system

    @property
    def h(self) -> float | None:
        return self.lpnet.h

    def body_velocity(self, y: jax.Array) -> jax.Array:
        r"""$\xi = K\mu$, what a gyroscope reads ($K$ the symmetric part of `readout`)."""
        return 0.5 * (self.readout + self.readout.T) @ y

    def step(self, y: jax.Array) -> jax.Array:
        return self.lpnet.step(y)

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        group = self.system.require_group()
        y = check_state(y, self.system.dim)
        y1 = self.lpnet.step(y)
        velocity = 0.5 * (self.body_velocity(y) + self.body_velocity(y1))
        return group.right_exp(group.check(g, "g"), check_h(self) * velocity), y1

    @property
    def exact_flows_per_step(self) -> int:
        return self.lpnet.exact_flows_per_step

    def hyperparameters(self) -> dict[str, Any]:
        return {"lpnet": self.lpnet.hyperparameters()}

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.lpnet, self, self.lpnet.reinitialised(key))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        return cls(LPNet.from_hyperparameters(system, hyperparameters["lpnet"], key=key, h=h))

    def default_optimiser(self):
        from .._solvers._levenberg_marquardt import LevenbergMarquardt
        from .._solvers._stage import KeepIfBetter

        return (KeepIfBetter(LevenbergMarquardt(200)),)
