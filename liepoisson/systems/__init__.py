"""Physical Poisson systems: rigid body, heavy top, Kirchhoff, extended pendulum, charged particle;
double-bracket dissipation of any Lie-Poisson system; external forces in the body frame
(linear and quadratic drag, constant torques); nonholonomic constraints on its body
velocity (the Lie-Poisson-d'Alembert equations: the Suslov problem, the Chaplygin sleigh)."""

from ._base import (
    AbstractDefinedByParams as AbstractDefinedByParams,
    AbstractDissipativeSystem as AbstractDissipativeSystem,
    AbstractExactlySolvableSystem as AbstractExactlySolvableSystem,
    AbstractLiePoissonSystem as AbstractLiePoissonSystem,
    AbstractPoissonSystem as AbstractPoissonSystem,
)
from ._terms import AbstractExactTerm as AbstractExactTerm, CollectiveTerm as CollectiveTerm
from ._charged_particle import (
    ChargedParticle as ChargedParticle,
    segment_field_integral as segment_field_integral,
)
from ._free_rigid_body import (
    FreeRigidBodyTerm as FreeRigidBodyTerm,
    free_rigid_body_flow as free_rigid_body_flow,
)
from ._double_bracket import (
    DoubleBracket as DoubleBracket,
    damped_heavy_top as damped_heavy_top,
    damped_rigid_body as damped_rigid_body,
)
from ._forces import (
    FORCES as FORCES,
    AbstractDissipativeForce as AbstractDissipativeForce,
    AbstractForce as AbstractForce,
    AbstractForcedSystem as AbstractForcedSystem,
    ConstantTorque as ConstantTorque,
    Forced as Forced,
    LinearDrag as LinearDrag,
    QuadraticDrag as QuadraticDrag,
    force_from_params as force_from_params,
    forces_flow as forces_flow,
)
from ._generalized_rigid_body import GeneralizedRigidBody as GeneralizedRigidBody
from ._heavy_top import HeavyTop as HeavyTop
from ._kirchhoff import Kirchhoff as Kirchhoff
from ._lie_poisson import LiePoissonSystem as LiePoissonSystem
from ._nonholonomic import (
    SE2_BASIS as SE2_BASIS,
    LiePoissonDAlembert as LiePoissonDAlembert,
    chaplygin_sleigh as chaplygin_sleigh,
    sleigh_pose as sleigh_pose,
    suslov as suslov,
)
from ._pendulum import ExtendedPendulum as ExtendedPendulum
from ._registry import (
    SYSTEMS as SYSTEMS,
    check_system_matches as check_system_matches,
    from_name as from_name,
    system_for_file as system_for_file,
)
from ._rigid_body import RigidBody as RigidBody
from ._zeitlin import Zeitlin as Zeitlin
from ._reversing import (
    check_reversing_symmetry as check_reversing_symmetry,
    check_sign_symmetry as check_sign_symmetry,
    reversing_symmetries as reversing_symmetries,
    reversing_symmetry as reversing_symmetry,
    sign_symmetries as sign_symmetries,
)
from ._splitting_check import check_splitting as check_splitting
