r"""A DeepONet fitted to body observations. A free body's motion relative to its first
configuration depends on its first velocity only (left invariance): the network maps the first
observed velocity $\xi_0$ (branch) and the time since it (trunk) to the relative configuration
$g_0^{-1}g(t)$ and the velocity $\xi(t)$; the prediction is $g_0$ times it, projected onto the
group. Fitted by Adam on the mean squared error in the scaled outputs. Rotations and poses."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators import BodyObservations
from liepoisson import AbstractLieGroup, Poses, Rotations
from liepoisson.internals import positive_float, positive_int, show_progress
from liepoisson.systems import AbstractLiePoissonSystem

from .._models._deeponet import DeepONet
from .._solvers._adam import Adam
from .._solvers._problem import AbstractLeastSquares
from .._solvers._record import TrainingRecord
from .._solvers._stage import Context
from ._fit import solve, training_record
from ._problem import Description, MapProblem


def continuous_quaternions(group: AbstractLieGroup, g: np.ndarray) -> np.ndarray:
    r"""Configurations `(T, size)` of one trajectory with their unit quaternions' signs chosen
    continuous in time ($q_k\cdot q_{k-1} \ge 0$; consecutive attitudes less than a half-turn
    apart) from a first one of scalar part $w \ge 0$: $\pm q$ are one attitude, and a network
    regressing components must not see jumps between them. Other groups' components unchanged."""
    g = np.array(g, dtype=np.float64)
    if not isinstance(group, (Rotations, Poses)):
        return g
    q = g[:, :4]
    signs = np.sign(np.sum(q[1:] * q[:-1], axis=1))
    signs = np.cumprod(np.concatenate([[1.0 if q[0, 3] >= 0.0 else -1.0], np.where(signs == 0.0, 1.0, signs)]))
    g[:, :4] = q * signs[:, None]
    return g


def relative_states(group: AbstractLieGroup, g: np.ndarray, xi: np.ndarray) -> np.ndarray:
    r"""$(g_0^{-1}g_k, \xi_k)$ `(T, size + dim)` of one trajectory (`group.between`,
    `continuous_quaternions`)."""
    rel = np.asarray(group.between(jnp.asarray(g[:1]), jnp.asarray(g)))
    return np.concatenate([continuous_quaternions(group, rel), xi], axis=1)


class OperatorData(eqx.Module):
    """Trajectories as a DeepONet's training data: initial states `u0` `(S, n)`, the distinct
    times `times` `(K,)` since each trajectory's start and `index` `(S, T)` into them (the
    trunk is evaluated once per distinct time: once per sample time for regular sampling,
    not once per observation), states `u` `(S, T, n)` and `mask` `(S, T)` (0 where a shorter
    trajectory is padded)."""

    u0: jax.Array
    times: jax.Array
    index: jax.Array
    u: jax.Array
    mask: jax.Array


def operator_data(data: BodyObservations) -> OperatorData:
    r"""`OperatorData` of body observations with configurations and velocities: $u_0 = \xi_0$,
    $u = (g_0^{-1}g, \xi)$ (`relative_states`), times since each trajectory's first."""
    if data.configurations is None or data.velocities is None:
        raise ValueError(f"a DeepONet maps observed states to observed states: it needs configurations and "
                         f"velocities; these observations hold {' and '.join(data.measured)} only")
    if len(data) < 2:
        raise ValueError(f"data holds {len(data)} trajectory; a DeepONet's branch learns how the motion depends "
                         "on the first velocity: give at least two trajectories")
    states = [relative_states(data.group, g, v) for g, v in zip(data.configurations, data.velocities, strict=True)]
    T = max(s.shape[0] for s in states)
    n = states[0].shape[1]
    u, t, mask = np.zeros((len(states), T, n)), np.zeros((len(states), T)), np.zeros((len(states), T))
    for j, (s, tj) in enumerate(zip(states, data.times, strict=True)):
        k = s.shape[0]
        u[j, :k], u[j, k:] = s, s[-1]
        t[j, :k], t[j, k:] = tj - tj[0], tj[-1] - tj[0]
        mask[j, :k] = 1.0
    times, index = np.unique(t, return_inverse=True)
    u0 = np.stack([v[0] for v in data.velocities])
    return OperatorData(jnp.asarray(u0), jnp.asarray(times), jnp.asarray(index.reshape(t.shape)),
                        jnp.asarray(u), jnp.asarray(mask))


class OperatorFit(eqx.Module):
    """What `fit_deeponet` trains: the network, and the data's mean interval `h` (for the record)."""

    net: DeepONet
    h: float


class OperatorLoss(AbstractLeastSquares):
    """The DeepONet's residuals on every present observation, in units of its output scale."""

    def residuals(self, y: OperatorFit, args: OperatorData) -> jax.Array:
        net = y.net
        predicted = net.combine(jax.vmap(net.coefficients)(args.u0)[:, None],
                                jax.vmap(net.basis)(args.times)[args.index])
        return (predicted - args.u) / jnp.asarray(y.net.output_scale) * args.mask[..., None]

    def count(self, y: OperatorFit, args: OperatorData) -> int:
        return round(float(np.sum(np.asarray(args.mask)))) * int(args.u.shape[-1])

    def __call__(self, y: OperatorFit, args: OperatorData) -> jax.Array:
        r = self.residuals(y, args)
        return jnp.sum(r * r) / (jnp.sum(args.mask) * args.u.shape[-1])


