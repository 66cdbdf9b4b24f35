r"""Direct sums of algebras of any kind: $\mathfrak g_1 \oplus \dots \oplus \mathfrak g_k$ with
every operation blockwise, so a sum of matrix algebras never forms a structure-constant tensor
(coupled bodies: the Hamiltonian couples the blocks, the bracket does not)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._abstract_algebra import AbstractLieAlgebra
from ._validation import as_state


class DirectSum(AbstractLieAlgebra):
    r"""$\mathfrak g_1 \oplus \dots \oplus \mathfrak g_k$: the state is the summands' states one
    after the other; $[\,\cdot\,,\cdot\,]$, $\mathrm{ad}^*$, $\mathbb B$ and the coadjoint flow
    act block by block; the Casimirs are the summands' in order.

    **Arguments:** `summands`, two or more algebras of the same sign convention (`LieAlgebra`s,
    `MatrixLieAlgebra`s, or sums); `name` (default the names joined by `+`).
    `liepoisson.direct_sum` builds one.
    """

    def __init__(self, summands: Sequence[AbstractLieAlgebra], name: str | None = None):
        summands = tuple(summands)
        if len(summands) < 2:
            raise ValueError(f"a direct sum needs at least two summands; got {len(summands)}")
        for i, g in enumerate(summands):
            if not isinstance(g, AbstractLieAlgebra):
                raise TypeError(f"direct_sum arguments must be Lie algebras; argument {i} is {type(g).__name__}")
        signs = {g.sign for g in summands}
        if len(signs) != 1:
            raise ValueError(f"direct_sum needs summands with the same sign convention; got signs {sorted(signs)}")
        self.summands = summands
        self.sign = signs.pop()
        self.name = name or "+".join(g.name for g in summands)
        self.basis_names = tuple(f"{g.name}.{b}" for g in summands for b in g.basis_names)
        self._slices = []
        start = 0
        for g in summands:
            self._slices.append(slice(start, start + g.dim))
            start += g.dim
        self._dim = start

    @property
    def dim(self) -> int:
        return self._dim

    @property
    def n_casimirs(self) -> int:
        return sum(g.n_casimirs for g in self.summands)

    def _blocks(self, x: jax.Array) -> list[jax.Array]:
        return [x[..., sl] for sl in self._slices]

    @property
    def structure_constants(self) -> np.ndarray:
        """The block-diagonal $C_{abd}$ (each summand's; a `ValueError` if one cannot hold its own)."""
        C = np.zeros((self.dim, self.dim, self.dim))
        for g, sl in zip(self.summands, self._slices):
            C[sl, sl, sl] = g.structure_constants
        C.setflags(write=False)
        return C

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        xi, eta = as_state(xi, "xi", self.dim), as_state(eta, "eta", self.dim)
        return jnp.concatenate([g.bracket(a, b) for g, a, b in zip(self.summands, self._blocks(xi), self._blocks(eta))],
                               axis=-1)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        xi, mu = as_state(xi, "xi", self.dim), as_state(mu, "mu", self.dim)
        return jnp.concatenate([g.ad_star(a, m) for g, a, m in zip(self.summands, self._blocks(xi), self._blocks(mu))],
                               axis=-1)

    def poisson_action(self, mu: ArrayLike, xi: ArrayLike) -> jax.Array:
        xi, mu = as_state(xi, "xi", self.dim), as_state(mu, "mu", self.dim)
        parts = [g.poisson_action(m, a) for g, m, a in zip(self.summands, self._blocks(mu), self._blocks(xi))]
        return jnp.concatenate(parts, axis=-1)

    def poisson_tensor(self, mu: ArrayLike) -> jax.Array:
        mu = as_state(mu, "mu", self.dim)
        B = jnp.zeros(mu.shape[:-1] + (self.dim, self.dim))
        for g, m, sl in zip(self.summands, self._blocks(mu), self._slices):
            B = B.at[..., sl, sl].set(g.poisson_tensor(m))
        return B

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        mu = as_state(mu, "mu", self.dim)
        return jnp.concatenate([g.casimirs(m) for g, m in zip(self.summands, self._blocks(mu))], axis=-1)

    def casimir_gradients(self, mu: ArrayLike) -> jax.Array:
        mu = as_state(mu, "mu", self.dim)
        rows = []
        for g, m, sl in zip(self.summands, self._blocks(mu), self._slices):
            G = g.casimir_gradients(m)  # (..., k_i, n_i)
            pad = [(0, 0)] * (G.ndim - 1) + [(sl.start, self.dim - sl.stop)]
            rows.append(jnp.pad(G, pad))
        return jnp.concatenate(rows, axis=-2)

    def _coadjoint_flow(self, alpha, t, mu):
        return jnp.concatenate([g._coadjoint_flow(a, t, m)
                                for g, a, m in zip(self.summands, self._blocks(alpha), self._blocks(mu))], axis=-1)

    def _coadjoint_increment(self, alpha, t, mu):
        return jnp.concatenate([g._coadjoint_increment(a, t, m)
                                for g, a, m in zip(self.summands, self._blocks(alpha), self._blocks(mu))], axis=-1)

    def _flow_parameters(self, mu0, mu1, t, casimir_gradients):
        # Each summand's Casimirs depend on its own block only: the problem separates.
        out, row = [], 0
        for g, sl in zip(self.summands, self._slices):
            k = g.n_casimirs
            out.append(g._flow_parameters(mu0[..., sl], mu1[..., sl], t, casimir_gradients[..., row:row + k, sl]))
            row += k
        return jnp.concatenate(out, axis=-1)

    def definition(self) -> dict[str, Any]:
        return {"kind": "DirectSum", "name": self.name, "summands": [g.definition() for g in self.summands]}

    def value_key(self) -> tuple[Any, ...]:
        return ("DirectSum", self.name, tuple(_key(g) for g in self.summands))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, DirectSum) and self.value_key() == other.value_key()

    def __hash__(self) -> int:
        return hash(self.value_key())


def _key(g: AbstractLieAlgebra) -> Any:
    key = getattr(g, "value_key", None)
    return key() if key is not None else id(g)
