"""LPNets, G-LPNets and unstructured baselines: data-driven Lie-Poisson step maps (JAX), and
training as a free function (`learn.fit`): a loss builds the training problem from a map and
data, solver stages minimise it.

Importing `learn` switches JAX to float64.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._models._base import (
    AbstractBodyMap as AbstractBodyMap,
    AbstractCasimirConservingMap as AbstractCasimirConservingMap,
    AbstractLearnedMap as AbstractLearnedMap,
    AbstractOneFlowMap as AbstractOneFlowMap,
    AbstractWarmStartableMap as AbstractWarmStartableMap,
)
from ._models._baseline import MLPBaseline as MLPBaseline, NeuralODE as NeuralODE
from ._models._body_lpnet import BodyLPNet as BodyLPNet
from ._models._deeponet import DeepONet as DeepONet
from ._models._drag import DRAG_KINDS as DRAG_KINDS, Dissipative as Dissipative, LearnedDrag as LearnedDrag
from ._models._equivariant import GroupAveraged as GroupAveraged
from ._models._glpnet import GLPNet as GLPNet, linear_to_activation as linear_to_activation
from ._models._isospectral import IsospectralPolynomial as IsospectralPolynomial
from ._models._spectrum import (
    AbstractGaugedSpectrum as AbstractGaugedSpectrum,
    AbstractSpectrum as AbstractSpectrum,
    DegreeSpectrum as DegreeSpectrum,
    HarmonicSpectrum as HarmonicSpectrum,
    QuasiGeostrophicSpectrum as QuasiGeostrophicSpectrum,
    in_gauge as in_gauge,
)
from ._models._stream_operator import StreamOperator as StreamOperator, planetary_vorticity as planetary_vorticity
from ._models._nonholonomic import AbstractDAlembertMap as AbstractDAlembertMap
from ._models._nonholonomic import DAlembertMap as DAlembertMap
from ._models._nonholonomic import QuadraticDAlembertMap as QuadraticDAlembertMap
from ._models._learned_system import LearnedHamiltonian as LearnedHamiltonian
from ._models._learned_terms import RidgeTerms as RidgeTerms
from ._models._load import load as load
from ._models._lpnet import LPNet as LPNet
from ._models._mlp import AffineMLP as AffineMLP
from ._models._networks import AbstractNetwork as AbstractNetwork, AbstractWrappedNetwork as AbstractWrappedNetwork
from ._models._parametric import ParametricHamiltonian as ParametricHamiltonian
from ._models._parametrisation import (
    AbstractInvertibleParametrisation as AbstractInvertibleParametrisation,
    AbstractLiftedParametrisation as AbstractLiftedParametrisation,
    AbstractStepParametrisation as AbstractStepParametrisation,
    SE3RotationShear as SE3RotationShear,
    TestFlowParametrisation as TestFlowParametrisation,
    default_parametrisation as default_parametrisation,
)
from ._models._plus_affine import PlusAffine as PlusAffine
from ._models._reversible import Reversible as Reversible
from ._solvers._adam import Adam as Adam
from ._solvers._checkpoint import Checkpoint as Checkpoint
from ._solvers._levenberg_marquardt import LevenbergMarquardt as LevenbergMarquardt
from ._solvers._loop import AbstractSolver as AbstractSolver, Step as Step, iterate as iterate
from ._solvers._optimistix import Optimistix as Optimistix
from ._solvers._problem import (
    AbstractLeastSquares as AbstractLeastSquares,
    AbstractObjective as AbstractObjective,
    AbstractProblem as AbstractProblem,
    AbstractStructuredJacobian as AbstractStructuredJacobian,
)
from ._solvers._quasi_newton import (
    OptaxLBFGS as OptaxLBFGS,
    ScipyBFGS as ScipyBFGS,
    ScipyLBFGSB as ScipyLBFGSB,
)
from ._solvers._record import StageRecord as StageRecord, TrainingRecord as TrainingRecord
from ._solvers._stage import (
    AbstractStage as AbstractStage,
    AbstractWrappedStage as AbstractWrappedStage,
    Context as Context,
    KeepIfBetter as KeepIfBetter,
    Linearisation as Linearisation,
    Progress as Progress,
    Restarts as Restarts,
    Result as Result,
    WarmStart as WarmStart,
)
from ._training._body import (
    BodyLoss as BodyLoss,
    BodyObjective as BodyObjective,
    BodySegments as BodySegments,
    body_quadratic_estimate as body_quadratic_estimate,
    latent_momenta as latent_momenta,
    weak_form_drag as weak_form_drag,
    weak_form_quadratic as weak_form_quadratic,
)
from ._training._deeponet import BodyDeepONet as BodyDeepONet, fit_deeponet as fit_deeponet
from ._training._dissipative import fit_dissipative as fit_dissipative
from ._training._inertia import Inertia as Inertia, inertia as inertia, inertia_matrix as inertia_matrix
from ._training._fit import default_optimiser as default_optimiser, fit as fit
from ._training._families import (
    FAMILIES as FAMILIES,
    Family as Family,
    quadratic_estimate as quadratic_estimate,
    select_quadratic as select_quadratic,
)
from ._training._criterion import (
    FamilyChoice as FamilyChoice,
    FamilyScore as FamilyScore,
    SkippedFamily as SkippedFamily,
)
from ._training._fit_splitting import fit_splitting as fit_splitting
from ._training._stream_fit import StreamOperatorFit as StreamOperatorFit, WaldTest as WaldTest
from ._training._stream_fit import fit_stream_operator as fit_stream_operator
from ._training._phase import fit_phase as fit_phase
from ._training._identify import (
    PrincipalAxes as PrincipalAxes,
    QuadraticPart as QuadraticPart,
    quadratic_part as quadratic_part,
)
from ._training._losses import (
    AbstractLoss as AbstractLoss,
    AbstractPairsLoss as AbstractPairsLoss,
    AlphaLoss as AlphaLoss,
    MeanSquares as MeanSquares,
    Pairs as Pairs,
    StateLoss as StateLoss,
    alpha_mse as alpha_mse,
    state_mse as state_mse,
)
from ._training._observed import Segments as Segments, TrajectoryLoss as TrajectoryLoss
from ._training._problem import Fitted as Fitted
from ._training._sweep import (
    Sweep as Sweep,
    SweepResult as SweepResult,
    grid_points as grid_points,
    sweep as sweep,
)
