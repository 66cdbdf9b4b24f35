r"""The reversible LPNet (not in the paper): $\Phi = R\,\mathbb B^{-1}R\circ\mathbb B$ for an
LPNet step $\mathbb B$ and a reversing symmetry $R$ of the system, an implicit step map."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from numpy.typing import ArrayLike

from integrators import AbstractImplicitStepMap
from liepoisson.internals import positive_int
from liepoisson.systems import AbstractPoissonSystem, check_reversing_symmetry, reversing_symmetry

from ._base import AbstractCasimirConservingMap
from ._lpnet import LPNet
from ._parametrisation import AbstractInvertibleParametrisation


class Reversible(AbstractImplicitStepMap, AbstractCasimirConservingMap):
    r"""The $R$-reversible map $\Phi = R\,\mathbb B^{-1}R\circ\mathbb B$ of an LPNet step
    $\mathbb B(y) = \mathbb T(\alpha(y))\,y$, for a reversing symmetry $R = \mathrm{diag}(r)$ of
    the system (`liepoisson.systems.reversing_symmetries`: anti-Poisson, $H\circ R = H$,
    Casimirs kept).

    One step: $m = \mathbb T(\alpha(y))\,y$, then $y_{n+1} = w$ solving
    $w = R\,\mathbb T(-\alpha(Rw))\,R\,m$ by fixed-point iteration from $2m - y$ ($m$ is near
    the midpoint). Both halves are test flows (the second conjugated by $R$, which maps each
    leaf to itself), so the Casimirs are conserved exactly, and $R\Phi R = \Phi^{-1}$: the map
    is $R$-reversible like the flow, to round-off once the iteration has converged (a step that
    has not is NaN: `integrators.AbstractImplicitStepMap`). It is not a Poisson map, but a
    reversible map has no secular energy drift near invariant tori that $R$ maps to themselves
    (Hairer, Lubich, Wanner, *Geometric Numerical Integration*, ch. XI). With a
    `learn.GroupAveraged` network over the system's sign symmetries the step is reversible
    under every $RS$, hence every reversing symmetry.

    `learn.fit` trains it on the explicit residual $R\,\mathbb T(-\alpha(Ry_1))\,R\,
    \mathbb T(\alpha(y_0))\,y_0 - y_1$, zero exactly when the step carries $y_0$ to $y_1$
    (`training_prediction`): two test flows per pair, no iteration.

    **Arguments:** `lpnet`, an `LPNet` whose parametrisation has a closed-form inverse
    (`learn.AbstractInvertibleParametrisation`; `TestFlowParametrisation`:
    $\mathbb T(\alpha)^{-1} = \mathbb T(-\alpha)$); `symmetry`:
    `"auto"` (the first of `reversing_symmetries`) or a sign vector $r$; `iterations` of the
    fixed point (default 16).
    """

    lpnet: LPNet
    symmetry: tuple[float, ...] = eqx.field(static=True)
    iterations: int = eqx.field(static=True)

    def __init__(self, lpnet: LPNet, symmetry: ArrayLike | str = "auto", iterations: int = 16):
        if not isinstance(lpnet, LPNet):
            raise TypeError(f"lpnet must be a learn.LPNet; got {type(lpnet).__name__}")
        if not isinstance(lpnet.parametrisation, AbstractInvertibleParametrisation):
            raise ValueError(  # noqa: TRY004 (a valid LPNet whose step cannot be inverted in closed form)
                "Reversible needs an LPNet whose parametrisation has a closed-form inverse "
                "(a learn.AbstractInvertibleParametrisation, e.g. the TestFlowParametrisation: one test flow per "
                f"step, whose inverse is the flow of -alpha); got {type(lpnet.parametrisation).__name__}"
            )
        if isinstance(symmetry, str):
            if symmetry != "auto":
                raise ValueError(f"symmetry must be 'auto' or a vector of +1/-1 signs; got {symmetry!r}")
            signs = reversing_symmetry(lpnet.system)
        else:
            signs = check_reversing_symmetry(lpnet.system, symmetry, "symmetry")
        self.lpnet = lpnet
        self.symmetry = tuple(float(r) for r in signs)
        self.iterations = positive_int(iterations, "iterations")

    @property
    def system(self) -> AbstractPoissonSystem:
        return self.lpnet.system

    @property
    def h(self) -> float | None:
        return self.lpnet.h

    def start(self, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        m = self.lpnet.step(y)
        return m, 2.0 * m - y

    def iterate(self, m: jax.Array, w: jax.Array) -> jax.Array:
        r"""$R\,\mathbb T(-\alpha(Rw))\,R\,m$, whose fixed point $w$ ends the step."""
        r = jnp.asarray(self.symmetry)
        return r * self.lpnet.parametrisation.inverse_step(self.lpnet.alpha(r * w), r * m, self.h)

    def training_prediction(self, y0: jax.Array, y1: jax.Array) -> jax.Array:
        return self.iterate(self.lpnet.step(y0), y1)

    @property
    def exact_flows_per_step(self) -> int:
        return self.lpnet.parametrisation.exact_flows * (1 + self.iterations)

    def hyperparameters(self) -> dict[str, Any]:
        return {"lpnet": self.lpnet.hyperparameters(), "symmetry": [int(r) for r in self.symmetry],
                "iterations": self.iterations}

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.lpnet, self, self.lpnet.reinitialised(key))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        lpnet = LPNet.from_hyperparameters(system, hyperparameters["lpnet"], key=key, h=h)
        return cls(lpnet, hyperparameters["symmetry"], hyperparameters["iterations"])

    def normalised(self, y0, y1, h, targets=None):
        """The LPNet's scalings from the data, with half the first-order estimate of $\\alpha$
        (a step is two test flows)."""
        return eqx.tree_at(lambda m: m.lpnet, self, self.lpnet.normalised(y0, y1, h, targets, fraction=0.5))
