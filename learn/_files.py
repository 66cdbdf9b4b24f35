"""HDF5 model files and training checkpoints: attributes for hyperparameters, datasets for
weights (never pickle); written to a temporary file renamed into place."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from typing import Any

import equinox as eqx
import h5py
import jax
import jax.numpy as jnp
import numpy as np

from integrators.internals import atomic_path, open_hdf5

FORMAT = "learn-model"
#: 2: learned maps are composed (LPNet + network, Reversible, GLPNet + method); version 1
#: files (flags) are read by `_legacy.upgrade_attributes`.
FORMAT_VERSION = 2


def array_leaves(tree: Any) -> list[np.ndarray]:
    """The array leaves of a pytree (equinox model or optimiser state), in a fixed order."""
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(eqx.filter(tree, eqx.is_array))]


def replace_array_leaves(tree: Any, leaves: list[np.ndarray], what: str) -> Any:
    """`tree` with its array leaves replaced by `leaves` (checked for count, shape, dtype)."""
    dynamic, static = eqx.partition(tree, eqx.is_array)
    old, treedef = jax.tree_util.tree_flatten(dynamic)
    if len(old) != len(leaves):
        raise ValueError(f"{what}: the file holds {len(leaves)} arrays; the model expects {len(old)}")
    new = []
    for i, (o, n) in enumerate(zip(old, leaves)):
        if tuple(o.shape) != tuple(n.shape):
            raise ValueError(f"{what}: array {i} has shape {n.shape} in the file, {o.shape} expected")
        new.append(jnp.asarray(n, dtype=o.dtype))
    return eqx.combine(jax.tree_util.tree_unflatten(treedef, new), static)


def write(path: Any, attrs: dict[str, Any], groups: dict[str, Any]) -> None:
    """Write `attrs` (JSON-encoded when not scalar/str) and `groups` = {name: list of arrays or
    dict of arrays} atomically to `path`."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        for key, value in attrs.items():
            if isinstance(value, (str, int, float, bool, np.integer, np.floating)):
                f.attrs[key] = value
            else:
                f.attrs[key + "_json"] = json.dumps(value)
        for name, content in groups.items():
            g = f.create_group(name)
            if isinstance(content, dict):
                g.attrs["kind"] = "dict"
                for k, v in content.items():
                    g.create_dataset(k, data=np.asarray(v))
            else:
                g.attrs["kind"] = "list"
                g.attrs["count"] = len(content)
                for i, v in enumerate(content):
                    g.create_dataset(f"{i:04d}", data=np.asarray(v))


def read(path: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """`(attrs, groups)` as written by `write` (JSON attributes decoded)."""
    path = os.fspath(path)
    expected = "a learn model, checkpoint or training record file (written by .save or learn.fit)"
    f = open_hdf5(path, expected)
    try:
        with f:
            if f.attrs.get("format") != FORMAT:
                what = ("a trajectory data set (read it with integrators.Trajectories.load)"
                        if "trajectories" in f and "format_version" in f.attrs else "another kind of HDF5 file")
                raise ValueError(f"path {path!r} holds {what}; expected {expected}")
            attrs: dict[str, Any] = {}
            for key, value in f.attrs.items():
                if isinstance(value, bytes):
                    value = value.decode()
                if isinstance(value, np.generic):
                    value = value.item()
                if key.endswith("_json"):
                    key, value = key[: -len("_json")], json.loads(value)
                attrs[key] = value
            groups: dict[str, Any] = {}
            for name, g in f.items():
                if g.attrs["kind"] == "dict":
                    groups[name] = {k: np.asarray(v) for k, v in g.items()}
                else:
                    groups[name] = [np.asarray(g[f"{i:04d}"]) for i in range(int(g.attrs["count"]))]
    except ValueError as err:
        if str(err).startswith(f"path {path!r}"):
            raise
        raise ValueError(f"path {path!r} is damaged (corrupt HDF5 data or attributes): {err}") from err
    except (OSError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"path {path!r} is damaged (corrupt HDF5 data or attributes): {type(err).__name__}: {err}") from err
    return attrs, groups


# What `learn.fit` writes to a `Checkpoint` beside a model's `file_attributes()`.
CHECKPOINT_ATTRIBUTES = {
    "class": str, "system": str, "system_params": dict, "hyperparameters": dict, "fit_settings": dict,
    "epoch": int, "best_epoch": int, "best_loss": float, "elapsed_s": float,
}
CHECKPOINT_GROUPS = {"weights": list, "best": list, "optimizer": list, "history": dict}
HISTORY = ("epoch", "train_loss", "val_loss")


def read_checkpoint(
    path: str, class_name: str, upgrade: Callable[[dict[str, Any], str], dict[str, Any]] | None = None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """`(attrs, groups)` of a training checkpoint written by `learn.fit` for a `class_name`,
    the attributes passed through `upgrade(attrs, where)` (older format versions); `ValueError`
    naming the file and what is wrong: a model saved by `.save` (with how to start from it),
    another class, or a missing or mistyped attribute or group."""
    attrs, groups = read(path)
    if upgrade is not None:
        attrs = upgrade(attrs, f"checkpoint {path!r}")
    saved = attrs.get("class")
    if set(groups) == {"weights"} and not {"fit_settings", "epoch"} & set(attrs) and isinstance(saved, str):
        raise ValueError(
            f"checkpoint {path!r} is a saved model (written by {saved}.save), not a training "
            "checkpoint: it holds the weights but not the optimiser state, epoch and fit settings "
            "that resume needs. To start training from it, load it and fit with a new checkpoint "
            f"path: `model = learn.{saved}.load({path!r})`, then `learn.fit(model, data, ..., "
            "checkpoint=learn.Checkpoint(new_path, resume=True))`"
        )
    if saved is not None and saved != class_name:
        raise ValueError(f"checkpoint {path!r} holds a {saved}, not a {class_name}")
    missing = [f"attribute {k!r}" for k in CHECKPOINT_ATTRIBUTES if k not in attrs]
    missing += [f"group {k!r}" for k in CHECKPOINT_GROUPS if k not in groups]
    if missing:
        raise ValueError(
            f"checkpoint {path!r} is not a complete training checkpoint (as learn.fit writes with "
            f"learn.Checkpoint): missing {', '.join(missing)}"
        )
    for key, kind in CHECKPOINT_ATTRIBUTES.items():
        value = attrs[key]
        ok = isinstance(value, (int, float)) if kind is float else isinstance(value, kind)
        if not ok or isinstance(value, bool):
            raise ValueError(
                f"checkpoint {path!r} is damaged: attribute {key!r} must be a {kind.__name__}; "
                f"got {type(value).__name__} {value!r}"
            )
    for key, kind in CHECKPOINT_GROUPS.items():
        if not isinstance(groups[key], kind):
            raise ValueError(f"checkpoint {path!r} is damaged: group {key!r} must hold a {kind.__name__} of arrays")  # noqa: TRY004 (a damaged file)
    absent = [k for k in HISTORY if k not in groups["history"]]
    if absent:
        raise ValueError(f"checkpoint {path!r} is damaged: group 'history' lacks {', '.join(map(repr, absent))}")
    return attrs, groups
