"""Shared lists (every algebra, every system), hypothesis strategies and references that do
not share code with `liepoisson` (numpy/scipy only)."""

from __future__ import annotations

import dataclasses
import functools
import multiprocessing
import os
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from hypothesis import strategies as st

import learn
import liepoisson as lp
from integrators.internals import counted_compilations

EPS = np.finfo(np.float64).eps


# -- the shared lists ------------------------------------------------------------------------
def _generic_so3():
    # so(3) from its constants only: automatic Casimirs, matrix-exponential flow.
    C = np.zeros((3, 3, 3))
    for a, b, c in [(0, 1, 2), (1, 2, 0), (2, 0, 1)]:
        C[a, b, c], C[b, a, c] = 1.0, -1.0
    return lp.LieAlgebra(C, name="generic_so3")


ALGEBRA_FACTORIES = {
    "so3": lp.so3,
    "so3_spatial": lambda: lp.so3(sign=+1),
    "se3": lp.se3,
    "se2": lp.se2,
    "sl2": lp.sl2,
    "heisenberg": lp.heisenberg,
    "so3+heisenberg": lambda: lp.direct_sum(lp.so3(), lp.heisenberg()),
    "generic_so3": _generic_so3,
}

SYSTEM_FACTORIES = {
    "RigidBody": lambda: lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)),
    "HeavyTop": lambda: lp.systems.HeavyTop(
        inertia=(1.0, 1.5, 2.5), mgl=0.7, center_of_mass=(0.3, -0.2, 1.0)
    ),
    "Kirchhoff": lambda: lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.5), mass=(1.0, 2.0, 3.0)),
    "ExtendedPendulum": lambda: lp.systems.ExtendedPendulum(),
    # q, m != 1 so that a q/m mix-up (the paper writes q/m in the tensor) would show.
    "ChargedParticle": lambda: lp.systems.ChargedParticle(
        charge=1.3, mass=0.8, field_strength=0.9, potential_strength=0.05
    ),
}


@functools.cache
def algebra(name: str) -> lp.LieAlgebra:
    return ALGEBRA_FACTORIES[name]()


@functools.cache
def system(name: str):
    return SYSTEM_FACTORIES[name]()


ALGEBRAS = list(ALGEBRA_FACTORIES)
SYSTEMS = list(SYSTEM_FACTORIES)
# Lie-Poisson systems and the algebra they live on.
LIE_POISSON_SYSTEMS = ["RigidBody", "HeavyTop", "Kirchhoff"]



def slow_except(values, default):
    """`values` to parametrize over, those not in `default` marked slow (run with -m slow): the
    default run keeps a representative few."""
    return [v if v in default else pytest.param(v, marks=pytest.mark.slow) for v in values]


# By default the algebras with their own code paths (so(3), se(3): closed forms; sl(2): not
# compact; a direct sum; so(3) from its constants alone: the generic path) and the systems on
# them; so(3) with the spatial sign, se(2), Heisenberg (also inside the direct sum), the heavy
# top (se(3) like Kirchhoff) and the extended pendulum with -m slow.
algebra_names = pytest.mark.parametrize(
    "name", slow_except(ALGEBRAS, {"so3", "se3", "sl2", "so3+heisenberg", "generic_so3"}))
system_names = pytest.mark.parametrize(
    "name", slow_except(SYSTEMS, {"RigidBody", "Kirchhoff", "ChargedParticle"}))


# -- hypothesis strategies -------------------------------------------------------------------
def vectors(dim: int, bound: float = 2.0):
    return st.lists(
        st.floats(-bound, bound, allow_nan=False, allow_infinity=False), min_size=dim, max_size=dim
    ).map(lambda v: np.array(v, dtype=np.float64))


def _particle_states(bound: float = 2.0):
    # |x| >= 0.2: the field |x| and the potential 1/|x| are not smooth at the origin.
    return st.tuples(
        vectors(2, bound), st.floats(0.2, bound), st.floats(0.0, 2 * np.pi)
    ).map(lambda v: np.concatenate([v[0], v[1] * np.array([np.cos(v[2]), np.sin(v[2])])]))


def states(name: str, dim: int, bound: float = 2.0):
    """Random states of a system (or an algebra's dual); away from singular points."""
    if name == "ChargedParticle":
        return _particle_states(bound)
    return vectors(dim, bound)


times = st.floats(-1.5, 1.5, allow_nan=False)


# -- independent references ------------------------------------------------------------------
def reference_poisson_tensor(C: np.ndarray, mu: np.ndarray, sign: int = -1) -> np.ndarray:
    """B_ab = sign * C_abd mu_d, by explicit loops."""
    n = C.shape[0]
    B = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            B[a, b] = sign * sum(C[a, b, d] * mu[d] for d in range(n))
    return B


