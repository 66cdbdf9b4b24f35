"""Gradient training (optax Adam), compiled in chunks of epochs: the `Adam` stage of `learn.fit`.

Each chunk of `CHUNK` epochs is one jitted `lax.scan`; the best-validation weights are
tracked inside the scan, so no epoch is lost between host synchronisations.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from tqdm.auto import tqdm

from liepoisson import common_path_first
from liepoisson.internals import positive_float, positive_int

from .. import _files
from ._checkpoint import read_resumable
from ._problem import AbstractProblem
from ._record import StageRecord
from ._stage import AbstractResumableStage, Context, Result

CHUNK = 1000


def _where(cond, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(cond, a, b), new, old)


def _samples(args: Any) -> int:
    return int(jax.tree_util.tree_leaves(args)[0].shape[0])


def _take(args: Any, index: jax.Array) -> Any:
    """The samples `index` of every leaf of `args` (samples on axis 0)."""
    return jax.tree_util.tree_map(lambda a: a[index], args)


@dataclasses.dataclass(frozen=True)
class Adam(AbstractResumableStage):
    r"""Adam (optax) on the training loss, compiled in chunks of epochs; keeps the weights of
    the lowest validation loss (training loss without a validation set).

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

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        log_every = self.log_every if self.log_every is not None else max(1, self.epochs // 1000)
        settings = {**context.file_settings, **dataclasses.asdict(self), "log_every": log_every}
        report = context.report
        best, info = train_adam(
            problem, epochs=self.epochs, learning_rate=self.learning_rate,
            final_learning_rate=self.final_learning_rate, batch_size=self.batch_size, seed=context.seed,
            progress=context.progress, log_every=log_every, checkpoint=context.checkpoint, settings=settings,
            desc=context.desc or problem.name,
            on_chunk=None if report is None else lambda done, lt, lv: report(context.offset + done, context.total,
                                                                             lt, lv),
        )
        record = StageRecord(
            optimiser="Adam", settings=dataclasses.asdict(self), iterations=info["epochs"],
            train_loss=info["train_loss"], val_loss=info["val_loss"], kept=True, wall_time_s=info["wall_time_s"],
            details={"best_epoch": info["best_epoch"], "stopped": info["stopped"]},
        )
        return Result(best, record, info["history"])


def train_adam(
    problem: AbstractProblem,
    *,
    epochs: int,
    learning_rate: float,
    final_learning_rate: float | None,
    batch_size: int | None,
    seed: int,
    progress: bool,
    log_every: int,
    checkpoint: Any,
    settings: dict[str, Any],
    desc: str,
    on_chunk: Callable[[int, float, float], None] | None = None,
):
    """Minimise the problem's objective (a mean over samples) with Adam.

    `on_chunk(epochs_done, train_loss, val_loss)` is called after every compiled chunk.
    Returns `(best, info)`: the `y` with the lowest validation loss (training loss when there
    is no validation set) and a dict with the history and timings.
    """
    objective, model = problem.objective, problem.y0
    train = jax.tree_util.tree_map(jnp.asarray, problem.train)
    val = jax.tree_util.tree_map(jnp.asarray, problem.validation) if problem.has_validation else train
    n = _samples(train)
    has_val = problem.has_validation
    full = batch_size is None or batch_size >= n
    bs = n if full else int(batch_size)
    nb = 1 if full else n // bs
    if final_learning_rate is None:
        schedule: Any = learning_rate
    else:
        schedule = optax.exponential_decay(
            learning_rate, transition_steps=epochs * nb, decay_rate=final_learning_rate / learning_rate
        )
    opt = optax.adam(schedule)
    params, static = eqx.partition(model, eqx.is_inexact_array)

    def loss(p, args):
        return objective(eqx.combine(p, static), args)

    opt_state = opt.init(params)
    best = params
    # Strongly typed (not weak Python scalars): the carry's types are those the scan returns,
    # so every chunk reuses the first chunk's compilation.
    best_loss = jnp.asarray(jnp.inf, dtype=float)
    best_epoch = jnp.asarray(-1, dtype=int)
    epoch0, elapsed0 = 0, 0.0
    hist: dict[str, list] = {"epoch": [], "train_loss": [], "val_loss": []}

    path = None if checkpoint is None else os.fspath(checkpoint.path)
    checkpoint_every = 10_000 if checkpoint is None else checkpoint.every
    if checkpoint is not None and checkpoint.resumable():
        attrs, groups = read_resumable(path, problem, settings)
        params = eqx.filter(_files.replace_array_leaves(params, groups["weights"], "weights"), eqx.is_array)
        best = eqx.filter(_files.replace_array_leaves(params, groups["best"], "best"), eqx.is_array)
        opt_state = _files.replace_array_leaves(opt_state, groups["optimizer"], "optimizer")
        epoch0 = int(attrs["epoch"])
        best_loss = jnp.asarray(attrs["best_loss"], dtype=float)
        best_epoch = jnp.asarray(int(attrs["best_epoch"]), dtype=int)
        elapsed0 = float(attrs["elapsed_s"])
        hist = {k: list(v) for k, v in groups["history"].items()}

    base_key = jax.random.PRNGKey(seed)
    chunk = min(CHUNK, epochs)

    def run(carry, epoch_ids, train, val):
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

    # A chunk whose losses are not all finite is run again from the same state with every path
    # of `expm_action` (exact either way); if it is still not finite, the check below stops.
    run = common_path_first(
        run, lambda out: bool(np.all(np.isfinite(out[1][0])) and (not has_val or np.all(np.isfinite(out[1][1]))))
    )

    def write_checkpoint(carry, epoch, elapsed):
        p, s, bp, bl, be = carry
        _files.write(
            path,
            {
                **{k: v for k, v in model_attrs.items()},
                "epoch": int(epoch),
                "best_loss": float(bl),
                "best_epoch": int(be),
                "elapsed_s": float(elapsed),
                "fit_settings": settings,
            },
            {
                "weights": _files.array_leaves(p),
                "best": _files.array_leaves(bp),
                "optimizer": _files.array_leaves(s),
                "history": {k: np.asarray(v) for k, v in hist.items()},
            },
        )

    model_attrs = problem.file_attributes() if checkpoint is not None else {}
    carry = (params, opt_state, best, best_loss, best_epoch)
    start = time.perf_counter()
    epoch = epoch0
    last_checkpoint = epoch0
    stopped = ""
    bar = tqdm(total=epochs, initial=epoch0, disable=not progress, desc=desc, unit="epoch", leave=False)
    try:
        while epoch < epochs:
            ids = jnp.arange(epoch, epoch + chunk)
            carry, (lt, lv) = run(carry, ids, train, val)
            k = min(chunk, epochs - epoch)
            lt, lv = np.asarray(lt)[:k], np.asarray(lv)[:k]
            e = np.arange(epoch, epoch + k)
            keep = (e % log_every == 0) | (e == epochs - 1)
            hist["epoch"].extend(e[keep].tolist())
            hist["train_loss"].extend(lt[keep].tolist())
            hist["val_loss"].extend(lv[keep].tolist())
            epoch += k
            bar.update(k)
            bar.set_postfix(train=f"{lt[-1]:.3g}", val=f"{lv[-1]:.3g}", best=f"{float(carry[3]):.3g}")
            if on_chunk is not None:
                on_chunk(epoch, float(lt[-1]), float(lv[-1]))
            if not np.all(np.isfinite(lt)):
                bad = int(e[np.argmax(~np.isfinite(lt))])
                stopped = f"non-finite training loss at epoch {bad}; kept the best weights before it"
                break
            if checkpoint is not None and epoch - last_checkpoint >= checkpoint_every and epoch < epochs:
                write_checkpoint(carry, epoch, elapsed0 + time.perf_counter() - start)
                last_checkpoint = epoch
    finally:
        bar.close()

    p, s, bp, bl, be = carry
    # The weights after the last update were never scored inside the scan. The losses are
    # those compiled once per structure (`AbstractProblem.losses`), shared with the stages.
    final = problem.losses(eqx.combine(p, static))
    if final.selection < float(bl):
        bp, bl, be = p, jnp.asarray(final.selection, dtype=float), jnp.asarray(epoch, dtype=int)
        carry = (p, s, bp, bl, be)
    wall = elapsed0 + time.perf_counter() - start
    if checkpoint is not None:
        write_checkpoint(carry, epoch, wall)
    if not np.isfinite(float(bl)):
        raise FloatingPointError(f"training diverged: no finite loss ({stopped or 'all epochs'})")
    best_model = eqx.combine(bp, static)
    losses = problem.losses(best_model)
    info = {
        "history": {k: np.asarray(v) for k, v in hist.items()},
        "train_loss": losses.train,
        "val_loss": losses.validation,
        "wall_time_s": wall,
        "best_epoch": int(be),
        "epochs": int(epoch),
        "stopped": stopped,
    }
    return best_model, info
