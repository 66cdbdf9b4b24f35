r"""How the parameters $\alpha$ of an LPNet relate to one step: $y_{n+1} = \mathbb T(\alpha)\,y_n$.

A parametrisation is a family of exact Poisson maps (for fixed parameters) and its inverse,
the parameters that carry $y_0$ to $y_1$ ([the paper](https://arxiv.org/abs/2308.15349),
Sec. 4, eqs. (25) and (26); for so(3), Sec. 5.1, eq. (30)). Both live in `liepoisson`, beside
the flows; the inverse is chosen there by the flow's type (closed form for so(3) and the se(3)
rotation-shear, Gauss-Newton otherwise).
"""

from __future__ import annotations

import abc

import jax
import numpy as np
from numpy.typing import ArrayLike

import liepoisson as lp
from liepoisson.internals import check_system, pairs, positive_float
from liepoisson.systems import AbstractLiePoissonSystem, AbstractPoissonSystem


class AbstractStepParametrisation(abc.ABC):
    r"""The parameters $\alpha\in\mathbb R^{n_\text{params}}$ of one learned step
    $y \mapsto \mathbb T(\alpha)\,y$ and how to find them from a data pair.

    `step` must be an exact flow of the system's bracket for fixed parameters (a Poisson map
    that conserves every Casimir), usable under `jit`, `vmap` and `grad`.
    """

    system: AbstractPoissonSystem
    rtol: float

    @property
    @abc.abstractmethod
    def n_params(self) -> int:
        """Number of parameters of one step."""

    @property
    @abc.abstractmethod
    def exact_flows(self) -> int:
        """Exact test flows evaluated by one `step`."""

    @abc.abstractmethod
    def step(self, params: jax.Array, y: jax.Array, h: float) -> jax.Array:
        """$\\mathbb T(\\alpha)\\,y$ for one sample: `params` `(n_params,)`, `y` `(dim,)`."""

    @abc.abstractmethod
    def params_from_pair(self, y0: ArrayLike, y1: ArrayLike, h: float) -> np.ndarray:
        """Parameters carrying `y0` to `y1` in one step of size `h`, Casimir-projected.

        `y0`, `y1` of shape `(..., dim)`; returns `(..., n_params)`. Raises `ValueError`
        naming the pair when no step connects them (different Casimirs).
        """

    def params_estimate(self, y0: ArrayLike, y1: ArrayLike, h: float) -> np.ndarray:
        r"""First-order estimate $\alpha \approx \mathbb B(y_0)^+ (y_1 - y_0)/h$ (minimum norm,
        hence orthogonal to the Casimir gradients; `system.poisson_lstsq`); not validated. Used
        to scale networks."""
        y0, y1 = pairs(y0, y1, self.system.dim)
        h = positive_float(h, "h")
        return self.system.poisson_lstsq(y0, (y1 - y0) / h)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.system!r}, rtol={self.rtol:g})"

    # A parametrisation is a static part of an LPNet's pytree: equal ones (same kind, same
    # system object, same rtol) let two networks share compiled code.
    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.system is self.system and other.rtol == self.rtol

    def __hash__(self) -> int:
        return hash((type(self), id(self.system), self.rtol))


class AbstractInvertibleParametrisation(AbstractStepParametrisation):
    r"""A parametrisation whose steps have a closed-form inverse, $\mathbb T(\alpha)^{-1}$ =
    `inverse_step(alpha, ., h)`: what a reversible step ($R\,\mathbb B^{-1}R\circ\mathbb B$,
    `learn.Reversible`) needs."""

    @abc.abstractmethod
    def inverse_step(self, params: jax.Array, y: jax.Array, h: float) -> jax.Array:
        r"""$\mathbb T(\alpha)^{-1}\,y$ for one sample."""


class AbstractLiftedParametrisation(AbstractStepParametrisation):
    r"""A parametrisation whose step carries the configuration: its parameters are the body
    velocity of its exact flow (what `LPNet.lifted_step` and `learn.fit_phase` need)."""

    @abc.abstractmethod
    def lifted_step(self, params: jax.Array, g: jax.Array, y: jax.Array, h: float) -> tuple[jax.Array, jax.Array]:
        r"""`step` lifted to the configuration: $(g\gamma, \mathbb T(\alpha)\,y)$, $\gamma$ the
        group element of the step's exact flow."""


