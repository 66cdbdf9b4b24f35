r"""The part of an LPNet's lifted step that momenta cannot fix, fitted to configurations.

An LPNet step is the test flow $\mu_1 = \mathrm{Ad}^*_{\exp(h\alpha)}\mu_0$. The group elements
carrying $\mu_0$ to $\mu_1$ (in the lifted step's order: a turn first, then the flow) are
$\mathrm{Stab}(\mu_0)\exp(h\alpha)$, whose directions at a regular point are the Casimir
gradients: the configuration's true step is $g_1 = g_0\exp(h\,\beta\cdot\nabla C(\mu_0))
\exp(h\alpha)$ for some rates $\beta$, for the net's own $\alpha$ (any member of the family,
Casimir-projected or not, if it carries $\mu_0$ to $\mu_1$). Each configuration pair gives its
$\beta$ in closed form; a network $\beta(\mu)$ is fitted to them by Levenberg-Marquardt.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators import Trajectories
from liepoisson.internals import positive_int, show_progress

from .._models._lpnet import LPNet
from .._models._mlp import AffineMLP
from .._models._parametrisation import AbstractLiftedParametrisation
from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._record import TrainingRecord
from .._solvers._stage import Context, KeepIfBetter
from ._fit import solve, training_record
from ._losses import MeanSquares, Pairs
from ._problem import Description, MapProblem

#: A pair whose configuration step leaves the Casimir directions by more than this fraction of
#: the step's size ($h|\hat\alpha| + |\log|$) is not a motion with these momenta: refused.
OFF_ORBIT = 1e-6


class PhaseNetwork(eqx.Module):
    """What `fit_phase` trains: the phase network at the data's step `h` (for the record)."""

    network: AffineMLP
    h: float


def _turns(group, g0, g1, alpha, h, grads):
    r"""`(rates (N, k), off (N,), turn (N, dim))`: $\log(g_0^{-1}g_1\exp(-h\alpha))$ and its
    least-squares rates on the Casimir gradients `grads` `(N, k, dim)` (divided by `h`), and
    what is left of it off their span."""
    turn = group.log_between(g0, np.asarray(group.right_exp(jnp.asarray(g1), jnp.asarray(-h * alpha))))
    pinv = np.linalg.pinv(np.transpose(grads, (0, 2, 1)))  # (N, k, dim)
    rates = np.einsum("nkd,nd->nk", pinv, turn) / h
    off = np.linalg.norm(turn - h * np.einsum("nk,nkd->nd", rates, grads), axis=1)
    return rates, off, turn


def phase_rates(net: LPNet, data: Trajectories, noisy: bool = False) -> tuple[np.ndarray, np.ndarray]:
    r"""`(states (N, dim), rates (N, k))`: for every consecutive pair of `data` (states and
    configurations), the $\beta$ with $g_1 \approx g_0\exp(h\beta\cdot\nabla C(\mu_0))
    \exp(h\alpha(\mu_0))$, $\alpha$ the net's own (what its lifted step applies), by least
    squares on the Casimir gradients (exact when $\exp(h\alpha)$ carries $\mu_0$ to $\mu_1$).
    `ValueError` naming a pair whose configuration step, against the pair's exact parameters
    $\hat\alpha$ (`net.params_from_pair`), leaves those directions: no motion with these
    momenta. With `noisy` (observed momenta and configurations), no pair is checked: what
    leaves the directions is the noise (and the net's misfit), which the least squares drop."""
    system = net.system
    group = system.require_group()
    h = float(data.h)
    y0 = data.states[:, :-1].reshape(-1, system.dim)
    y1 = data.states[:, 1:].reshape(-1, system.dim)
    g0 = data.configurations[:, :-1].reshape(-1, group.size)
    g1 = data.configurations[:, 1:].reshape(-1, group.size)
    grads = np.asarray(system.casimir_gradients(y0))  # (N, k, dim)
    if not noisy:
        _check_on_orbit(net, data, y0, y1, g0, g1, grads)
    alpha = np.asarray(jax.vmap(net.alpha)(jnp.asarray(y0)))
    rates, _, _ = _turns(group, g0, g1, alpha, h, grads)
    return y0, rates


