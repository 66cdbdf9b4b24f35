"""liepoisson: Lie algebras, Lie-Poisson brackets, Casimirs, exact coadjoint flows and the
physical systems of the LPNets paper."""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._abstract_algebra import AbstractLieAlgebra as AbstractLieAlgebra
from ._algebra import LieAlgebra as LieAlgebra
from ._definitions import algebra_from_definition as algebra_from_definition
from ._direct_sum import DirectSum as DirectSum
from ._matrix_algebra import (
    MatrixLieAlgebra as MatrixLieAlgebra,
    gl as gl,
    se as se,
    semidirect as semidirect,
    sl as sl,
    so as so,
    sp as sp,
    su as su,
    u as u,
)
from ._catalogue import (
    direct_sum as direct_sum,
    heisenberg as heisenberg,
    levi_civita as levi_civita,
    se2 as se2,
    se3 as se3,
    sl2 as sl2,
    so3 as so3,
)
from ._coadjoint import (
    AbstractCoadjointFlow as AbstractCoadjointFlow,
    MatrixExponentialFlow as MatrixExponentialFlow,
    RodriguesFlow as RodriguesFlow,
    SE3Flow as SE3Flow,
    rotate as rotate,
    rotation_coefficients as rotation_coefficients,
)
from ._groups import (
    AbstractLieGroup as AbstractLieGroup,
    MatrixGroup as MatrixGroup,
    Poses as Poses,
    Rotations as Rotations,
    rotation_angle as rotation_angle,
)
from ._expm import expm_action as expm_action
from ._expm import matrix_exponential as matrix_exponential
from ._samples import common_path_first as common_path_first, vmap_samples as vmap_samples
from ._casimirs import polynomial_casimirs as polynomial_casimirs
from ._elliptic import ellipj as ellipj
from ._inverse import gauss_newton_parameters as gauss_newton_parameters
from ._namespace import HEYOKA as HEYOKA, JAX as JAX, NUMPY as NUMPY
from ._polynomial import Polynomial as Polynomial
from ._rotation_shear import (
    se3_rotation_shear as se3_rotation_shear,
    se3_rotation_shear_parameters as se3_rotation_shear_parameters,
)

from . import systems as systems  # noqa: E402  (systems build on the algebra)

__version__ = "0.1.0"