class TestFlowParametrisation(AbstractInvertibleParametrisation, AbstractLiftedParametrisation):
    r"""Any system with exact test flows (Lie-Poisson on any algebra, or the affine/canonical
    systems of the paper): one step is $y \mapsto \mathbb T(h, \alpha)\,y$ =
    `system.test_flow(alpha, h, y)`, $\alpha\in\mathbb R^n$.

    `params_from_pair` is `system.test_flow_parameters`: the shortest rotation in closed form
    for so(3)* ([the paper](https://arxiv.org/abs/2308.15349)'s $A = \Pi^0\times\Pi^1/h$,
    Sec. 5.1, eq. (30), with the exact angle), Gauss-Newton restricted to the complement of
    the Casimir gradients otherwise.

    **Arguments:** `system`; `rtol`: tolerance for the Casimir mismatch of a pair (and, times
    100, for the residual of the parameters found).
    """

    __test__ = False  # not a pytest test class, despite its name

    def __init__(self, system: AbstractPoissonSystem, rtol: float = 1e-10):
        self.system = check_system(system)
        self.rtol = positive_float(rtol, "rtol")

    @property
    def n_params(self) -> int:
        return self.system.dim

    @property
    def exact_flows(self) -> int:
        return 1

    def step(self, params, y, h):
        return self.system.test_flow(params, h, y)

    def lifted_step(self, params, g, y, h):
        r"""$(g\exp(h\alpha),\ \mathrm{Ad}^*_{\exp(h\alpha)}y)$: the test flow's body
        velocity is $\alpha$ throughout (`system.lifted_test_flow`)."""
        return self.system.lifted_test_flow(params, h, g, y)

    def inverse_step(self, params, y, h):
        r"""The test flow of $-\alpha$: the flow of a linear Hamiltonian run backwards."""
        return self.step(-params, y, h)

    def params_from_pair(self, y0, y1, h):
        return self.system.test_flow_parameters(y0, y1, positive_float(h, "h"), rtol=self.rtol)


class SE3RotationShear(AbstractStepParametrisation):
    r"""se(3)* (Kirchhoff): one step is a rotation of $\Pi$ and $p$ followed by a shear of
    $\Pi$, `liepoisson.se3_rotation_shear` (the paper's data preparation for Kirchhoff's
    equations, re-derived), parameters $\alpha = (A, b)\in\mathbb R^6$; two exact test flows,
    so $|p|^2$ and $\Pi\cdot p$ are conserved exactly. `params_from_pair` is its closed-form
    inverse `liepoisson.se3_rotation_shear_parameters`.

    **Arguments:** `system`, a Lie-Poisson system whose algebra is se(3) with its closed-form
    flow (`liepoisson.se3()`, e.g. `liepoisson.systems.Kirchhoff`); `rtol` as above.
    """

    def __init__(self, system: AbstractPoissonSystem, rtol: float = 1e-10):
        system = check_system(system)
        if not (isinstance(system, AbstractLiePoissonSystem) and isinstance(system.algebra.exact_flow, lp.SE3Flow)):
            raise ValueError(  # noqa: TRY004 (a system of the right type on the wrong algebra)
                "SE3RotationShear needs a Lie-Poisson system on se(3)* built on liepoisson.se3() "
                f"(e.g. liepoisson.systems.Kirchhoff); got {system!r}"
            )
        self.system = system
        self.rtol = positive_float(rtol, "rtol")

    @property
    def n_params(self) -> int:
        return 6

    @property
    def exact_flows(self) -> int:
        return 2

    def step(self, params, y, h):
        return lp.se3_rotation_shear(params, h, y, sign=self.system.algebra.sign)

    def params_from_pair(self, y0, y1, h):
        return lp.se3_rotation_shear_parameters(
            y0, y1, positive_float(h, "h"), sign=self.system.algebra.sign, rtol=self.rtol, names=("y0", "y1")
        )


PARAMETRISATIONS: dict[str, type[AbstractStepParametrisation]] = {
    cls.__name__: cls for cls in (TestFlowParametrisation, SE3RotationShear)
}


def parametrisation_from_name(name: str, system: AbstractPoissonSystem) -> AbstractStepParametrisation:
    """The parametrisation class `name` built for `system` (as stored in model files)."""
    if name not in PARAMETRISATIONS:
        raise ValueError(f"unknown parametrisation {name!r}; known: {sorted(PARAMETRISATIONS)}")
    return PARAMETRISATIONS[name](system)


def default_parametrisation(system: AbstractPoissonSystem) -> AbstractStepParametrisation:
    """`TestFlowParametrisation`: one exact test flow per step, for every system (every system
    of the library has exact test flows)."""
    return TestFlowParametrisation(check_system(system))