@dataclasses.dataclass(frozen=True)
class _Problem(MapProblem):
    """A DeepONet's fit: no map, no step to trace."""

    def step_size(self, y):
        return None

    @property
    def name(self) -> str:
        return "DeepONet"

    def reinitialised(self, key):
        raise ValueError("a DeepONet's fit has no restarts")


def fit_deeponet(data: BodyObservations, *, width: int = 32, hidden: tuple[int, ...] = (64, 64),
                 activation: str = "tanh", epochs: int = 60_000, learning_rate: float = 3e-3,
                 final_learning_rate: float | None = 1e-5, key: int = 0, progress: bool | None = None
                 ) -> tuple[BodyDeepONet, TrainingRecord]:
    r"""`(model, record)`: a `BodyDeepONet` fitted to body observations by full-batch Adam.

    **Arguments:**

    - `data`: `integrators.BodyObservations` with configurations and velocities, two or more
      trajectories (any group; unit quaternions' signs made continuous).
    - `width`: the trunk's basis functions $p$; `hidden`, `activation`: both MLPs' layers.
    - `epochs` of Adam from `learning_rate` decaying exponentially to `final_learning_rate`
      (constant if `None`); `key`: an int seed of the weights.
    - `progress`: a bar (default: on a terminal).

    The network's scalings come from the data; the loss is the mean squared error of the
    relative configurations' components and the velocities, each over its spread."""
    if not isinstance(data, BodyObservations):
        raise TypeError(f"data must be integrators.BodyObservations; got {type(data).__name__}")
    if isinstance(key, bool) or not isinstance(key, (int, np.integer)):
        raise TypeError(f"key must be an int seed of the weights; got {key!r}")
    stage = Adam(positive_int(epochs, "epochs"), positive_float(learning_rate, "learning_rate"),
                 final_learning_rate=final_learning_rate)
    context = Context(seed=int(key), progress=show_progress(progress), desc="DeepONet")
    args = operator_data(data)
    n = int(args.u.shape[-1])
    present = np.asarray(args.mask) > 0
    net = DeepONet(data.dim, n, width=width, hidden=hidden, activation=activation, key=int(key)).rescaled(
        np.asarray(args.u0), np.asarray(args.times)[np.asarray(args.index)[present]], np.asarray(args.u)[present])
    h = float(np.mean(data.intervals()))
    description = Description(loss="DeepONet states", h=h, n_train=int(present.sum()), n_val=0, seed=int(key),
                              validation_fraction=0.0)
    problem = _Problem(OperatorLoss(), OperatorFit(net, h), args, None, description)
    solved, results = solve(problem, (stage,), context)
    return BodyDeepONet(solved.y0.net, data.system), training_record(solved, results)


class BodyDeepONet(eqx.Module):
    r"""A DeepONet on a body's states (`fit_deeponet`): `predict(g0, xi0, t)` gives the
    configurations $g_0\,r(t)$ (projected onto the group) and velocities at the times `t` after
    one initial state. `net` maps `system.dim` velocities to `group.size + dim` components."""

    net: DeepONet
    system: AbstractLiePoissonSystem = eqx.field(static=True)

    def __check_init__(self):
        if not isinstance(self.net, DeepONet):
            raise TypeError(f"net must be a learn.DeepONet; got {type(self.net).__name__}")
        group = getattr(self.system, "group", None)
        if not isinstance(group, AbstractLieGroup):
            raise TypeError(f"system must be a Lie-Poisson system with a configuration group; got {self.system!r}")
        if (self.net.in_size, self.net.out_size) != (self.system.dim, group.size + self.system.dim):
            raise ValueError(
                f"net maps {self.net.in_size} inputs to {self.net.out_size} outputs; a DeepONet of {self.system!r} "
                f"maps its {self.system.dim} velocities to {group.size} configuration components and "
                f"{self.system.dim} velocities")

    def predict(self, g0: ArrayLike, xi0: ArrayLike, t: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """`(g (T, size), xi (T, dim))` at the times `t` `(T,)` since the initial state."""
        group, dim = self.system.group, self.system.dim
        g0 = np.asarray(group.check(g0, "g0"))
        if g0.shape != (group.size,):
            raise ValueError(f"g0 must be one configuration of shape ({group.size},); got {g0.shape}")
        xi0, t = _real(xi0, "xi0"), _real(t, "t")
        if xi0.shape != (dim,) or not np.all(np.isfinite(xi0)):
            raise ValueError(f"xi0 must be a finite body velocity of shape ({dim},); got {xi0.tolist()}")
        if t.ndim != 1 or not np.all(np.isfinite(t)):
            raise ValueError(f"t must be a 1-D array of finite times; got shape {t.shape}")
        u = np.asarray(self.net(jnp.asarray(xi0), jnp.asarray(t)))
        rel = group.project(jnp.asarray(u[:, : group.size]))
        return np.asarray(group.compose(jnp.asarray(g0), rel)), u[:, group.size :]


def _real(value: ArrayLike, name: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be real numbers; got {type(value).__name__}") from err
