r"""What the MLP-based learned maps (`LPNet`, `MLPBaseline`) share: a network
$s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$ with fixed affine
scalings, and gradient training (`fit`)."""

from __future__ import annotations

import abc
import os
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap, TrainingRecord, replace
from ._data import PairData, prepare
from ._mlp import MLP, affine, as_key, check_activation, check_hidden
from ._quasi_newton import check_method
from ._training import refine, train_adam
from ._validation import positive_float, positive_int

if TYPE_CHECKING:  # typing.Self needs Python 3.11
    from typing_extensions import Self

_SCALINGS = ("input_shift", "input_scale", "output_shift", "output_scale")


class AbstractMLPMap(AbstractLearnedMap):
    r"""A learned map built on $N(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in})
    + m_\text{out}$, with scalings $m, s$ fixed (not trained): the identity unless the first
    `fit` is called with `normalise=True`.

    Subclasses call `_init_network` from their `__init__`, define `_step` from `_network`,
    name the losses their `fit` accepts (`_losses`), add their own hyperparameters, rebuild
    a skeleton (`_skeleton`, ending with `_restore_scalings`) and turn the data into training inputs,
    targets and a loss (`_build`).
    """

    mlp: MLP
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None = eqx.field(static=True)
    input_shift: tuple[float, ...] = eqx.field(static=True)
    input_scale: tuple[float, ...] = eqx.field(static=True)
    output_shift: tuple[float, ...] = eqx.field(static=True)
    output_scale: tuple[float, ...] = eqx.field(static=True)
    hidden: tuple[int, ...] = eqx.field(static=True)
    record: TrainingRecord | None = eqx.field(static=True)

    _losses: eqx.AbstractClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def _build(self, pairs: PairData, loss: str, set_scalings: bool):
        """`(model, (inputs, targets), (inputs_val, targets_val), loss_fn)` for `fit`; the
        model has its scalings set from `pairs` (`_with_scalings`) when `set_scalings`."""

    def _init_network(self, hidden: Any, activation: Any, key: Any, h: Any, out_size: int) -> None:
        """Set the untrained network and the identity scalings (`self.system` is set)."""
        self.hidden = check_hidden(hidden)
        n = self.system.dim
        self.mlp = MLP(n, out_size, self.hidden, check_activation(activation), as_key(key))
        self.h = None if h is None else positive_float(h, "h")
        self.input_shift, self.input_scale = (0.0,) * n, (1.0,) * n
        self.output_shift, self.output_scale = (0.0,) * out_size, (1.0,) * out_size
        self.record = None

    @property
    def activation(self) -> str:
        return self.mlp.activation

    def _network(self, y: jax.Array) -> jax.Array:
        """$N(y)$ for one sample `(dim,)`."""
        x = (y - jnp.asarray(self.input_shift)) / jnp.asarray(self.input_scale)
        return jnp.asarray(self.output_shift) + jnp.asarray(self.output_scale) * self.mlp(x)

    def _with_scalings(self, inputs: Any, outputs: Any) -> Self:
        """A copy whose scalings are the mean/std of sample `inputs` and `outputs`."""
        in_shift, in_scale = affine(inputs, len(self.input_shift))
        out_shift, out_scale = affine(outputs, len(self.output_shift))
        return replace(self, input_shift=in_shift, input_scale=in_scale, output_shift=out_shift,
                       output_scale=out_scale)

    @abc.abstractmethod
    def _own_hyperparameters(self) -> dict[str, Any]:
        """The subclass's hyperparameters besides the network's and the scalings."""

    def hyperparameters(self):
        return {
            "hidden": list(self.hidden),
            "activation": self.activation,
            **self._own_hyperparameters(),
            **{name: list(getattr(self, name)) for name in _SCALINGS},
        }

    def _restore_scalings(self, hp: dict[str, Any]) -> Self:
        """This skeleton with the scalings stored in `hp`."""
        return replace(self, **{name: tuple(hp[name]) for name in _SCALINGS})

    def fit(
        self,
        data: Any,
        epochs: int = 100_000,
        learning_rate: float = 1e-3,
        final_learning_rate: float | None = None,
        batch_size: int | None = None,
        validation_fraction: float = 0.2,
        seed: int = 0,
        loss: str = "state",
        h: float | None = None,
        checkpoint: Any = None,
        resume: bool = False,
        progress: bool = True,
        log_every: int | None = None,
        checkpoint_every: int = 10_000,
        normalise: bool = False,
        refine_iterations: int = 0,
        refine_method: str = "lbfgsb",
    ) -> Self:
        r"""Train on data pairs; returns the fitted network (a new object) with the weights of
        the best validation loss, `.history`, `.train_loss`, `.val_loss`, `.h`, `.wall_time_s`.

        **Arguments:**

        - `data`: an `integrators.Trajectories`, or `(y0, y1)` arrays `(N, dim)` with `h`.
        - `epochs` of Adam (0: none, only the quasi-Newton refinement from the current
          weights); `learning_rate` and `final_learning_rate` (Adam with exponential decay
          from one to the other over all steps; constant if `final_learning_rate` is None).
        - `batch_size`: None for full batch, else seeded shuffled mini-batches (remainder dropped
          per epoch).
        - `validation_fraction` of the pairs held out (random, seeded by `seed`).
        - `loss`: `"state"` (default, the paper's: MSE between the
          step of $y_0$ and $y_1$; for an LPNet $\mathbb T(\alpha(y_0))y_0$, through the exact
          flow) or, LPNet only, `"alpha"` (MSE between $\alpha(y_0)$ and
          `parametrisation.params_from_pair(y0, y1, h)`, divided by the output scale).
        - `checkpoint`: HDF5 path written every `checkpoint_every` epochs and at the end;
          `resume=True` continues from it (epoch, optimiser state, best weights).
        - `progress`: tqdm bar with the losses; `log_every`: history resolution in epochs
          (default epochs // 1000).
        - `normalise`: on the first fit, set the fixed input/output scalings from the
          training data (True) or keep the identity (False, default: a plain MLP as in the
          paper). Inputs: mean/std of $y_0$; outputs: of the pairs' parameters (LPNet) or of
          $y_1 - y_0$ (MLPBaseline). On E1 normalising an LPNet reaches a lower loss (1.6e-11
          vs 3-4e-11 after 1e5 epochs) but the 10,000-step rollout drifts more in energy
          (2e-3..0.6 vs 4e-4..7e-4).
        - `refine_iterations`: after Adam, minimise the full-batch training loss further with
          a quasi-Newton method (`refine_method`: `"lbfgsb"`, SciPy L-BFGS-B, default;
          `"bfgs"`; `"lbfgs"`, optax) for this many iterations, starting from the
          best-validation weights; the refined weights are kept only if their validation loss
          is lower. The history continues past `epochs` with one entry per iteration
          (validation loss NaN). Adam's checkpoint does not cover this stage: a resumed fit
          repeats it. Default 0 (Adam only, as in the paper). On E2 (`python -m paper run E2
          --full`, seeds 0-2, 1e5 Adam epochs) 30,000 L-BFGS-B iterations take the MSE from
          3.0e-10..5.9e-10 to 4.8e-13..9.5e-13 and the 10,000-step energy error of the LPNet
          from 3.5e-3..7.8e-3 to 1.5e-5..1.1e-3.
        """
        epochs = positive_int(epochs, "epochs", minimum=0)
        learning_rate = positive_float(learning_rate, "learning_rate")
        if final_learning_rate is not None:
            final_learning_rate = positive_float(final_learning_rate, "final_learning_rate")
        if batch_size is not None:
            batch_size = positive_int(batch_size, "batch_size")
        if loss not in self._losses:
            raise ValueError(f"loss must be one of {list(self._losses)}; got {loss!r}")
        if log_every is None:
            log_every = max(1, epochs // 1000)
        log_every = positive_int(log_every, "log_every")
        checkpoint_every = positive_int(checkpoint_every, "checkpoint_every")
        refine_iterations = positive_int(refine_iterations, "refine_iterations", minimum=0)
        refine_method = check_method(refine_method)
        if epochs == 0 and refine_iterations == 0:
            raise ValueError("epochs=0 and refine_iterations=0 leave nothing to train; give epochs >= 1 "
                             "(Adam) or refine_iterations >= 1 (quasi-Newton from the current weights)")
        if checkpoint is not None:
            checkpoint = os.fspath(checkpoint)
        if resume and checkpoint is None:
            raise ValueError("resume=True needs checkpoint='path.h5'")
        pairs = prepare(data, self.system, h, validation_fraction, seed)
        # Scalings are set on the first fit only, so that a refit keeps the same network.
        model, train, val, loss_fn = self._build(pairs, loss, bool(normalise) and self.record is None)
        model = replace(model, h=pairs.h)
        settings = {
            "epochs": epochs,
            "learning_rate": learning_rate,
            "final_learning_rate": final_learning_rate,
            "batch_size": batch_size,
            "validation_fraction": float(validation_fraction),
            "seed": int(seed),
            "loss": loss,
            "normalise": bool(normalise),
            "refine_iterations": refine_iterations,
            "refine_method": refine_method,
            "h": pairs.h,
            "n_train": int(train[0].shape[0]),
            "n_val": int(val[0].shape[0]),
        }
        if epochs == 0:
            best, info = model, _no_adam(model, train, val, loss_fn)
        else:
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
                # the refinement runs after Adam: a checkpoint resumes whatever refinement follows
                settings={k: v for k, v in settings.items() if not k.startswith("refine")},
                desc=type(model).__name__,
            )
        extra = {"best_epoch": info["best_epoch"], "epochs_run": info["epochs"], "stopped": info["stopped"]}
        history, wall = info["history"], info["wall_time_s"]
        train_loss, val_loss = info["train_loss"], info["val_loss"]
        if refine_iterations:
            best, ref = refine(best, train, val, loss_fn, iterations=refine_iterations, method=refine_method,
                               progress=progress, desc=f"{type(model).__name__} {refine_method}")
            n = ref["iterations"]
            history = {
                "epoch": np.concatenate([history["epoch"], info["epochs"] + np.arange(1, n + 1)]),
                "train_loss": np.concatenate([history["train_loss"], ref["history"]["train_loss"]]),
                "val_loss": np.concatenate([history["val_loss"], np.full(n, np.nan)]),
            }
            wall += ref["wall_time_s"]
            extra.update(
                refine_iterations_run=n, refine_kept=ref["kept"], train_loss_before_refine=train_loss, val_loss_before_refine=val_loss,
                adam_wall_time_s=info["wall_time_s"], refine_wall_time_s=ref["wall_time_s"],
            )
            if ref["kept"]:
                train_loss = float(loss_fn(best, jnp.asarray(train[0]), jnp.asarray(train[1])))
                val_loss = ref["criterion_after"] if val[0].shape[0] else float("nan")
        record = TrainingRecord(history, train_loss, val_loss, wall, {**settings, **extra})
        return replace(best, record=record)


def _no_adam(model, train, val, loss_fn) -> dict[str, Any]:
    """`train_adam`'s info for zero epochs: the losses of `model` as it is."""
    X, T = (jnp.asarray(a) for a in train)
    has_val = val[0].shape[0] > 0
    return {
        "history": {"epoch": np.zeros(0, int), "train_loss": np.zeros(0), "val_loss": np.zeros(0)},
        "train_loss": float(loss_fn(model, X, T)),
        "val_loss": float(loss_fn(model, jnp.asarray(val[0]), jnp.asarray(val[1]))) if has_val else float("nan"),
        "wall_time_s": 0.0,
        "best_epoch": -1,
        "epochs": 0,
        "stopped": "",
    }
