"""Model files and checkpoints of format version 1 (learned maps configured by flags) read as
today's composed maps: the architecture is translated, the weights are the same arrays in the
same order."""

from __future__ import annotations

from typing import Any

from .._files import FORMAT_VERSION


def upgrade_attributes(attrs: dict[str, Any], where: str) -> dict[str, Any]:
    """`attrs` of a model file or checkpoint (as `_checkpoint.read` returns them) in today's
    form; `ValueError` naming the version for a file this code cannot read."""
    version = attrs.get("format_version", 1)
    if version == FORMAT_VERSION:
        return _method_with_ordering(attrs)
    if version != 1:
        raise ValueError(
            f"{where} has model format version {version!r}; this liepoisson reads versions 1 to {FORMAT_VERSION}: "
            "write it again with the version that made it, or train the model anew"
        )
    if not isinstance(attrs.get("hyperparameters"), dict):
        raise ValueError(f"{where} is a version-1 file without the hyperparameters of a learned map (damaged, or "  # noqa: TRY004 - an unfit value (file, data), not an argument of the wrong type
                         "not a model file)")
    hp = dict(attrs["hyperparameters"])
    old = cls = attrs.get("class")
    try:
        if cls == "LPNet":
            cls, hp = _lpnet_v1(hp)
        elif cls == "GLPNet":
            symmetric = hp.pop("symmetric", False)
            hp["method"] = {"name": "Strang" if symmetric else "LieTrotter", "ordering": None}
        elif cls == "MLPBaseline":
            hp = {"network": _affine_mlp(hp)}
    except (KeyError, TypeError, IndexError) as err:
        raise ValueError(
            f"{where} is a version-1 {old} file whose hyperparameters this liepoisson cannot read "
            f"({type(err).__name__}: {err}); train the model anew"
        ) from err
    return {**attrs, "class": cls, "hyperparameters": hp, "format_version": FORMAT_VERSION, "upgraded_from": old}


def _method_with_ordering(attrs: dict[str, Any]) -> dict[str, Any]:
    """A G-LPNet written before its method's ordering was recorded (`"method"`: a class name)
    as written today (`{"name": ..., "ordering": None}`): a checkpoint compares equal to the
    model it resumes."""
    hp = attrs.get("hyperparameters")
    if attrs.get("class") != "GLPNet" or not isinstance(hp, dict) or not isinstance(hp.get("method"), str):
        return attrs
    return {**attrs, "hyperparameters": {**hp, "method": {"name": hp["method"], "ordering": None}}}


def _affine_mlp(hp: dict[str, Any]) -> dict[str, Any]:
    dim = len(hp["input_scaling"][0])
    return {"kind": "AffineMLP", "in_size": dim, "out_size": len(hp["output_scaling"][0]),
            "hidden": hp["hidden"], "activation": hp["activation"], "input_scaling": hp["input_scaling"],
            "output_scaling": hp["output_scaling"]}


def _lpnet_v1(hp: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    network = _affine_mlp(hp)
    if hp.get("equivariant"):
        network = {"kind": "GroupAveraged", "group": hp["equivariant"], "network": network}
    lpnet = {"network": network, "parametrisation": hp.get("parametrisation", "TestFlowParametrisation")}
    if hp.get("reversing") is None:
        return "LPNet", lpnet
    return "Reversible", {"lpnet": lpnet, "symmetry": hp["reversing"],
                          "iterations": hp.get("fixed_point_iterations", 16)}
