"""Reading a learned map from its file whatever its class."""

from __future__ import annotations

import os

from liepoisson.systems import AbstractPoissonSystem

from .. import _files as _checkpoint
from ._base import AbstractLearnedMap
from ._baseline import MLPBaseline, NeuralODE
from ._body_lpnet import BodyLPNet
from ._drag import Dissipative
from ._glpnet import GLPNet
from ._isospectral import IsospectralPolynomial
from ._legacy import upgrade_attributes
from ._lpnet import LPNet
from ._nonholonomic import DAlembertMap, QuadraticDAlembertMap
from ._reversible import Reversible


def load(path: str | os.PathLike, system: AbstractPoissonSystem | None = None) -> AbstractLearnedMap:
    """Read a learned map written by `.save` (or the best weights of an Adam checkpoint),
    whatever its class (`LPNet`, `Reversible`, `GLPNet`, `MLPBaseline`), from the class the
    file names; `system` as in `AbstractLearnedMap.load`."""
    classes = {cls.__name__: cls for cls in (LPNet, Reversible, GLPNet, MLPBaseline, NeuralODE, IsospectralPolynomial,
                                                    DAlembertMap, QuadraticDAlembertMap, Dissipative, BodyLPNet)}
    attrs, groups = _checkpoint.read(path)  # read once: the class is in the file
    attrs = upgrade_attributes(attrs, f"path {os.fspath(path)!r}")
    name = attrs.get("class")
    if name not in classes:
        raise ValueError(f"path {os.fspath(path)!r} holds a {name!r}, not a learned map ({', '.join(classes)})")
    return classes[name].from_file(path, attrs, groups, system)
