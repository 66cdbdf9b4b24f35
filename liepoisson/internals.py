"""The plumbing `liepoisson` shares with the library's other packages (`integrators`, `learn`,
`paper`, `benchmarks`): argument checks that raise `ValueError`/`TypeError` naming the
argument, and progress bars. Not a user API: these names may change with the library.

- `as_state(y, name, dim)`, `states(y, name, dim)`, `pairs(y0, y1, dim)`: float64 arrays of
  states `(..., dim)`, finite, checked.
- `positive_float(x, name)`, `positive_int(n, name, minimum=1)`, `fraction(x, name)`: scalars.
- `is_traced(x)`: a JAX tracer (inside `jit`, `vmap`, `grad`), whose values no check can see.
- `check_system(system)`: a `liepoisson.systems.AbstractPoissonSystem`; `refuse_nonholonomic(system,
  what)`: `ValueError` for a constrained system where `what` moves along coadjoint orbits.
- `check_casimirs_agree(...)`: pairs whose Casimirs differ are named; `casimir_scale(gradients,
  y)`: |grad C_j(y)| |y|, the size a Casimir change is measured against.
- `check_fits_in_memory(need, what, remedy)`: `ValueError` before allocating `need` bytes that
  would not fit in the memory one request may take.
- `harmonic_multiplier(W, multiplier)`: the operator on u(N) diagonal in the quantized
  spherical harmonics (Zeitlin's model): sum of mu_lm omega_lm T_lm, in JAX.
- `jsonable(value)`: `value` as reading it back from JSON gives it (tuples as lists).
- `show_progress(progress)`, `progress_bar(total, desc, unit, progress)`: tqdm bars, on by
  default only when stderr is a terminal.
"""

from ._casimir_values import casimir_scale as casimir_scale
from ._inverse import check_casimirs_agree as check_casimirs_agree
from ._jsonable import jsonable as jsonable
from ._matrix_algebra import SEMIDIRECT as SEMIDIRECT
from ._matrix_algebra import dagger as dagger
from ._memory import check_fits_in_memory as check_fits_in_memory
from ._progress import progress_bar as progress_bar
from ._progress import show_progress as show_progress
from ._quantized_sphere import harmonic_multiplier as harmonic_multiplier
from ._validation import (
    as_state as as_state,
)
from ._validation import (
    fraction as fraction,
)
from ._validation import (
    is_traced as is_traced,
)
from ._validation import (
    pairs as pairs,
)
from ._validation import (
    positive_float as positive_float,
)
from ._validation import (
    positive_int as positive_int,
)
from ._validation import (
    states as states,
)
from .systems._base import check_system as check_system
from .systems._nonholonomic import refuse_nonholonomic as refuse_nonholonomic
