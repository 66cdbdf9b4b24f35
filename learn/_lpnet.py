r"""LPNets (paper section "A general application to finite-dimensional Lie groups"):
a network predicts the parameters $\alpha(y)$ of an exact Poisson step, $y_{n+1} =
\mathbb T(\alpha(y_n))\,y_n$ (eq. sol_eval_iteration)."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators._step_map import check_state, traced_h, xla_flops
from liepoisson._validation import check_system, positive_float, positive_int
from liepoisson.systems import (
    AbstractPoissonSystem,
    check_reversing_symmetry,
    check_sign_symmetry,
    reversing_symmetry,
    sign_symmetries,
)

from ._base import AbstractLearnedMap
from ._mlp import AffineMLP, Scaling, as_key, check_activation, check_hidden
from ._parametrisation import (
    AbstractStepParametrisation,
    TestFlowParametrisation,
    default_parametrisation,
    parametrisation_from_name,
)


class LPNet(AbstractLearnedMap):
    r"""Local Lie-Poisson network: $y \mapsto \mathbb T(h, \alpha(y))\,y$ with
    $\alpha(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$.

    Every step is an exact test flow, so the Casimirs are conserved to round-off whatever the
    weights. The map is *not* exactly Poisson, because $\alpha$ depends on the point
    (DESIGN.md section 2): `poisson_defect` measures by how much. Its energy error therefore
    drifts: over $N$ steps it grows like $N$ times the one-step error, so long rollouts need a
    small loss. Two things help: refining Adam with L-BFGS-B,
    `optimiser=(Adam(20_000), QuasiNewton(30_000))`, and, where the system has a reversing
    symmetry, the reversible LPNet below. On the so(3) rigid body (`benchmarks/lpnet_accuracy/`,
    seeds 0-2, max energy error over 2000 steps) Adam alone gives 4e-2..2e-1; with L-BFGS-B
    5000, 3.5e-3..5.2e-3, reversible 3e-4..2.5e-3; on the 6-dimensional so(4) body with
    L-BFGS-B 30000, 1.9e-2 (seed 0), reversible 2.0e-3..4.3e-3 (seeds 0-2). Where accuracy over long times
    matters more than the paper's architecture, a G-LPNet (`learn.fit_splitting`) is exactly
    Poisson.

    The affine scalings $m, s$ are fixed (not trained): the identity unless `learn.fit` is
    called with `normalise=True`, which sets them from the training data (inputs: mean/std of
    $y_0$; outputs: mean/std of the pairs' parameters).

    **Arguments:** `system`; `hidden` layer widths (paper: (16, 16, 16), 659 parameters for
    the rigid body); `activation` (paper: sigmoid); `key` (int seed or PRNG key);
    `parametrisation` (an `AbstractStepParametrisation` or its class name; default
    `default_parametrisation(system)`); `h`, the time step (`None`: set by `learn.fit` from the
    data); `input_scaling`, `output_scaling`: `(shift, scale)` pairs (default identity);
    `reversing` (default `None`, the paper's LPNet): `"auto"` or a sign vector $r$ for the
    reversible LPNet below; `fixed_point_iterations` (default 16) of its implicit half;
    `equivariant` (default `False`, the paper's LPNet): `True` (every sign symmetry of the
    system) or a list of sign vectors, to symmetrise $\alpha$, below.

    **Equivariant LPNet** (`equivariant=True`, or a list of sign vectors; not in the paper).
    The sign flips $S = \mathrm{diag}(s)$ that are symmetries of the system
    (`liepoisson.systems.sign_symmetries`: Poisson, $H\circ S = H$; the rigid body's half-turns)
    commute with its flow. They carry test flows to test flows,
    $S\,\mathbb T(\alpha)\,S = \mathbb T(S\alpha)$ (checked at construction), so with the
    average over the group $G$ they generate,
    $\alpha(y) = \frac1{|G|}\sum_{S\in G} S\,\tilde\alpha(Sy)$ of the network $\tilde\alpha$,
    every step commutes with them too: $\Phi(Sy) = S\,\Phi(y)$ for any weights. A reversible
    step is then reversible under every $RS$, and in particular under every reversing
    symmetry $R'$ of the system (since $RR'$ is a sign symmetry), not only the one it was
    built with. This matters because reversibility guarantees no energy drift only near
    invariant tori that $R$ maps to themselves, i.e. orbits that meet its fixed set, and which
    orbits those are depends on $R$: on the so(4) body each of the three $R$ misses some of
    the held-out orbits (`benchmarks/lpnet_accuracy/fixed_sets.py`). Each $\alpha$ costs $|G|$
    network evaluations ($|G|$ = 4 on so(3), 8 on so(4) and se(3)), a reversible step
    $|G|\,(1 + $ `fixed_point_iterations`$)$. Measured (BENCHMARKS.md, "LPNet accuracy"):
    on the so(4) body, reversible, Adam 20000 + L-BFGS-B 5000, seed 0: loss 2.6e-13 instead of
    3.2e-10, max energy error over 2000 steps 2.1e-5 instead of 6.4e-3, and the same over
    10000 steps.

    **Reversible LPNet** (`reversing`, not in the paper). Where the system has a reversing
    symmetry $R = \mathrm{diag}(r)$ (`liepoisson.systems.reversing_symmetries`: anti-Poisson,
    $H\circ R = H$, Casimirs kept; `"auto"` takes the first), the step is
    $\Phi = R\,\mathbb B^{-1}R\circ\mathbb B$ with $\mathbb B(y) = \mathbb T(\alpha(y))\,y$:
    $m = \mathbb T(\alpha(y))\,y$, then $y_{n+1} = w$ solving
    $w = R\,\mathbb T(-\alpha(Rw))\,R\,m$ by fixed-point iteration from $2m - y$ ($m$ is
    near the midpoint; on a partly trained so(3) rigid body at $h = 0.1$ each iteration gained
    a factor 20-50, and 10 reached round-off; on E4's charged particle, with larger $\alpha$,
    16 iterations do not converge and 64 do: `with_fixed_point_iterations(64)` gives the trained
    network more). A step whose iteration has not converged is NaN, which a rollout reports as
    a `RolloutDivergedError` saying so. Both halves are
    test flows (the second conjugated by $R$, which maps each leaf to itself), so the Casimirs
    are conserved exactly as before, and $R\Phi R = \Phi^{-1}$: the map is $R$-reversible like
    the flow (to round-off, once the iteration has converged). It is still not a Poisson map,
    but a reversible map has no secular energy drift near invariant tori (Hairer, Lubich,
    Wanner, *Geometric Numerical Integration*, ch. XI). `learn.fit` trains it on the explicit
    residual $R\,\mathbb T(-\alpha(Ry_1))\,R\,\mathbb T(\alpha(y_0))\,y_0 - y_1$, zero exactly
    when the step carries $y_0$ to $y_1$ (`training_prediction`), so training costs two test
    flows per pair, not an iteration. A step whose last iteration still moves the state by more
    than $2^{10}\varepsilon$ (relative) returns NaN, which a rollout reports as divergence.
    Measured (`benchmarks/lpnet_accuracy/`): BENCHMARKS.md, "LPNet accuracy".
    """

    network: AffineMLP
    parametrisation: AbstractStepParametrisation = eqx.field(static=True)
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None
    reversing: tuple[float, ...] | None = eqx.field(static=True)
    fixed_point_iterations: int = eqx.field(static=True)
    symmetries: tuple[tuple[float, ...], ...] | None = eqx.field(static=True)

    def __init__(
        self,
        system: AbstractPoissonSystem,
        hidden: Sequence[int] = (16, 16, 16),
        activation: str = "sigmoid",
        key: int | jax.Array = 0,
        parametrisation: AbstractStepParametrisation | str | None = None,
        h: float | None = None,
        input_scaling: Scaling | None = None,
        output_scaling: Scaling | None = None,
        reversing: ArrayLike | str | None = None,
        fixed_point_iterations: int = 16,
        equivariant: bool | Sequence[ArrayLike] = False,
    ):
        self.system = check_system(system)
        if parametrisation is None:
            parametrisation = default_parametrisation(system)
        elif isinstance(parametrisation, str):
            parametrisation = parametrisation_from_name(parametrisation, system)
        if not isinstance(parametrisation, AbstractStepParametrisation):
            raise TypeError(
                "parametrisation must be a learn.AbstractStepParametrisation or its class name; got "
                f"{type(parametrisation).__name__}"
            )
        if parametrisation.system is not system:
            raise ValueError("parametrisation must be built for the same system object as the LPNet")
        self.parametrisation = parametrisation
        self.network = AffineMLP(
            system.dim, parametrisation.n_params, check_hidden(hidden), check_activation(activation),
            as_key(key), input_scaling, output_scaling,
        )
        self.h = None if h is None else positive_float(h, "h")
        self.reversing = _reversing(system, parametrisation, reversing)
        self.fixed_point_iterations = positive_int(fixed_point_iterations, "fixed_point_iterations")
        if isinstance(equivariant, str) or not (isinstance(equivariant, (bool, np.bool_, Sequence, np.ndarray))):
            raise TypeError(f"equivariant must be True, False or a list of sign vectors; got {equivariant!r}")
        no = isinstance(equivariant, (bool, np.bool_)) and not equivariant
        self.symmetries = None if no else _symmetry_group(system, parametrisation, equivariant)

    def alpha(self, y: jax.Array) -> jax.Array:
        """The step parameters $\\alpha(y)$ for one state `(dim,)`; for an equivariant LPNet
        the group average $\\frac1{|G|}\\sum_S S\\,\\tilde\\alpha(Sy)$ of the network."""
        if self.symmetries is None:
            return self.network(y)
        group = jnp.asarray(self.symmetries)
        return jnp.mean(group * jax.vmap(self.network)(group * y), axis=0)

    def _first_half(self, y: jax.Array) -> jax.Array:
        """$\\mathbb T(\\alpha(y))\\,y$: the whole step of the paper's LPNet."""
        return self.parametrisation.step(self.alpha(y), y, self.h)

    def _second_half(self, w: jax.Array, m: jax.Array) -> jax.Array:
        """$R\\,\\mathbb T(-\\alpha(Rw))\\,R\\,m$, whose fixed point $w$ ends a reversible step."""
        r = jnp.asarray(self.reversing)
        return r * self.parametrisation.step(-self.alpha(r * w), r * m, self.h)

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        m = self._first_half(y)
        if self.reversing is None:
            return m
        w = jax.lax.fori_loop(0, self.fixed_point_iterations - 1, lambda _, w: self._second_half(w, m), 2.0 * m - y)
        w_next = self._second_half(w, m)
        moved = jnp.max(jnp.abs(w_next - w))
        return jnp.where(moved <= _FIXED_POINT_RTOL * jnp.maximum(1.0, jnp.max(jnp.abs(w_next))), w_next, jnp.nan)

    @property
    def divergence_hint(self) -> str:
        hint = super().divergence_hint
        if self.reversing is None:
            return hint
        return (f"{hint}, or its reversible step's fixed-point iteration did not converge in "
                f"fixed_point_iterations={self.fixed_point_iterations}: try "
                f"net.with_fixed_point_iterations({4 * self.fixed_point_iterations})")

    def with_fixed_point_iterations(self, iterations: int) -> LPNet:
        """The same trained reversible LPNet with another iteration count for the implicit half
        of its step (a large step, or large $\alpha$, contracts slowly: E4's charged particle
        needs about 64)."""
        if self.reversing is None:
            raise ValueError("with_fixed_point_iterations is for a reversible LPNet (reversing=...); this one is not")
        # A static field (the loop bound is a Python int at trace time), which eqx.tree_at cannot
        # replace; a shallow copy shares the weights, and the new count recompiles the step.
        new = copy.copy(self)
        object.__setattr__(new, "fixed_point_iterations", positive_int(iterations, "iterations"))
        return new

    def training_prediction(self, y0: jax.Array, y1: jax.Array) -> jax.Array:
        """The step of $y_0$, or for a reversible LPNet the explicit residual form
        $R\\,\\mathbb T(-\\alpha(Ry_1))\\,R\\,\\mathbb T(\\alpha(y_0))\\,y_0$ (equal to $y_1$
        exactly when the step carries $y_0$ to $y_1$)."""
        if self.reversing is None:
            return self.step(y0)
        return self._second_half(check_state(y1, self.system.dim), self._first_half(check_state(y0, self.system.dim)))

    def alpha_estimate(self, y0: ArrayLike, y1: ArrayLike, h: float) -> np.ndarray:
        """First-order estimate of $\\alpha$ from pairs (`params_estimate`; half of it for a
        reversible LPNet, whose step is two test flows), used to normalise the outputs."""
        estimate = self.parametrisation.params_estimate(y0, y1, h)
        return estimate if self.reversing is None else 0.5 * estimate

    @property
    def exact_flows_per_step(self) -> int:
        per_flow = self.parametrisation.exact_flows
        return per_flow if self.reversing is None else per_flow * (1 + self.fixed_point_iterations)

    def step_flops(self) -> float:
        """XLA's count, with the fixed-point iteration of a reversible LPNet counted
        `fixed_point_iterations` times (XLA counts a loop body once)."""
        if self.reversing is None:
            return super().step_flops()
        y = jnp.zeros(self.system.dim)
        first = xla_flops(lambda m, y: m._first_half(y), traced_h(self), y)
        return first + self.fixed_point_iterations * xla_flops(lambda m, y: m._second_half(y, y), traced_h(self), y)

    def hyperparameters(self) -> dict[str, Any]:
        reversible = {} if self.reversing is None else {
            "reversing": [int(r) for r in self.reversing], "fixed_point_iterations": self.fixed_point_iterations}
        # the group itself, not True: a file keeps the function its weights were trained as
        equivariant = {} if self.symmetries is None else {
            "equivariant": [[int(v) for v in s] for s in self.symmetries if any(v < 0 for v in s)]}
        return {
            **self.network.hyperparameters(),
            "parametrisation": type(self.parametrisation).__name__,
            **reversible,
            **equivariant,
        }


#: A reversible step whose last fixed-point iteration moved the state by more than this (relative
#: to max(1, |y|_inf)) has not converged: 2^10 eps, a few hundred roundings of the test flow.
_FIXED_POINT_RTOL = 2.0**10 * float(np.finfo(np.float64).eps)


def _symmetry_group(system, parametrisation, equivariant) -> tuple[tuple[float, ...], ...]:
    """The group $G$ an equivariant LPNet averages over: the identity and the sign symmetries
    `equivariant` (`True`: all of `sign_symmetries(system)`; else the sign vectors given,
    checked by `check_sign_symmetry`), with their products. Each must carry test flows to test
    flows, $S\\,\\mathbb T(\\alpha)\\,y = \\mathbb T(S\\alpha)\\,Sy$: true for every test flow
    (the flow of $\\langle\\alpha, y\\rangle$) since $S$ is Poisson, and checked at seeded
    random $\\alpha, y$ because a parametrisation's parameters may transform otherwise. Python
    floats, sorted (a static field)."""
    if parametrisation.n_params != system.dim:
        raise ValueError(
            "equivariant needs step parameters that transform like the state (n_params == dim = "
            f"{system.dim}); {type(parametrisation).__name__} has n_params={parametrisation.n_params}"
        )
    if isinstance(equivariant, (bool, np.bool_)):
        given = False
        found = sign_symmetries(system)
        if not found:
            raise ValueError(
                f"equivariant=True needs a sign flip S with B(Sy) = S B(y) S and H(Sy) = H(y); {system!r} "
                "has none (liepoisson.systems.sign_symmetries): use equivariant=False"
            )
    else:
        given = True
        try:
            candidates = list(equivariant)
        except TypeError as err:
            raise TypeError(
                f"equivariant must be True, False or a list of sign vectors; got {equivariant!r}") from err
        found = [check_sign_symmetry(system, s, f"equivariant[{i}]") for i, s in enumerate(candidates)]
    group = {(1.0,) * system.dim}
    for s in found:
        group.add(tuple(float(v) for v in s))
    while True:  # close under products (a product of symmetries is one)
        products = {tuple(a * b for a, b in zip(u, v)) for u in group for v in group} - group
        if not products:
            break
        group |= products
    rng = np.random.default_rng(0)
    y = rng.normal(size=(16, system.dim))
    singular = system.singular(y)
    if singular is not None:
        y = y[~np.asarray(singular)]
    y = y[:4]
    alpha = 0.3 * rng.normal(size=y.shape)  # |h alpha| ~ 0.03-0.1, a training step's size
    h = 0.1
    step = jax.vmap(lambda a, y: parametrisation.step(a, y, h))
    base = np.asarray(step(jnp.asarray(alpha), jnp.asarray(y)))
    if y.shape[0] == 0 or not np.all(np.isfinite(base)):
        raise ValueError(f"equivariant: no regular probe state of {system!r} to check the test flows on")
    tol = _LAW_RTOL * max(1.0, float(np.abs(base).max()))
    kept = []
    for s in sorted(group):
        sv = np.asarray(s)
        moved = np.asarray(step(jnp.asarray(sv * alpha), jnp.asarray(sv * y)))
        if np.all(np.isfinite(moved)) and np.abs(moved - sv * base).max() <= tol:
            kept.append(s)
        elif given:
            raise ValueError(
                f"equivariant: the step of {type(parametrisation).__name__} does not transform under "
                f"S = {sv.astype(int).tolist()} as S T(alpha) y = T(S alpha) S y; leave this one out"
            )
    if len(kept) < len(group):
        # The law holds for products of elements it holds for, so a gap here is a parametrisation
        # whose parameters do not transform like the state: no subgroup is safe to guess.
        raise ValueError(
            f"equivariant=True: the step of {type(parametrisation).__name__} on {system!r} does not "
            "transform under every sign symmetry as S T(alpha) y = T(S alpha) S y (those it does: "
            f"{[list(map(int, s)) for s in kept if any(v < 0 for v in s)]}); pass those as equivariant=[...] "
            "or use equivariant=False"
        )
    return tuple(kept)


#: $S\,\mathbb T(\alpha)\,y$ and $\mathbb T(S\alpha)\,Sy$ are the same computation on sign-flipped
#: numbers, up to the order of a few hundred roundings (an expm): $10^4\varepsilon$.
_LAW_RTOL = 1e4 * float(np.finfo(np.float64).eps)


def _reversing(system, parametrisation, reversing) -> tuple[float, ...] | None:
    """The sign vector of a reversible LPNet's symmetry, checked; None for the paper's LPNet."""
    if reversing is None:
        return None
    if not isinstance(parametrisation, TestFlowParametrisation):
        raise ValueError(  # noqa: TRY004 (a valid parametrisation that cannot be reversed)
            "reversing needs the TestFlowParametrisation (one test flow per step, whose inverse is "
            f"the flow of -alpha); got {type(parametrisation).__name__}"
        )
    if isinstance(reversing, str):
        if reversing != "auto":
            raise ValueError(f"reversing must be None, 'auto' or a vector of +1/-1 signs; got {reversing!r}")
        signs = reversing_symmetry(system)
    else:
        signs = check_reversing_symmetry(system, reversing, "reversing")
    return tuple(float(r) for r in signs)
