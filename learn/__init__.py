"""LPNets, G-LPNets and unstructured baselines: data-driven Lie-Poisson maps (JAX).

Importing `learn` switches JAX to float64.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._base import AbstractLearnedMap as AbstractLearnedMap
from ._base import TrainingRecord as TrainingRecord
from ._baseline import MLPBaseline as MLPBaseline
from ._glpnet import GLPNet as GLPNet
from ._lpnet import LPNet as LPNet
from ._parametrisation import (
    AbstractStepParametrisation as AbstractStepParametrisation,
)
from ._parametrisation import (
    LieAlgebraParametrisation as LieAlgebraParametrisation,
)
from ._parametrisation import (
    SE3RotationShear as SE3RotationShear,
)
from ._parametrisation import (
    SO3Rotation as SO3Rotation,
)
from ._parametrisation import (
    default_parametrisation as default_parametrisation,
)
