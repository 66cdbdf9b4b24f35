"""The plumbing `integrators` shares with the library's other packages (`learn`, `paper`,
`benchmarks`): step-map helpers, atomic files, Dask helpers and figure styles. Not a user API:
these names may change with the library.

- `check_state(y, dim)`: one float64 state `(dim,)` (works on traced values); `check_h(step_map)`:
  its step size, or a `ValueError` for a map that has none yet.
- `composition_flops(step_map, method)`: XLA's flops of a step composed by a splitting method;
  `splitting_method(method, name)`: a method instance from an instance or a class (`TypeError` naming
  `name` otherwise).
- `traced_h(step_map)`: the map with its step size as a traced array (one compiled program for
  every h); `xla_flops(fn, *args)`: XLA's flop count of `fn` compiled.
- `atomic_path(path)`, `atomic_write_text(path, text)`: write to a temporary file renamed into
  place; `open_hdf5(path, expected)`: open for reading with an error that says what was expected.
- `require_distributed()`, `check_client(client)`, `map_unordered(...)`: Dask helpers;
  `integrate_chunk(...)`: one chunk of a ground-truth ensemble (the unit of work of
  `save_ground_truth` on a cluster).
- `validation_split(n, validation_fraction, seed, unit)`: the seeded training/validation split
  of `n` items (pairs of `Trajectories`, trajectories of `Observations`), as sorted indices.
- `rk4_steps(field, y, h, substeps)`: classical Runge-Kutta steps on any pytree (the learned
  maps' RK4 and `RK4`'s).
- `rms_size(states)`: sqrt(mean |y|^2) over a list of arrays of states, the
  size `observe`'s noise is relative to.
- `json_values(value, nan=None)`: results as JSON values (numpy as numbers, infinities as
  strings, NaN as `nan`): the paper's metrics and the benchmarks' result files.
- `figure(**kw)`, `save_figure(fig, path)`, `series_styles(n)`, `span_decades(ax, axis)`:
  matplotlib figures in the library's style, saved atomically.
- `check_isospectral(system)`, `check_stage_tolerance(tol)`, `ISOSPECTRAL_TOL`,
  `ISOSPECTRAL_MAX_ITER`: what the isospectral methods accept and their defaults (a learned map
  on the same step uses them).
- `counted_compilations()`: a `with` block counting the programs JAX traced and XLA compiled
  in it (tests and benchmarks of compilation reuse).
- `serial_lapack()`, `serial_lapack_block()`: JAX's CPU LAPACK (SciPy's OpenBLAS) on one
  thread, for the process or for a `with` block.
"""

from ._distributed import (
    check_client as check_client,
)
from ._distributed import (
    map_unordered as map_unordered,
)
from ._distributed import (
    require_distributed as require_distributed,
)
from ._files import atomic_path as atomic_path
from ._files import atomic_write_text as atomic_write_text
from ._files import open_hdf5 as open_hdf5
from ._ground_truth import integrate_chunk as integrate_chunk
from ._isospectral import DEFAULT_MAX_ITER as ISOSPECTRAL_MAX_ITER  # noqa: F401 (re-exported, renamed)
from ._isospectral import DEFAULT_TOL as ISOSPECTRAL_TOL  # noqa: F401 (re-exported, renamed)
from ._isospectral import check_isospectral as check_isospectral
from ._isospectral import check_stage_tolerance as check_stage_tolerance
from ._json_values import json_values as json_values
from ._lapack import openblas_kernels as openblas_kernels
from ._lapack import serial_lapack as serial_lapack
from ._lapack import serial_lapack_block as serial_lapack_block
from ._observations import rms_size as rms_size
from ._plots import figure as figure
from ._plots import save_figure as save_figure
from ._plots import series_styles as series_styles
from ._plots import span_decades as span_decades
from ._runge_kutta import rk4_steps as rk4_steps
from ._splitting._base import composition_flops as composition_flops
from ._splitting._base import splitting_method as splitting_method
from ._step_map import check_h as check_h
from ._step_map import check_state as check_state
from ._step_map import traced_h as traced_h
from ._step_map import xla_flops as xla_flops
from ._timing import counted_compilations as counted_compilations
from ._validation_split import validation_split as validation_split
