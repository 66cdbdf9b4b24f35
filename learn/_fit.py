"""Argument checks and the shared `fit` of the gradient-trained maps (LPNet, MLPBaseline)."""

from __future__ import annotations

import os
from typing import Any

from ._data import prepare
from ._training import train_adam
from ._validation import positive_float, positive_int


def fit_gradient(
    model,
    data,
    *,
    epochs,
    learning_rate,
    final_learning_rate,
    batch_size,
    validation_fraction,
    seed,
    loss,
    h,
    checkpoint,
    resume,
    progress,
    log_every,
    checkpoint_every,
    normalise=False,
    losses: tuple[str, ...],
    build: Any,
):
    """Validate the arguments, prepare the data, let `build(model, pairs, loss)` return
    `(model_ready, train, val, loss_fn)`, train, and attach the record."""
    from ._base import TrainingRecord, replace

    epochs = positive_int(epochs, "epochs")
    learning_rate = positive_float(learning_rate, "learning_rate")
    if final_learning_rate is not None:
        final_learning_rate = positive_float(final_learning_rate, "final_learning_rate")
    if batch_size is not None:
        batch_size = positive_int(batch_size, "batch_size")
    if loss not in losses:
        raise ValueError(f"loss must be one of {list(losses)}; got {loss!r}")
    if log_every is None:
        log_every = max(1, epochs // 1000)
    log_every = positive_int(log_every, "log_every")
    checkpoint_every = positive_int(checkpoint_every, "checkpoint_every")
    if checkpoint is not None:
        checkpoint = os.fspath(checkpoint)
    if resume and checkpoint is None:
        raise ValueError("resume=True needs checkpoint='path.h5'")
    pairs = prepare(data, model.system, h, validation_fraction, seed)
    model, train, val, loss_fn = build(model, pairs, loss, bool(normalise))
    settings = {
        "epochs": epochs,
        "learning_rate": learning_rate,
        "final_learning_rate": final_learning_rate,
        "batch_size": batch_size,
        "validation_fraction": float(validation_fraction),
        "seed": int(seed),
        "loss": loss,
        "normalise": bool(normalise),
        "h": pairs.h,
        "n_train": int(train[0].shape[0]),
        "n_val": int(val[0].shape[0]),
    }
    best, info = train_adam(
        model,
        train,
        val,
        loss_fn,
        epochs=epochs,
        learning_rate=learning_rate,
        final_learning_rate=final_learning_rate,
        batch_size=batch_size,
        seed=seed,
        progress=progress,
        log_every=log_every,
        checkpoint=checkpoint,
        checkpoint_every=checkpoint_every,
        resume=resume,
        settings=settings,
        desc=type(model).__name__,
    )
    record = TrainingRecord(
        info["history"],
        info["train_loss"],
        info["val_loss"],
        info["wall_time_s"],
        {**settings, "best_epoch": info["best_epoch"], "epochs_run": info["epochs"], "stopped": info["stopped"]},
    )
    return replace(best, record=record)
