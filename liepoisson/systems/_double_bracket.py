r"""Double-bracket dissipation of a Lie-Poisson system (Bloch, Krishnaprasad, Marsden & Ratiu,
*The Euler-Poincaré equations and double bracket dissipation*, Comm. Math. Phys. 175 (1996)):
the motion stays on the coadjoint orbit, every Casimir is conserved, the energy decays."""

from __future__ import annotations

import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._namespace import HEYOKA
from ._base import (
    AbstractDissipativeSystem,
    AbstractLiePoissonSystem,
    AbstractPoissonSystem,
    matvec,
)
from ._wrapped import AbstractWrappedSystem

#: Relative asymmetry of a metric accepted as symmetric (a matrix typed or computed in
#: float64 is symmetric to a few roundings of its largest entry).
_SYMMETRY_RTOL = 1e-12


def check_gamma(gamma: Any, name: str = "gamma") -> float:
    """A finite dissipation strength >= 0 (0: the undamped system); a Python, numpy or JAX
    scalar."""
    if isinstance(gamma, (bool, str, bytes)) or not (
        isinstance(gamma, numbers.Real) or getattr(gamma, "ndim", None) == 0
    ):
        raise TypeError(f"{name} must be a real number >= 0; got {type(gamma).__name__} {gamma!r}")
    if np.iscomplexobj(gamma):
        raise TypeError(f"{name} must be a real number >= 0, not complex; got {type(gamma).__name__} {gamma!r}")
    try:
        value = float(gamma)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real number >= 0; got {type(gamma).__name__} {gamma!r}") from None
    if not np.isfinite(value) or value < 0.0:
        raise ValueError(
            f"{name} must be finite and >= 0 (the dissipation strength; 0 is the undamped system); got {value!r}"
        )
    return value


