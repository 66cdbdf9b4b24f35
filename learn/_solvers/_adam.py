"""Gradient training (optax Adam), compiled in chunks of epochs: the `Adam` stage of `learn.fit`.

Each chunk of `CHUNK` epochs is one jitted `lax.scan` and one step of the shared loop
(`learn.AbstractSolver`); the best-validation weights are tracked inside the scan, so no epoch
is lost between host synchronisations, and offered to the loop's best so far after each chunk.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from liepoisson import common_path_first
from liepoisson.internals import positive_float, positive_int

from .. import _files
from ._compiled import AbstractAtStructure, compiled
from ._loop import AbstractSolver, Step
from ._problem import AbstractProblem
from ._stage import Context

CHUNK = 1000


def _where(cond, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(cond, a, b), new, old)


def _with_key(run: Any, base_key: jax.Array, carry: Any, epoch_ids: jax.Array, train: Any, val: Any) -> Any:
    return run(carry, epoch_ids, train, val, base_key)


def _samples(args: Any) -> int:
    return int(jax.tree_util.tree_leaves(args)[0].shape[0])


def _take(args: Any, index: jax.Array) -> Any:
    """The samples `index` of every leaf of `args` (samples on axis 0)."""
    return jax.tree_util.tree_map(lambda a: a[index], args)


@dataclasses.dataclass
class _State:
    """Where an Adam run is: the carry of its compiled chunks (weights, optimiser state, and
    the best weights, loss and epoch so far, tracked inside the scan so that no epoch is lost
    between host synchronisations), the epochs done, the chunk function and the data."""

    carry: Any
    epoch: int
    run: Any
    train: Any
    val: Any
    static: Any


@dataclasses.dataclass(frozen=True)
class Adam(AbstractSolver):
    r"""Adam (optax) on the training loss, compiled in chunks of epochs (one chunk a step of the
    shared loop); keeps the weights of the lowest validation loss (training loss without a
    validation set), the start's included.

    `epochs`; `learning_rate`, and `final_learning_rate` for an exponential decay from one to
    the other over all steps (constant if `None`); `batch_size` `None` for full batch, else
    seeded shuffled mini-batches (remainder dropped per epoch); `log_every`: history resolution
    in epochs (default `epochs // 1000`). Resumable with a `learn.Checkpoint`.
    """

    epochs: int = 100_000
    learning_rate: float = 1e-3
    final_learning_rate: float | None = None
    batch_size: int | None = None
    log_every: int | None = None
    resumable: ClassVar[bool] = True
    keeps_best: ClassVar[bool] = True
    unit: ClassVar[str] = "epoch"

    def __post_init__(self):
        positive_int(self.epochs, "Adam.epochs")
        positive_float(self.learning_rate, "Adam.learning_rate")
        if self.final_learning_rate is not None:
            positive_float(self.final_learning_rate, "Adam.final_learning_rate")
        if self.batch_size is not None:
            positive_int(self.batch_size, "Adam.batch_size")
        if self.log_every is not None:
            positive_int(self.log_every, "Adam.log_every")

    @property
    def budget(self) -> int:
        return self.epochs

    def with_budget(self, budget: int) -> Adam:
        return dataclasses.replace(self, epochs=budget)

    @property
    def _log_every(self) -> int:
        return self.log_every if self.log_every is not None else max(1, self.epochs // 1000)

    def file_settings(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "log_every": self._log_every}

    def init(self, problem: AbstractProblem, context: Context) -> Any:
        objective, epochs = problem.objective, self.epochs
        train = jax.tree_util.tree_map(jnp.asarray, problem.train)
        val = jax.tree_util.tree_map(jnp.asarray, problem.validation) if problem.has_validation else train
        n = _samples(train)
        has_val = problem.has_validation
        full = self.batch_size is None or self.batch_size >= n
        bs = n if full else int(self.batch_size)
        nb = 1 if full else n // bs
        if self.final_learning_rate is None:
            schedule: Any = self.learning_rate
        else:
            schedule = optax.exponential_decay(self.learning_rate, transition_steps=epochs * nb,
                                               decay_rate=self.final_learning_rate / self.learning_rate)
        opt = optax.adam(schedule)
        params, static = eqx.partition(problem.y0, eqx.is_inexact_array)

        def build():
            def loss(p, args):
                return objective(eqx.combine(p, static), args)

            def run(carry, epoch_ids, train, val, base_key):
                def body(carry, epoch):
                    p, s, bp, bl, be = carry
                    active = epoch < epochs
                    if full:
                        lt, g = jax.value_and_grad(loss)(p, train)
                        upd, s2 = opt.update(g, s, p)
                        p2 = optax.apply_updates(p, upd)
                    else:
                        lt = loss(p, train)
                        perm = jax.random.permutation(jax.random.fold_in(base_key, epoch), n)
                        batches = perm[: nb * bs].reshape(nb, bs)

                        def inner(c, idx):
                            pp, ss = c
                            g = jax.grad(loss)(pp, _take(train, idx))
                            u, ss = opt.update(g, ss, pp)
                            return (optax.apply_updates(pp, u), ss), None

                        (p2, s2), _ = jax.lax.scan(inner, (p, s), batches)
                    lv = loss(p, val) if has_val else jnp.asarray(jnp.nan)
                    crit = lv if has_val else lt
                    better = active & (crit < bl)
                    bp = _where(better, p, bp)
                    bl = jnp.where(better, crit, bl)
                    be = jnp.where(better, epoch, be)
                    p = _where(active, p2, p)
                    s = _where(active, s2, s)
                    return (p, s, bp, bl, be), (lt, lv)

                return jax.lax.scan(body, carry, epoch_ids)

            # A chunk whose losses are not all finite is run again from the same state with every
            # path of `expm_action` (exact either way); if it is still not finite, the loop stops.
            return common_path_first(
                run, lambda out: bool(np.all(np.isfinite(out[1][0])) and (not has_val or np.all(np.isfinite(out[1][1]))))
            )

        # Compiled once per structure, objective, settings and data size, not once per fit (a
        # sweep over seeds compiles its chunk once); the seed's key is an input.
        run = compiled(("adam", AbstractAtStructure(objective, problem.y0), self, n, has_val), build)
        base_key = jax.random.PRNGKey(context.seed)
        # Strongly typed (not weak Python scalars): the carry's types are those the scan returns,
        # so every chunk reuses the first chunk's compilation.
        carry = (params, opt.init(params), params, jnp.asarray(jnp.inf, dtype=float), jnp.asarray(-1, dtype=int))
        return _State(carry, 0, functools.partial(_with_key, run, base_key), train, val, static)

    def resume(self, problem: AbstractProblem, context: Context, state: Any, attrs: dict[str, Any],
               groups: dict[str, Any], weights: Any) -> Any:
        _, opt_state, *_ = state.carry
        params = eqx.filter(weights, eqx.is_inexact_array)
        best = eqx.filter(_files.replace_array_leaves(problem.y0, groups["best"], "best"), eqx.is_inexact_array)
        opt_state = _files.replace_array_leaves(opt_state, groups["optimizer"], "optimizer")
        state.carry = (params, opt_state, best, jnp.asarray(attrs["best_loss"], dtype=float),
                       jnp.asarray(int(attrs["best_epoch"]), dtype=int))
        state.epoch = int(attrs["epoch"])
        return state

    def optimizer_leaves(self, state: Any) -> list[Any]:
        return _files.array_leaves(state.carry[1])

    def step(self, problem: AbstractProblem, state: Any) -> tuple[Any, Step]:
        epoch, epochs = state.epoch, self.epochs
        chunk = min(CHUNK, epochs)
        state.carry, (lt, lv) = state.run(state.carry, jnp.arange(epoch, epoch + chunk), state.train, state.val)
        k = min(chunk, epochs - epoch)
        lt, lv = np.asarray(lt)[:k], np.asarray(lv)[:k]
        e = np.arange(epoch, epoch + k)
        keep = (e % self._log_every == 0) | (e == epochs - 1)
        state.epoch += k
        _, _, bp, bl, be = state.carry
        stop = ""
        if not np.all(np.isfinite(lt)):
            bad = int(e[np.argmax(~np.isfinite(lt))])
            stop = f"non-finite training loss at epoch {bad}; kept the best weights before it"
        return state, Step(k, e[keep], lt[keep], lv[keep], (eqx.combine(bp, state.static), float(bl), int(be)), stop,
                           (float(lt[-1]), float(lv[-1])))

    def current(self, state: Any) -> Any:
        return eqx.combine(state.carry[0], state.static)

    def final_candidate(self, problem: AbstractProblem, state: Any, done: int) -> tuple[Any, float, int]:
        # The weights after the last update were never scored inside the scan. The losses are
        # those compiled once per structure (`AbstractProblem.losses`), shared with the stages.
        y = self.current(state)
        return y, problem.losses(y).selection, state.epoch

    def postprocess(self, problem: AbstractProblem, state: Any, best: Any, stopped: str):
        if best is None or not np.isfinite(best[1]):
            raise FloatingPointError(f"training diverged: no finite loss ({stopped or 'all epochs'})")
        return best[0], {"best_epoch": int(best[2]), "stopped": stopped}, None
