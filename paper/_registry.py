"""The experiments `python -m paper` knows, in the paper's order."""

from .e1_rigid_body import EXPERIMENT as _E1
from .e2_rigid_body_many import EXPERIMENT as _E2
from .e3_extended_pendulum import EXPERIMENT as _E3
from .e4_charged_particle import EXPERIMENT as _E4
from .e5_kirchhoff import EXPERIMENT as _E5
from .e6_glpnet_rigid_body import EXPERIMENT as _E6
from .w1_learned_vs_classical import EXPERIMENT as _W1
from .w2_observations import EXPERIMENT as _W2
from .w3_dissipation import EXPERIMENT as _W3
from .w4_bodies import EXPERIMENT as _W4
from .w5_zeitlin import EXPERIMENT as _W5
from .w6_nonholonomic import EXPERIMENT as _W6
from .w7_air import EXPERIMENT as _W7
from .w8_fluids import EXPERIMENT as _W8

EXPERIMENTS = {exp.id: exp for exp in (_E1, _E2, _E3, _E4, _E5, _E6, _W1, _W2, _W3, _W4, _W5, _W6, _W7, _W8)}

#: What `python -m paper` runs without a subcommand: the paper's six experiments. The studies
#: beyond the paper (W1, an hour-scale sweep; W2, learning from observations; W3, dissipation;
#: W4, bodies observed by their attitude, pose and velocities; W5, Zeitlin's fluid at N = 16
#: and 32; W6, nonholonomic systems; W7, bodies in air; W8, fluids from data) run on request:
#: `python -m paper run W1 W2 W3 W4 W5 W6 W7 W8`.
PAPER_EXPERIMENTS = tuple(i for i in EXPERIMENTS if i.startswith("E"))
