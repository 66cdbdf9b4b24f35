"""Gradient training (optax Adam) of a learned map, compiled in chunks of epochs.

Each chunk of `CHUNK` epochs is one jitted `lax.scan`; the best-validation weights are
tracked inside the scan, so no epoch is lost between host synchronisations.
"""

from __future__ import annotations

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
from liepoisson.systems import check_system_matches

from .. import _files as _checkpoint
from .._models._legacy import upgrade_attributes

CHUNK = 1000


def _where(cond, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(cond, a, b), new, old)


def train_adam(
    model: Any,
    train: tuple[np.ndarray, np.ndarray],
    val: tuple[np.ndarray, np.ndarray],
    loss_fn: Callable[[Any, jax.Array, jax.Array], jax.Array],
    *,
    epochs: int,
    learning_rate: float,
    final_learning_rate: float | None,
    batch_size: int | None,
    seed: int,
    progress: bool,
    log_every: int,
    checkpoint: str | None,
    checkpoint_every: int,
    resume: bool,
    settings: dict[str, Any],
    desc: str,
    on_chunk: Callable[[int, float, float], None] | None = None,
):
    """Minimise `loss_fn(model, inputs, targets)` (a mean over samples) with Adam.

    `on_chunk(epochs_done, train_loss, val_loss)` is called after every compiled chunk.
    Returns `(best_model, info)`: the weights with the lowest validation loss (training loss
    when there is no validation set) and a dict with the history and timings.
    """
    X, T = (jnp.asarray(a) for a in train)
    Xv, Tv = (jnp.asarray(a) for a in val)
    n = X.shape[0]
    has_val = Xv.shape[0] > 0
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

    def loss(p, x, t):
        return loss_fn(eqx.combine(p, static), x, t)

    opt_state = opt.init(params)
    best = params
    best_loss = jnp.asarray(jnp.inf)
    best_epoch = jnp.asarray(-1)
    epoch0, elapsed0 = 0, 0.0
    hist: dict[str, list] = {"epoch": [], "train_loss": [], "val_loss": []}

    if checkpoint is not None and resume and os.path.exists(checkpoint):
        attrs, groups = read_resumable(checkpoint, model, settings)
        params = eqx.filter(_checkpoint.replace_array_leaves(params, groups["weights"], "weights"), eqx.is_array)
        best = eqx.filter(_checkpoint.replace_array_leaves(params, groups["best"], "best"), eqx.is_array)
        opt_state = _checkpoint.replace_array_leaves(opt_state, groups["optimizer"], "optimizer")
        epoch0 = int(attrs["epoch"])
        best_loss = jnp.asarray(attrs["best_loss"])
        best_epoch = jnp.asarray(int(attrs["best_epoch"]))
        elapsed0 = float(attrs["elapsed_s"])
        hist = {k: list(v) for k, v in groups["history"].items()}

    base_key = jax.random.PRNGKey(seed)
    chunk = min(CHUNK, epochs)

    def run(carry, epoch_ids, X, T, Xv, Tv):
        def body(carry, epoch):
            p, s, bp, bl, be = carry
            active = epoch < epochs
            if full:
                lt, g = jax.value_and_grad(loss)(p, X, T)
                upd, s2 = opt.update(g, s, p)
                p2 = optax.apply_updates(p, upd)
            else:
                lt = loss(p, X, T)
                perm = jax.random.permutation(jax.random.fold_in(base_key, epoch), n)
                batches = perm[: nb * bs].reshape(nb, bs)

                def inner(c, idx):
                    pp, ss = c
                    g = jax.grad(loss)(pp, X[idx], T[idx])
                    u, ss = opt.update(g, ss, pp)
                    return (optax.apply_updates(pp, u), ss), None

                (p2, s2), _ = jax.lax.scan(inner, (p, s), batches)
            lv = loss(p, Xv, Tv) if has_val else jnp.asarray(jnp.nan)
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

    @jax.jit
    def evaluate(p, X, T):
        return loss(p, X, T)

    def write_checkpoint(carry, epoch, elapsed):
        p, s, bp, bl, be = carry
        _checkpoint.write(
            checkpoint,
            {
                **{k: v for k, v in model_attrs.items()},
                "epoch": int(epoch),
                "best_loss": float(bl),
                "best_epoch": int(be),
                "elapsed_s": float(elapsed),
                "fit_settings": settings,
            },
            {
                "weights": _checkpoint.array_leaves(p),
                "best": _checkpoint.array_leaves(bp),
                "optimizer": _checkpoint.array_leaves(s),
                "history": {k: np.asarray(v) for k, v in hist.items()},
            },
        )

    model_attrs = model.file_attributes() if checkpoint is not None else {}
    carry = (params, opt_state, best, best_loss, best_epoch)
    start = time.perf_counter()
    epoch = epoch0
    last_checkpoint = epoch0
    stopped = ""
    bar = tqdm(total=epochs, initial=epoch0, disable=not progress, desc=desc, unit="epoch", leave=False)
    try:
        while epoch < epochs:
            ids = jnp.arange(epoch, epoch + chunk)
            carry, (lt, lv) = run(carry, ids, X, T, Xv, Tv)
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
    # The weights after the last update were never scored inside the scan.
    final_crit = evaluate(p, Xv, Tv) if has_val else evaluate(p, X, T)
    if bool(final_crit < bl):
        bp, bl, be = p, final_crit, jnp.asarray(epoch)
        carry = (p, s, bp, bl, be)
    wall = elapsed0 + time.perf_counter() - start
    if checkpoint is not None:
        write_checkpoint(carry, epoch, wall)
    if not np.isfinite(float(bl)):
        raise FloatingPointError(f"training diverged: no finite loss ({stopped or 'all epochs'})")
    best_model = eqx.combine(bp, static)
    info = {
        "history": {k: np.asarray(v) for k, v in hist.items()},
        "train_loss": float(evaluate(bp, X, T)),
        "val_loss": float(evaluate(bp, Xv, Tv)) if has_val else float("nan"),
        "wall_time_s": wall,
        "best_epoch": int(be),
        "epochs": int(epoch),
        "stopped": stopped,
    }
    return best_model, info


def read_resumable(path: str, model: Any, settings: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """`read_checkpoint` for resuming the fit of `model` with fit `settings`: `ValueError` if
    the file was written for another system, architecture or settings."""
    attrs, groups = _checkpoint.read_checkpoint(path, type(model).__name__, upgrade_attributes)
    try:
        check_system_matches(model.system, attrs.get("system"), attrs.get("system_params"), f"checkpoint {path!r}")
    except ValueError as err:
        raise ValueError(f"cannot resume: {err}") from None
    if attrs["hyperparameters"] != _checkpoint.jsonable(model.hyperparameters()):
        raise ValueError(
            f"checkpoint {path!r} was written for a model with hyperparameters "
            f"{attrs['hyperparameters']}; this model has {model.hyperparameters()}"
        )
    for key, value in _checkpoint.jsonable(settings).items():
        if attrs["fit_settings"].get(key) != value:
            raise ValueError(
                f"checkpoint {path!r} was written with {key}={attrs['fit_settings'].get(key)!r}; "
                f"resume needs the same value, got {key}={value!r}"
            )
    return attrs, groups
