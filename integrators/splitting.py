"""Classical splitting methods: stateless rules composing the exact sub-flows of
`system.hamiltonian_splitting()` by coefficient tables (`Strang()`, `TripleJump()`,
`Strang(ordering=(2, 0, 1))`), bound to a system and a step size by `Splitting`
(`Splitting(system, 0.1, Strang()).rollout(y0, n_steps)`, or `Strang(system, h=0.1)`)."""

from ._compensated import Compensated as Compensated  # the same object as integrators.Compensated
from ._compensated import two_sum as two_sum
from ._splitting._base import AbstractFlows as AbstractFlows
from ._splitting._base import AbstractSplittingMethod as AbstractSplittingMethod
from ._splitting._base import FlowList as FlowList
from ._splitting._base import IndexedFlows as IndexedFlows
from ._splitting._base import Splitting as Splitting
from ._splitting._blanes_moan import BlanesMoan4 as BlanesMoan4
from ._splitting._compensated import AbstractCompensableStepMap as AbstractCompensableStepMap
from ._splitting._compensated import compensated_flow as compensated_flow
from ._splitting._composition import (
    AbstractCompositionMethod as AbstractCompositionMethod,
)
from ._splitting._composition import (
    McLachlan4 as McLachlan4,
)
from ._splitting._composition import (
    Suzuki as Suzuki,
)
from ._splitting._composition import (
    TripleJump as TripleJump,
)
from ._splitting._composition import (
    Yoshida6 as Yoshida6,
)
from ._splitting._lie_trotter import LieTrotter as LieTrotter
from ._splitting._strang import Strang as Strang

#: Every splitting method (the classes: `cls()` is the method, `cls(system, h)` its step map),
#: for parametrised tests and sweeps.
METHODS = (LieTrotter, Strang, TripleJump, Suzuki, McLachlan4, Yoshida6, BlanesMoan4)


def splitting_method_by_name(name: str, argument: str = "method") -> AbstractSplittingMethod:
    """The method of `METHODS` whose class is called `name` (`"Suzuki"` -> `Suzuki()`), as files
    and profiles name it; `ValueError` naming `argument` and the known names otherwise."""
    for cls in METHODS:
        if cls.__name__ == name:
            return cls()
    raise ValueError(f"{argument}: unknown splitting method {name!r}; known: {', '.join(c.__name__ for c in METHODS)}")
