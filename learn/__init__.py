"""LPNets, G-LPNets and unstructured baselines: data-driven Lie-Poisson maps (JAX).

Importing `learn` switches JAX to float64.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._base import AbstractLearnedMap as AbstractLearnedMap, TrainingRecord as TrainingRecord
from ._lpnet import LPNet as LPNet
from ._parametrisation import (
    AbstractStepParametrisation as AbstractStepParametrisation,
    LieAlgebraParametrisation as LieAlgebraParametrisation,
    SO3Rotation as SO3Rotation,
    default_parametrisation as default_parametrisation,
)
from ._glpnet import GLPNet as GLPNet
from ._baseline import MLPBaseline as MLPBaseline