def reference_coadjoint_flow(C, alpha, t, mu, sign=-1):
    """scipy.linalg.expm of t M(alpha), M_ad = sign * C_abd alpha_b (docs/conventions.md).

    scipy's expm alone errs by ~1e-13 at norm 30 (Pade-13 branch); scaling to norm <= 1/4
    and squaring back in extended precision keeps the reference at ~norm * eps."""
    n = C.shape[0]
    M = np.zeros((n, n))
    for a in range(n):
        for d in range(n):
            M[a, d] = sign * sum(C[a, b, d] * alpha[b] for b in range(n))
    A = t * M
    s = max(0, int(np.ceil(np.log2(max(np.linalg.norm(A, 1), 1e-300) / 0.25))))
    E = scipy.linalg.expm(A / 2.0**s).astype(np.longdouble)
    for _ in range(s):
        E = E @ E
    return (E @ np.asarray(mu, dtype=np.longdouble)).astype(np.float64)


def pendulum_tensor(y):
    """Paper eq. bracket_ext_pendulum."""
    u, v, _ = y
    return np.array([[0.0, -1.0, -2 * v], [1.0, 0.0, 2 * u], [2 * v, -2 * u, 0.0]])


def particle_tensor(y, q, b0):
    """B = [[-q hat(B), -I], [I, 0]], hat(B) = [[0, -B3], [B3, 0]], B3 = b0 |x|."""
    B3 = b0 * np.hypot(y[2], y[3])
    return np.array(
        [[0.0, q * B3, -1.0, 0.0], [-q * B3, 0.0, 0.0, -1.0], [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]
    )


def reference_tensor(name: str, sys, y):
    """Poisson tensor written independently of the package."""
    if name == "ExtendedPendulum":
        return pendulum_tensor(y)
    if name == "ChargedParticle":
        return particle_tensor(y, sys.charge, sys.field_strength)
    return reference_poisson_tensor(sys.algebra.structure_constants, y, sys.algebra.sign)


def solve_ivp_flow(tensor, alpha, t, y0, rtol=1e-13, atol=1e-14):
    """dy/dt = B(y) alpha by DOP853 (the exact flow of H = <alpha, y>)."""
    if t == 0:
        return np.asarray(y0, dtype=float)
    sol = scipy.integrate.solve_ivp(
        lambda s, y: tensor(y) @ alpha, (0.0, t), np.asarray(y0, float), method="DOP853",
        rtol=rtol, atol=atol,
    )
    assert sol.success
    return sol.y[:, -1]


_DEFECTS: dict = {}


def poisson_defect(key, flow, tensor, alpha, t, y):
    """(max |J B(y) J^T - B(T y)|, max |T y|) for T = flow(alpha, t, .), J its JAX Jacobian
    at fixed alpha. Jitted once per `key`."""
    if key not in _DEFECTS:

        def defect(alpha, t, y):
            J = jax.jacfwd(flow, argnums=2)(alpha, t, y)
            out = flow(alpha, t, y)
            diff = J @ tensor(y) @ J.T - tensor(out)
            return jnp.max(jnp.abs(diff)), jnp.max(jnp.abs(out))

        _DEFECTS[key] = jax.jit(defect)
    d, s = _DEFECTS[key](jnp.asarray(alpha), jnp.asarray(t, dtype=jnp.float64), jnp.asarray(y))
    return float(d), float(s)


@dataclasses.dataclass(frozen=True)
class ToyProblem(learn.AbstractProblem):
    """A training problem of the solvers alone (no learned map, no system): `objective(y0,
    train)` from the start `y0`; restarts add standard normal noise to every leaf."""

    objective: learn.AbstractObjective
    y0: Any
    train: Any
    validation: Any = None
    name: str = "toy"

    def with_start(self, y0):
        return dataclasses.replace(self, y0=y0)

    def reinitialised(self, key):
        return jax.tree_util.tree_map(lambda a: a + jax.random.normal(key, jnp.shape(a)), self.y0)

    def warm_start(self):
        return None

    def file_attributes(self):
        return {}

    def read_checkpoint(self, path):
        raise ValueError("a toy problem has no checkpoints")


#: `with compilations() as seen`: `seen["traces"]` programs traced in the block (the library's counter).
compilations = counted_compilations


# -- a test's computation with LLVM's optimisations ------------------------------------------
_XLA_OPT = "--xla_backend_optimization_level"


def in_optimised_process(fn, *args):
    """`fn(*args)` in a fresh process whose XLA compiles with LLVM's optimisations (level 2,
    JAX's default), for a test whose time goes into running compiled code rather than compiling
    it: the suite's level 0 (tests/conftest.py) compiles faster and runs slower (BENCHMARKS.md,
    "The default test run"). `fn` a module-level function and its result picklable; an
    exception in it is raised here."""
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(_XLA_OPT)]
    before = os.environ.get("XLA_FLAGS")
    # the child reads XLA_FLAGS when its JAX first computes; Pool starts it here
    os.environ["XLA_FLAGS"] = " ".join([*flags, f"{_XLA_OPT}=2"])
    try:
        pool = multiprocessing.get_context("spawn").Pool(1)
    finally:
        if before is None:
            del os.environ["XLA_FLAGS"]
        else:
            os.environ["XLA_FLAGS"] = before
    with pool:
        return pool.apply(fn, args)