def _check_on_orbit(net: LPNet, data: Trajectories, y0, y1, g0, g1, grads) -> None:
    """`ValueError` naming the pair whose configuration step, against the pair's exact
    parameters, leaves the Casimir directions by more than `OFF_ORBIT` of its size."""
    group, h = net.system.require_group(), float(data.h)
    exact = np.asarray(net.params_from_pair(y0, y1, h))
    _, off, turn = _turns(group, g0, g1, exact, h, grads)
    size = h * np.linalg.norm(exact, axis=1) + np.linalg.norm(turn, axis=1)
    worst = int(np.argmax(off / np.maximum(size, np.finfo(float).tiny)))
    if off[worst] > OFF_ORBIT * max(size[worst], np.finfo(float).tiny):
        n_steps = data.states.shape[1] - 1
        raise ValueError(
            f"data: the configuration of trajectory {worst // n_steps}, step {worst % n_steps}, moves off the "
            f"directions its momenta allow ({off[worst]:.3g} of a step of size {size[worst]:.3g}): these "
            f"configurations are not a motion with these momenta on {group.name} (of another system, or noisy: "
            "then fit with noisy=True)")


def fit_phase(net: LPNet, data: Trajectories, *, hidden: tuple[int, ...] = (16, 16), activation: str = "sigmoid",
              key: int | jax.Array = 0, iterations: int = 200, noisy: bool = False,
              progress: bool | None = None) -> tuple[LPNet, TrainingRecord]:
    r"""`(net with a phase network, record)`: the rates $\beta(\mu)$ of `LPNet.lifted_step`
    along the Casimir gradients, fitted to the configurations of `data`.

    **Arguments:** `net`, an `LPNet` (its $\alpha$ fitted to momenta, e.g. by `learn.fit`);
    `data`, `integrators.Trajectories` with configurations (`ground_truth(..., g0=...)`) at
    the net's step; `hidden`, `activation`, `key`: the phase network, a `learn.AffineMLP` from
    states to one rate per Casimir (scaled to the data's rates); `iterations`:
    Levenberg-Marquardt steps at most on the rates' squared error; `noisy`: the momenta and
    configurations are observed with noise, so pairs that leave the Casimir directions are not
    refused (their part off them, the noise and the net's misfit, is dropped by the least
    squares; `phase_rates`).

    Each pair's rates come in closed form (`phase_rates`); only the network is fitted, so the
    momentum step is unchanged (and so are its Casimirs)."""
    if not isinstance(net, LPNet):
        raise TypeError(f"net must be a learn.LPNet; got {type(net).__name__}")
    if not isinstance(data, Trajectories):
        raise TypeError(f"data must be integrators.Trajectories with configurations; got {type(data).__name__}")
    if data.states.shape[1] < 2:
        raise ValueError("data holds one time per trajectory: the phase is fitted to pairs of consecutive "
                         "configurations; give at least two times")
    if data.configurations is None:
        raise ValueError("data holds no configurations: the phase is what configurations show and momenta do not; "
                         "integrate them with integrators.ground_truth(system, y0, h, n, g0=...)")
    if data.system.group != net.system.require_group():
        raise ValueError(f"data's configurations are on {data.system.group!r}; the net's system moves them on "
                         f"{net.system.group!r}")
    if not isinstance(net.parametrisation, AbstractLiftedParametrisation):
        raise ValueError(  # noqa: TRY004 (a right-type net without the capability)
            f"the net's parametrisation {type(net.parametrisation).__name__} does not carry a "
                         "configuration (its parameters are not a body velocity); build the LPNet with "
                         "parametrisation='TestFlowParametrisation'")
    if net.system.n_casimirs == 0:
        raise ValueError(f"{net.system!r} has no Casimirs: the test flow fixes the configuration's step, there is "
                         "no phase to fit")
    h = float(data.h)
    if net.h is not None and abs(net.h - h) > 1e-12 * h:
        raise ValueError(f"the net's step h={net.h} differs from the data's h={h}; fit the phase at the net's step")
    iterations = positive_int(iterations, "iterations")
    if not isinstance(noisy, bool):
        raise TypeError(f"noisy must be True or False; got {noisy!r}")
    net = eqx.tree_at(lambda m: m.h, net, h, is_leaf=lambda v: v is None)
    states, rates = phase_rates(net, data, noisy)
    network = AffineMLP(net.system.dim, net.system.n_casimirs, hidden, activation, key).rescaled(states, rates)
    scale = jnp.asarray(network.output_scale)
    loss = MeanSquares(lambda m, y, b: (jax.vmap(m.network)(y) - b) / scale, "phase rates")
    description = Description(loss=loss.name, h=h, n_train=int(states.shape[0]), n_val=0, seed=0,
                              validation_fraction=0.0)
    problem = MapProblem(loss, PhaseNetwork(network, h), Pairs(jnp.asarray(states), jnp.asarray(rates)), None,
                         description)
    context = Context(seed=0, progress=show_progress(progress))
    solved, results = solve(problem, (KeepIfBetter(LevenbergMarquardt(iterations)),), context)
    record = training_record(solved, results)
    fitted = eqx.tree_at(lambda m: m.phase, net, solved.y0.network, is_leaf=lambda v: v is None)
    return fitted, dataclasses.replace(record, model="LPNet phase")
