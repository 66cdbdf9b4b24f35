r"""The exact flow of the free rigid body, $\dot\Pi = \Pi\times\mathbb I^{-1}\Pi$, by Jacobi
elliptic functions, and the piece of a splitting that uses it.

Derivation (checked against heyoka in the tests, not copied from a table: published tables of
this solution carry sign and modulus errata). In a frame where the moments are monotone,
$I_1 < I_2 < I_3$ or $I_1 > I_2 > I_3$, and $\Pi$ turns about axis 3 ($\Pi_3$ never vanishes),
with $M^2 = |\Pi|^2$, $2H = \sum_i \Pi_i^2/I_i$,
$P = 2HI_3 - M^2 = \sum_i \Pi_i^2 (I_3/I_i - 1)$, $Q = M^2 - 2HI_1 = \sum_i \Pi_i^2(1 - I_1/I_i)$
(sums of terms of one sign: no cancellation),

$$\Pi_1 = A_1\operatorname{cn}u,\quad \Pi_2 = s A_2\operatorname{sn}u,\quad
\Pi_3 = s A_3\operatorname{dn}u,\quad u = u_0 + \epsilon\,\omega t,$$

$A_1^2 = I_1P/(I_3 - I_1)$, $A_2^2 = I_2P/(I_3 - I_2)$, $A_3^2 = I_3Q/(I_3 - I_1)$,
$\omega^2 = (I_3 - I_2)Q/(I_1I_2I_3)$, $m = k^2 = (I_2 - I_1)P/((I_3 - I_2)Q)$,
$1 - m = (I_3 - I_1)(M^2 - 2HI_2)/((I_3 - I_2)Q)$ (kept separately: near the separatrix
$m$ rounds to 1 while $1 - m$ still sets the period), $s = \operatorname{sign}\Pi_3$, $\epsilon = \operatorname{sign}(I_3 - I_2)$. Substituting into
Euler's equations with $\operatorname{sn}' = \operatorname{cn}\operatorname{dn}$ etc. reduces
each to one of $A_1^2 + A_3^2 = M^2$, $A_2^2 - A_1^2 = mA_3^2$, $\epsilon\omega A_1 = A_2A_3
(I_3 - I_2)/(I_2I_3)$ (and cyclic), which hold identically.

The initial phase never needs an inverse elliptic integral: $(\operatorname{sn}u_0,
\operatorname{cn}u_0, \operatorname{dn}u_0)$ are read off $\Pi(0)$ and advanced by the
addition theorem (A&S 16.17; its denominator $1 - m\operatorname{sn}^2u_0\operatorname{sn}^2v$
written as $\operatorname{cn}^2u_0 + \operatorname{sn}^2u_0\operatorname{dn}^2v$, a sum of squares) with $(\operatorname{sn}, \operatorname{cn}, \operatorname{dn})
(\epsilon\omega t)$.

The frame: a signed permutation $R\in SO(3)$ sorts the moments ($R$ commutes with the cross
product, so $R\Pi$ solves Euler's equations with the permuted moments); if $\Pi$ turns about
the axis of smallest moment ($M^2 < 2HI_2$), $(\Pi_1, \Pi_2, \Pi_3)\mapsto(\Pi_3, -\Pi_2,
\Pi_1)$ (also in $SO(3)$) makes it axis 3 with $I_1 > I_2 > I_3$. Symmetric bodies
($I_1 = I_2$ or $I_2 = I_3$) take the case whose formulas stay finite ($m = 0$: a
rotation), and a spherical body does not move.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from .._elliptic import ellipj
from .._validation import as_scalar_time, as_state, positive_vector
from ._base import AbstractPoissonSystem
from ._terms import AbstractExactTerm

_SWAP = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])  # in SO(3)


def _sorting_rotation(inertia: np.ndarray) -> np.ndarray:
    """A signed permutation R in SO(3) with R diag(I) R^T = diag(sorted I)."""
    order = np.argsort(inertia, kind="stable")
    R = np.eye(3)[order]
    if np.linalg.det(R) < 0:  # odd permutation: flip one axis to stay in SO(3)
        R[0] = -R[0]
    return R


def _ratio(num: jax.Array, den: jax.Array) -> jax.Array:
    """num / den, and 0 where den == 0 (the limits used below are all 0 there)."""
    safe = jnp.where(den == 0.0, 1.0, den)
    return jnp.where(den == 0.0, 0.0, num / safe)


def free_rigid_body_flow(inertia: ArrayLike, t: ArrayLike, y: ArrayLike) -> jax.Array:
    r"""$\Pi(t)$ of the free rigid body with principal moments `inertia` from $\Pi(0)$ = `y`
    (shape `(..., 3)`), exactly (to round-off), for any real `t`; traceable and batched.

    Conserves $|\Pi|^2$ and $H$ to round-off and is the time-$t$ map of
    $H = \tfrac12\Pi\cdot\mathbb I^{-1}\Pi$ on so(3)* (a Poisson map).
    """
    inertia = positive_vector(inertia, "inertia", 3)
    y = as_state(y, "y", 3)
    t = as_scalar_time(t)
    if np.all(inertia == inertia[0]):  # a spherical body: Omega is parallel to Pi
        return jnp.broadcast_to(y, jnp.broadcast_shapes(y.shape, t.shape + (3,)))
    R0 = _sorting_rotation(inertia)
    I = np.sort(inertia)
    # M^2 - 2H I_2 as a sum over components (no cancellation between M^2 and 2H I_2, which
    # would pick the wrong case next to the separatrix).
    D = jnp.sum(y * y * (1.0 - I[1] / inertia), axis=-1)
    if I[0] == I[1]:
        about_largest = jnp.ones_like(D, dtype=bool)
    elif I[1] == I[2]:
        about_largest = jnp.zeros_like(D, dtype=bool)
    else:
        about_largest = D >= 0.0
    R = jnp.where(about_largest[..., None, None], jnp.asarray(R0), jnp.asarray(_SWAP @ R0))
    J = jnp.where(
        about_largest[..., None], jnp.asarray(I), jnp.asarray(I[::-1])
    )  # moments in the frame
    x = jnp.einsum("...ij,...j->...i", R, y)
    J1, J2, J3 = J[..., 0], J[..., 1], J[..., 2]
    x2 = x * x
    P = jnp.sum(x2 * (J3[..., None] / J - 1.0), axis=-1)
    Q = jnp.sum(x2 * (1.0 - J1[..., None] / J), axis=-1)
    A1 = jnp.sqrt(jnp.maximum(_ratio(J1 * P, J3 - J1), 0.0))
    A2 = jnp.sqrt(jnp.maximum(_ratio(J2 * P, J3 - J2), 0.0))
    A3 = jnp.sqrt(jnp.maximum(_ratio(J3 * Q, J3 - J1), 0.0))
    omega = jnp.sqrt(jnp.maximum(_ratio((J3 - J2) * Q, J1 * J2 * J3), 0.0))
    m = jnp.clip(_ratio((J2 - J1) * P, (J3 - J2) * Q), 0.0, 1.0)
    # 1 - m = (J3 - J1)(M^2 - 2H J2) / ((J3 - J2) Q), accurate near the separatrix where m -> 1.
    mc = jnp.clip(_ratio((J3 - J1) * D, (J3 - J2) * Q), 0.0, 1.0)
    s = jnp.where(x[..., 2] >= 0.0, 1.0, -1.0)
    eps = jnp.sign(J3 - J2)
    # (cn u0, sn u0) is the unit vector along (x1/A1, s x2/A2) = (x1 A2, s x2 A1)/(A1 A2).
    cu, su = x[..., 0] * A2, s * x[..., 1] * A1
    norm = jnp.hypot(cu, su)
    c0 = jnp.where(norm > 0.0, cu / jnp.where(norm > 0.0, norm, 1.0), 1.0)
    s0 = jnp.where(norm > 0.0, su / jnp.where(norm > 0.0, norm, 1.0), 0.0)
    d0 = jnp.where(A3 > 0.0, jnp.abs(x[..., 2]) / jnp.where(A3 > 0.0, A3, 1.0), 1.0)
    s1, c1, d1 = ellipj(eps * omega * t, m, mc)
    den = c0 * c0 + (s0 * d1) ** 2  # = 1 - m sn^2 u0 sn^2 v without its cancellation near m = 1
    # den underflows to 0 only on a saddle (cn u0 = dn u0 = 0, m = 1) once sech(v)^2 < 1e-308:
    # there the state does not move.
    at_saddle = den == 0.0
    den = jnp.where(at_saddle, 1.0, den)
    sn = jnp.where(at_saddle, s0, (s0 * c1 * d1 + s1 * c0 * d0) / den)
    cn = jnp.where(at_saddle, c0, (c0 * c1 - s0 * s1 * d0 * d1) / den)
    # Back onto the invariant curve: sn^2 + cn^2 = 1, dn^2 = cn^2 + (1 - m) sn^2 (so |Pi|^2 and
    # H are kept to round-off even where cn, dn are tiny and known only to an absolute eps,
    # next to the saddles of the separatrix); dn > 0 for every m, so its addition formula is
    # not needed.
    r = jnp.hypot(sn, cn)
    sn, cn = sn / r, cn / r
    dn = jnp.sqrt(cn * cn + mc * sn * sn)
    x_t = jnp.stack([A1 * cn, s * A2 * sn, s * A3 * dn], axis=-1)
    return jnp.einsum("...ji,...j->...i", R, x_t)  # back: R^T x_t


class FreeRigidBodyTerm(AbstractExactTerm):
    r"""The piece $H_k = \tfrac12\Pi\cdot\mathbb I^{-1}\Pi$ of a Hamiltonian on so(3)*, with its
    exact elliptic flow (`free_rigid_body_flow`): a splitting sub-step that is the whole free
    rigid body, e.g. `Strang(system, h, terms=[FreeRigidBodyTerm(I), CollectiveTerm(...)])`
    for $H = \tfrac12\Pi\cdot\mathbb I^{-1}\Pi + V(\Pi)$.

    **Arguments:** `inertia`, the principal moments $(I_1, I_2, I_3)$; `name`.
    """

    def __init__(self, inertia: ArrayLike, name: str = "T"):
        self.inertia = positive_vector(inertia, "inertia", 3)
        self.name = str(name)

    def __repr__(self) -> str:
        return f"FreeRigidBodyTerm({self.inertia.tolist()})"

    def _check(self, system: AbstractPoissonSystem) -> None:
        r"""The flow is Euler's $\dot\Pi = \Pi\times\nabla H$ only if $\mathbb B(\Pi) = \hat\Pi$."""
        probe = np.array([0.3, -1.1, 0.7])
        hat = np.array(
            [[0.0, -probe[2], probe[1]], [probe[2], 0.0, -probe[0]], [-probe[1], probe[0], 0.0]]
        )
        B = None if system.dim != 3 else system.poisson_tensor_components([float(v) for v in probe])
        if B is None or not np.allclose(np.asarray(B, dtype=np.float64), hat, rtol=0.0, atol=1e-14):
            raise ValueError(
                f"FreeRigidBodyTerm needs a system on so(3)* with the rigid body's bracket "
                f"B(Pi) = hat(Pi) (Pi' = Pi x grad H); got {system!r}"
            )

    def value(self, system: AbstractPoissonSystem, y: ArrayLike) -> jax.Array:
        self._check(system)
        y = as_state(y, "y", 3)
        return 0.5 * jnp.sum(y * y / self.inertia, axis=-1)

    def flow(self, system: AbstractPoissonSystem, t: ArrayLike, y: ArrayLike) -> jax.Array:
        self._check(system)
        return free_rigid_body_flow(self.inertia, t, y)
