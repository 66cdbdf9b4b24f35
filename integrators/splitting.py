"""Classical splitting methods: exact sub-flows of `system.hamiltonian_splitting()` composed
by coefficient tables; each is a step map (`Strang(system, h=0.1).rollout(y0, n_steps)`)."""

from ._splitting._base import AbstractSplittingMethod as AbstractSplittingMethod
from ._splitting._base import IndexedFlows as IndexedFlows
from ._splitting._blanes_moan import BlanesMoan4 as BlanesMoan4
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

#: Every splitting method, for parametrised tests and sweeps.
METHODS = (LieTrotter, Strang, TripleJump, Suzuki, McLachlan4, Yoshida6, BlanesMoan4)
