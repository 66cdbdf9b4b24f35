"""Ground truth (heyoka), HDF5 data sets, classical Lie-Poisson splitting, Lie-group methods on
the coadjoint action (damped systems), diagnostics."""

import liepoisson as _liepoisson  # noqa: F401  (first: it switches JAX to float64)

from . import splitting as splitting
from ._comparison import Comparison as Comparison, ComparisonRow as ComparisonRow, compare as compare
from ._compensated import (
    AbstractCompensable as AbstractCompensable,
    Compensated as Compensated,
    two_sum as two_sum,
)
from ._convergence import Convergence as Convergence, convergence as convergence
from ._rollout_figures import RolloutFigures as RolloutFigures, rollout_figures as rollout_figures
from ._diagnostics import (
    DiagnosticsReport as DiagnosticsReport,
    Divergence as Divergence,
    diagnostics as diagnostics,
    error_growth_rate as error_growth_rate,
)
from ._damped_splitting import DampedSplitting as DampedSplitting
from ._forced_splitting import ForcedSplitting as ForcedSplitting
from ._splitting._base import Splitting as Splitting
from ._exact import ExactFlow as ExactFlow
from ._implicit import AbstractImplicitStepMap as AbstractImplicitStepMap
from ._ground_truth import (
    ground_truth as ground_truth,
    save_ground_truth as save_ground_truth,
    taylor_integrator as taylor_integrator,
)
from ._body_observations import BodyObservations as BodyObservations, observe_body as observe_body
from ._observed_trajectories import AbstractObservedTrajectories as AbstractObservedTrajectories
from ._imu_csv import read_gyro_csv as read_gyro_csv, write_gyro_csv as write_gyro_csv
from ._observations import (
    Observations as Observations,
    observe as observe,
    uneven_times as uneven_times,
)
from ._vorticity_snapshots import (
    add_field_noise as add_field_noise,
    read_vorticity_snapshots as read_vorticity_snapshots,
    write_vorticity_snapshots as write_vorticity_snapshots,
)
from ._lie_group import (
    LIE_GROUP_METHODS as LIE_GROUP_METHODS,
    AbstractLieGroupMethod as AbstractLieGroupMethod,
    CommutatorFree2 as CommutatorFree2,
    CommutatorFree4 as CommutatorFree4,
    LieEuler as LieEuler,
)
from ._isospectral import (
    ISOSPECTRAL_METHODS as ISOSPECTRAL_METHODS,
    IsospectralMidpoint as IsospectralMidpoint,
    IsospectralTripleJump as IsospectralTripleJump,
)
from ._lyapunov import lyapunov_exponent as lyapunov_exponent
from ._noise import (
    NOISE_LAWS as NOISE_LAWS,
    AbstractNoiseLaw as AbstractNoiseLaw,
    GaussianNoise as GaussianNoise,
    LaplaceNoise as LaplaceNoise,
    UniformNoise as UniformNoise,
)
from ._nonholonomic import AbstractStaggeredStepMap as AbstractStaggeredStepMap
from ._nonholonomic import ComposedLagrangeDAlembert as ComposedLagrangeDAlembert
from ._nonholonomic import DiscreteLagrangeDAlembert as DiscreteLagrangeDAlembert
from ._runge_kutta import GaussLegendre4 as GaussLegendre4, ImplicitMidpoint as ImplicitMidpoint, RK4 as RK4
from ._plots import (
    plot_comparison as plot_comparison,
    plot_convergence as plot_convergence,
    plot_diagnostics as plot_diagnostics,
    plot_energy as plot_energy,
    plot_vorticity as plot_vorticity,
    plot_work_precision as plot_work_precision,
)
from ._nonfinite import (
    NONFINITE_POLICIES as NONFINITE_POLICIES,
    AbstractNonfinitePolicy as AbstractNonfinitePolicy,
    RaiseIfNonfinite as RaiseIfNonfinite,
    ReturnNonfinite as ReturnNonfinite,
    RolloutDivergedError as RolloutDivergedError,
)
from ._step_map import (
    AbstractReconstructingStepMap as AbstractReconstructingStepMap,
    AbstractStepMap as AbstractStepMap,
    StepCost as StepCost,
)
from ._timing import StepTiming as StepTiming, step_timing as step_timing
from ._trajectories import FORMAT_VERSION as FORMAT_VERSION, Trajectories as Trajectories
