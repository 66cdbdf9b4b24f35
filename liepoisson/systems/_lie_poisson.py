r"""A Lie-Poisson system for any algebra and any Hamiltonian the user writes, with a portable
definition (saved with every data set and model, so that a file rebuilds the system)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._abstract_algebra import AbstractLieAlgebra
from .._definitions import algebra_from_definition
from .._groups import AbstractLieGroup, group_definition, group_from_definition
from .._namespace import JAX
from .._symbolic import (
    SYMBOLIC,
    NotSymbolicError,
    TreeFunction,
    check_tree,
    evaluate,
    symbols,
    trace,
)
from ._automatic_splitting import automatic_splitting
from ._base import AbstractDefinedByParams, AbstractLiePoissonSystem
from ._free_rigid_body import FreeRigidBodyTerm
from ._splitting_check import check_splitting
from ._terms import AbstractExactTerm, CollectiveTerm

#: `params["kind"]` of a user Lie-Poisson system in files (`from_name` dispatches on it).
KIND = "LiePoissonSystem"

# Probe points at which the Hamiltonian's values are recorded: a system passed to a loader must
# reproduce them (its Hamiltonian may be a callable that no file can hold).
_N_PROBES = 4


class _PieceFunction:
    r"""$\varphi(s)$ or $\varphi(s, c)$ of a `CollectiveTerm` rebuilt from its tree (the `m`
    form values are arguments `0..m-1`, the Casimirs `m..`)."""

    def __init__(self, tree: Any, m: int, n_casimirs: int):
        self.tree = check_tree(tree, m + n_casimirs, "splitting function")
        self.m = m

    def __call__(self, s: Sequence[Any], c: Sequence[Any] = ()) -> Any:
        return evaluate(self.tree, list(s) + list(c), JAX)


def _piece_definition(term: AbstractExactTerm, n_casimirs: int) -> dict[str, Any] | None:
    """A piece as JSON values, or None for a piece no file can hold (a user `AbstractExactTerm`,
    or a function that does not evaluate on symbols, e.g. one written with jax.numpy)."""
    if isinstance(term, FreeRigidBodyTerm):
        return {"kind": "FreeRigidBodyTerm", "inertia": [float(v) for v in np.asarray(term.inertia)]}
    if not isinstance(term, CollectiveTerm):
        return None
    m = term.forms.shape[0]
    s = symbols(m + (n_casimirs if term.uses_casimirs else 0))
    try:
        if term.uses_casimirs:
            tree = trace(lambda: term.function(s[:m], s[m:]), "splitting function")
        else:
            tree = trace(lambda: term.function(s), "splitting function")
    except NotSymbolicError:
        return None
    return {"kind": "CollectiveTerm", "forms": term.forms.tolist(), "function": tree,
            "name": term.name, "uses_casimirs": term.uses_casimirs}


def _piece_from_definition(d: dict[str, Any], n_casimirs: int) -> AbstractExactTerm:
    if d["kind"] == "FreeRigidBodyTerm":
        return FreeRigidBodyTerm(d["inertia"])
    if d["kind"] != "CollectiveTerm":
        raise ValueError(f"unknown splitting piece kind {d['kind']!r}")
    forms = np.asarray(d["forms"], dtype=np.float64)
    fn = _PieceFunction(d["function"], forms.shape[0], n_casimirs if d["uses_casimirs"] else 0)
    return CollectiveTerm(forms, fn, str(d["name"]), uses_casimirs=bool(d["uses_casimirs"]))


class LiePoissonSystem(AbstractLiePoissonSystem, AbstractDefinedByParams):
    r"""$\dot\mu = \mathbb{B}(\mu)\nabla H(\mu)$ on $\mathfrak g^*$ for a user algebra and Hamiltonian.

    **Arguments:**

    - `algebra`: a `LieAlgebra` (structure constants) or a `MatrixLieAlgebra` (`liepoisson.so(N)`,
      ...; its Hamiltonian is written on the components $\mu_a$, so for moderate dimensions).
    - `hamiltonian`: `hamiltonian(mu, xp)` on the components `mu[0..n-1]`, written with Python
      operators and the namespace `xp` (`xp.sqrt`, `xp.sin`, `xp.cos`, `xp.exp`, `xp.log`) so
      numpy, JAX and heyoka can all evaluate it. It is evaluated once on symbols here: a
      formula that calls numpy, jax.numpy or math on the state, or branches on it, is refused
      with a `TypeError` now rather than failing later inside JAX or heyoka. The recorded
      expression is what data sets and models save, so `Trajectories.load` rebuilds the system.
    - `name`: a label (files, messages).
    - `splitting`: optional exactly solvable pieces (`CollectiveTerm`s, `FreeRigidBodyTerm`)
      for classical splitting, checked here (`liepoisson.systems.check_splitting`): they must
      sum to $H$ and each must be exact (a `CollectiveTerm`'s forms must Poisson-commute).
      Pieces whose function does not evaluate on symbols (e.g. written with jax.numpy) work,
      but are not saved: load such files with `system=` to get the splitting back.
    - `group` (keyword): the configuration group (`liepoisson.MatrixGroup(basis)`, ...),
      checked to represent `algebra`; default: `Rotations` for so(3), `Poses` for se(3), none
      otherwise. Saved in files with the system when given (a user's own `AbstractLieGroup`
      subclass is not: load with `system=`).
    """

    def __init__(
        self,
        algebra: AbstractLieAlgebra,
        hamiltonian: Callable[[Sequence[Any], Any], Any],
        name: str = "LiePoissonSystem",
        splitting: Sequence[AbstractExactTerm] = (),
        *,
        group: AbstractLieGroup | None = None,
    ):
        if not isinstance(algebra, AbstractLieAlgebra):
            raise TypeError(f"algebra must be a liepoisson.LieAlgebra or MatrixLieAlgebra; got {type(algebra).__name__}")
        if not callable(hamiltonian):
            raise TypeError(f"hamiltonian must be callable (mu, xp) -> H; got {hamiltonian!r}")
        self.algebra = algebra
        self.name = str(name)
        if group is not None:
            if not isinstance(group, AbstractLieGroup):
                raise TypeError(f"group must be a liepoisson.AbstractLieGroup (Rotations, Poses, MatrixGroup); "
                                f"got {type(group).__name__}")
            group.check_algebra(algebra.structure_constants, f"the algebra {algebra.name!r}")
        self._group = group
        n = algebra.dim
        self._tree = trace(lambda: hamiltonian(symbols(n), SYMBOLIC), "hamiltonian")
        self._hamiltonian = hamiltonian
        self._splitting: tuple[AbstractExactTerm, ...] = ()
        self._splitting_missing = ""
        self._automatic: tuple[AbstractExactTerm, ...] | None = None
        y = np.random.default_rng(20241122).normal(size=(_N_PROBES, n))
        values = np.asarray(self.hamiltonian(y), dtype=np.float64)
        if not np.all(np.isfinite(values)):
            raise ValueError(
                f"hamiltonian is not finite at random states (values {values.tolist()}); "
                "a Hamiltonian must be finite on a dense set of states"
            )
        self._probes = {"y": y.tolist(), "H": values.tolist()}
        if splitting is None or (isinstance(splitting, Sequence) and len(splitting) == 0):
            return
        self._splitting = check_splitting(self, splitting, "splitting")

    @property
    def group(self) -> AbstractLieGroup | None:
        """The `group=` given, else the default of the algebra (`Rotations` for so(3),
        `Poses` for se(3))."""
        return self._group if self._group is not None else super().group

    def __repr__(self) -> str:
        return f"LiePoissonSystem(name={self.name!r}, algebra={self.algebra.name!r}, dim={self.dim})"

    def value_key(self) -> tuple[Any, ...] | None:
        """The definition is complete unless a splitting piece could not be saved: then
        `None` (equal only to itself)."""
        if self._splitting and self.params["splitting"] is None:
            return None
        return AbstractDefinedByParams.value_key(self)

    @property
    def hamiltonian_expression(self) -> Any:
        """The Hamiltonian as an expression tree (`liepoisson._symbolic`), as saved in files."""
        return self._tree

    @property
    def params(self) -> dict[str, Any]:
        """The system's full definition as JSON values: algebra, Hamiltonian expression,
        splitting (None where a piece cannot be saved), and the Hamiltonian at probe points."""
        k = self.algebra.n_casimirs
        pieces = [_piece_definition(t, k) for t in self._splitting]
        params = {
            "kind": KIND,
            "algebra": self.algebra.definition(),
            "hamiltonian": self._tree,
            "splitting": None if any(p is None for p in pieces) else pieces,
            "probes": self._probes,
        }
        group = None if self._group is None else group_definition(self._group)
        if group is not None:  # a group given (only then: files without one stay as they were)
            params["group"] = group
        return params

    @classmethod
    def from_params(cls, name: str, params: dict[str, Any], what: str = "params") -> LiePoissonSystem:
        """The system of `params` (as `params` returns them); `ValueError` naming `what` for a
        malformed definition."""
        try:
            algebra = algebra_from_definition(params["algebra"], f"{what}['algebra']")
            hamiltonian = TreeFunction(params["hamiltonian"], algebra.dim)
            k = algebra.n_casimirs
            pieces = params.get("splitting")
            splitting = () if not pieces else tuple(_piece_from_definition(p, k) for p in pieces)
            group = group_from_definition(params["group"]) if params.get("group") is not None else None
            system = cls(algebra, hamiltonian, name, splitting, group=group)
        except (KeyError, TypeError, ValueError, IndexError) as err:
            raise ValueError(f"{what} is not a valid LiePoissonSystem definition: {type(err).__name__}: {err}") from err
        if "splitting" in params and params["splitting"] is None:  # pieces no file could hold
            system._splitting_missing = (
                f"the splitting of {name!r} was not saved (one of its pieces is a function that does "
                "not evaluate on symbols, or a piece kind no file can hold); load the file with "
                "system=<your LiePoissonSystem> to use its splitting"
            )
        return system

    def hamiltonian_components(self, y, xp):
        return self._hamiltonian(y, xp)

    def hamiltonian_splitting(self):
        r"""The pieces given as `splitting`, or else derived from the Hamiltonian's expression
        (`automatic_splitting`): the addends of degree <= 2 by the eigen-decomposition of their
        Hessian, every other addend as a function of the linear forms its gradient spans. All
        pieces are then collective with exact flows, except for an addend whose forms do not
        Poisson-commute: that raises `ValueError` naming it (give `splitting=` then)."""
        if self._splitting:
            return self._splitting
        if self._splitting_missing:
            raise ValueError(self._splitting_missing)
        if self._automatic is None:
            try:
                pieces = automatic_splitting(self, self._tree)
            except ValueError as err:
                raise ValueError(f"{self.name}: no automatic exact splitting: {err}") from None
            self._automatic = check_splitting(self, pieces, "the automatic splitting")
        return self._automatic
