"""Networks rebuilt from their `spec()` (model files store the architecture as JSON)."""

from __future__ import annotations

from typing import Any

import jax

from ._equivariant import GroupAveraged
from ._mlp import AffineMLP
from ._networks import AbstractNetwork
from ._plus_affine import PlusAffine


def network_from_spec(spec: dict[str, Any], key: int | jax.Array) -> AbstractNetwork:
    """The network `spec` describes (`AbstractNetwork.spec`), with fresh weights from `key`."""
    if not isinstance(spec, dict):
        raise TypeError(f"a network spec must be a dict with a 'kind'; got {spec!r}")
    kind = spec.get("kind")
    rest = {k: v for k, v in spec.items() if k != "kind"}
    if kind == "AffineMLP":
        return AffineMLP(key=key, **rest)
    if kind == "GroupAveraged":
        return GroupAveraged(network_from_spec(rest["network"], key), rest["group"])
    if kind == "PlusAffine":
        return PlusAffine(network_from_spec(rest["network"], key), rest["shift"], rest["linear"])
    raise ValueError(f"unknown network kind {kind!r}; known: 'AffineMLP', 'GroupAveraged', 'PlusAffine'")