def check_metric(metric: Any, dim: int, name: str = "metric") -> np.ndarray:
    r"""`metric` as a symmetric positive definite `(dim, dim)` float64 matrix $K$ (identifying
    $\mathfrak g^*$ with $\mathfrak g$); the identity for None."""
    if metric is None:
        return np.eye(dim)
    try:
        K = np.asarray(metric)
    except (TypeError, ValueError) as err:  # ragged lists
        raise TypeError(f"{name} must be a ({dim}, {dim}) real matrix; got {metric!r}") from err
    if np.iscomplexobj(K):
        raise TypeError(f"{name} must be a ({dim}, {dim}) real matrix, not complex; got {K.dtype}")
    try:
        K = K.astype(np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a ({dim}, {dim}) real matrix; got {metric!r}") from err
    if K.shape != (dim, dim):
        raise ValueError(f"{name} must have shape ({dim}, {dim}) (the algebra's dimension); got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError(f"{name} must be finite; got {K.tolist()}")
    asymmetry = float(np.max(np.abs(K - K.T)))
    if asymmetry > _SYMMETRY_RTOL * max(float(np.max(np.abs(K))), np.finfo(float).tiny):
        raise ValueError(f"{name} must be symmetric; max |K - K^T| = {asymmetry:.3g}")
    try:
        np.linalg.cholesky(K)
    except np.linalg.LinAlgError:
        low = float(np.linalg.eigvalsh(K)[0])
        raise ValueError(
            f"{name} must be positive definite (a metric); its smallest eigenvalue is {low:.3g}"
        ) from None
    return 0.5 * (K + K.T)


class DoubleBracket(AbstractWrappedSystem, AbstractDissipativeSystem):
    r"""A Lie-Poisson system with double-bracket dissipation:

    $$\dot\mu = \mathbb B(\mu)\nabla H(\mu) + \gamma\,\mathbb B(\mu)\,K\,\mathbb B(\mu)\nabla H(\mu)
    = \mathbb B(\mu)\,\xi(\mu), \qquad \xi(\mu) = \nabla H + \gamma K\,\mathbb B(\mu)\nabla H,$$

    $K$ a symmetric positive definite metric identifying $\mathfrak g^*$ with $\mathfrak g$
    (default: the basis's, $K = I$). For the rigid body with $K = I$:
    $\dot\Pi = \Pi\times\Omega + \gamma\,\Pi\times(\Pi\times\Omega)$.

    The velocity is $\mathbb B(\mu)\,\xi$, a coadjoint motion with the state-dependent generator
    $\xi(\mu)$ (`generator`), so every Casimir is conserved ($\nabla C^\top\mathbb B = 0$); the
    energy decays, $\dot H = -\gamma\,(\mathbb B\nabla H)^\top K\,(\mathbb B\nabla H) \le 0$
    (`energy_rate`), toward the relative equilibria on the orbit (generically a local minimum
of $H$ there). The flow is not Poisson: no
    Hamiltonian splitting (`hamiltonian_splitting` raises), no G-LPNet can follow it; the
    Lie-group methods of `integrators` (`LieEuler`, `CommutatorFree2`, `CommutatorFree4`,
    `DampedSplitting`) and LPNets keep its Casimirs.

    **Arguments:** `system`, a Lie-Poisson system (`RigidBody`, `HeavyTop`, `Kirchhoff` or a
    `LiePoissonSystem`); `gamma` >= 0, the dissipation strength; `metric`, $K$ as a
    `(dim, dim)` matrix (default the identity).
    """

    name = "DoubleBracket"

    def __init__(self, system: AbstractLiePoissonSystem, gamma: float, metric: ArrayLike | None = None):
        if isinstance(system, DoubleBracket):
            raise TypeError(
                f"system is already damped ({system!r}); give the undamped system "
                f"(system.system) with the total dissipation instead"
            )
        if not isinstance(system, AbstractLiePoissonSystem):
            kind = "a Poisson system not on the dual of a Lie algebra" if isinstance(
                system, AbstractPoissonSystem) else "not a liepoisson system"
            raise TypeError(
                f"system must be a Lie-Poisson system (RigidBody, HeavyTop, Kirchhoff or a LiePoissonSystem "
                f"on any algebra): double-bracket dissipation needs the coadjoint action; got "
                f"{type(system).__name__}, {kind}"
            )
        self.system = system
        self.algebra = system.algebra
        self.gamma = check_gamma(gamma)
        self.metric = check_metric(metric, system.dim)
        self._identity = bool(np.array_equal(self.metric, np.eye(system.dim)))  # None and I are one system

    @property
    def conservative(self) -> AbstractLiePoissonSystem:
        """The undamped system, `system`."""
        return self.system


    def __repr__(self) -> str:
        metric = "" if self._identity else f", metric={self.metric.tolist()}"
        return f"DoubleBracket({self.system!r}, gamma={self.gamma!r}{metric})"

    def own_params(self) -> dict[str, Any]:
        return {"gamma": self.gamma, "metric": None if self._identity else self.metric.tolist()}

    @classmethod
    def from_own_params(cls, system, params) -> DoubleBracket:
        return cls(system, params["gamma"], params.get("metric"))

    def hamiltonian_splitting(self):
        raise ValueError(
            f"{self!r} is dissipative: its flow is not a composition of Hamiltonian flows, so the "
            "splitting methods of integrators.splitting cannot integrate it. Use "
            "integrators.DampedSplitting (the Hamiltonian part split exactly, the dissipation by a "
            "Lie-group method) or integrators.LieEuler / CommutatorFree2 / CommutatorFree4"
        )

    # -- the dissipation ----------------------------------------------------------------
    def dissipative_generator(self, y: ArrayLike) -> jax.Array:
        r"""$\gamma K\,\mathbb B(\mu)\nabla H(\mu)$: the dissipation is $\mathbb B(\mu)$ times it."""
        v = self.system.vector_field(y)  # B grad H, the undamped velocity
        return self.gamma * jnp.einsum("ab,...b->...a", jnp.asarray(self.metric), v)

    def dissipation(self, y: ArrayLike) -> jax.Array:
        r"""$\gamma\,\mathbb B(\mu)\,K\,\mathbb B(\mu)\nabla H(\mu)$, the dissipative part of the velocity."""
        y = self.check_regular(y)
        return jnp.einsum("...ab,...b->...a", self.poisson_tensor(y), self.dissipative_generator(y))

    def generator(self, y: ArrayLike) -> jax.Array:
        r"""$\xi(\mu) = \nabla H + \gamma K\,\mathbb B(\mu)\nabla H$, with $\dot\mu = \mathbb B(\mu)\,\xi(\mu)$."""
        y = self.check_regular(y)
        return self.hamiltonian_gradient(y) + self.dissipative_generator(y)

    def energy_rate(self, y: ArrayLike) -> jax.Array:
        r"""$\dot H = -\gamma\,(\mathbb B\nabla H)^\top K\,(\mathbb B\nabla H) \le 0$, shape `(...)`."""
        v = self.system.vector_field(y)  # B grad H
        return -self.gamma * jnp.einsum("...a,ab,...b->...", v, jnp.asarray(self.metric), v)

    def heyoka_system(self) -> list[tuple[Any, Any]]:
        r"""$\mathbb B(\nabla H + \gamma K\,\mathbb B\nabla H)$ as heyoka expressions,
        from the same Hamiltonian and Poisson tensor."""
        pairs = self.system.heyoka_system()
        ys = [v for v, _ in pairs]
        hamiltonian_velocity = [rhs for _, rhs in pairs]  # B grad H
        import heyoka as hy

        grad = [hy.diff(self.hamiltonian_components(ys, HEYOKA), v) for v in ys]
        K = self.metric
        xi = [grad[a] + self.gamma * sum((float(K[a, b]) * hamiltonian_velocity[b] for b in range(self.dim)
                                          if K[a, b] != 0.0), hy.expression(0.0))
              for a in range(self.dim)]
        return list(zip(ys, matvec(self.poisson_tensor_components(ys), xi)))


def damped_rigid_body(inertia=(2.0, 1.0, 2.0 / 3.0), gamma: float = 0.05) -> DoubleBracket:
    r"""The rigid body with a nutation damper, $\dot\Pi = \Pi\times\Omega + \gamma\,\Pi\times(\Pi\times\Omega)$
    (`DoubleBracket(RigidBody(inertia), gamma)`): from a spin about the minor axis (smallest
    moment, the default $I_3 = 2/3$), the energy decays at fixed $|\Pi|$ until it spins about
    the major axis (largest moment), as Explorer 1 did in 1958."""
    from ._rigid_body import RigidBody

    return DoubleBracket(RigidBody(inertia), gamma)


def damped_heavy_top(inertia=(1.0, 1.5, 2.5), mgl: float = 0.7, center_of_mass=(0.0, 0.0, 1.0),
                     gamma: float = 0.05) -> DoubleBracket:
    r"""The heavy top with double-bracket dissipation on se(3)* (`DoubleBracket(HeavyTop(...),
    gamma)`): $\Gamma\cdot\Gamma$ and $\Pi\cdot\Gamma$ are kept while the energy decays."""
    from ._heavy_top import HeavyTop

    return DoubleBracket(HeavyTop(inertia=inertia, mgl=mgl, center_of_mass=center_of_mass), gamma)
