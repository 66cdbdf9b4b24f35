r"""The Poisson system of a G-LPNet's learned Hamiltonian $\widetilde H = w\sum_s
\Phi_s(\langle\alpha_s, y\rangle)$ on the bracket of the system it was trained on: the bridge
from a trained network to every classical splitting method."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from liepoisson import JAX as _JAX
from liepoisson.systems import AbstractPoissonSystem, CollectiveTerm

from ._learned_terms import ridge_potential
from ._mlp import activation_antiderivative

if TYPE_CHECKING:
    from ._glpnet import GLPNet


class LearnedHamiltonian(AbstractPoissonSystem):
    r"""$\dot y = \mathbb B(y)\nabla\widetilde H(y)$ with the bracket, Casimirs and test flows of
    `net.system` and $\widetilde H$ the network's learned Hamiltonian (its parameters frozen,
    as numpy). `hamiltonian_splitting()` is one `CollectiveTerm` per module, in module order,
    so `integrators.splitting.Splitting(LearnedHamiltonian(net), h, net.method)` reproduces the
    network's step and the other methods of `integrators.splitting` run on the same learned
    Hamiltonian. The heyoka right-hand side works too (`ground_truth` of the learned dynamics).

    Built by `GLPNet.learned_system()`.
    """

    def __init__(self, net: GLPNet):
        self.base = net.system
        self.name = f"learned_{net.system.name}"
        self.dim = net.system.dim
        terms = net.terms
        self.activation = terms.activation
        self._antiderivative = activation_antiderivative(terms.activation)
        self.vectors = np.asarray(terms.vectors(), dtype=np.float64)
        self.weight = float(net.hamiltonian_weight)
        self.a = self.weight * np.asarray(terms.a_values(), dtype=np.float64)
        self.b = self.weight * np.asarray(terms.bias_values(), dtype=np.float64)
        self.e = self.weight * (np.zeros_like(self.a) if terms.e is None else np.asarray(terms.e, dtype=np.float64))

    @property
    def params(self):
        return {
            "base": self.base.name,
            "activation": self.activation,
            "vectors": self.vectors.tolist(),
            "a": self.a.tolist(),
            "b": self.b.tolist(),
            "e": self.e.tolist(),
        }

    @property
    def state_names(self):
        return self.base.state_names

    def hamiltonian_components(self, y, xp):
        total = 0.0
        for alpha, a, b, e in zip(self.vectors, self.a, self.b, self.e):
            s = sum(float(alpha[d]) * y[d] for d in range(self.dim) if alpha[d] != 0.0)
            total = total + ridge_potential(s, float(a), float(b), float(e), self._antiderivative, xp)
        return total

    def poisson_tensor_components(self, y):
        return self.base.poisson_tensor_components(y)

    @property
    def casimir_polynomials(self):
        return self.base.casimir_polynomials

    def casimirs(self, y):
        return self.base.casimirs(y)

    def casimir_gradients(self, y):
        return self.base.casimir_gradients(y)

    @property
    def n_casimirs(self):
        return self.base.n_casimirs

    def _test_flow(self, alpha, t, y):
        return self.base._test_flow(alpha, t, y)

    def _test_flow_increment(self, alpha, t, y):
        return self.base._test_flow_increment(alpha, t, y)

    def test_flow_parameters(self, y0, y1, t, *, rtol=1e-10):
        return self.base.test_flow_parameters(y0, y1, t, rtol=rtol)

    def hamiltonian_splitting(self):
        r"""$\widetilde H = \sum_s w\Phi_s(\langle\alpha_s, y\rangle)$, module by module."""
        return tuple(
            CollectiveTerm(
                alpha,
                lambda s, a=float(a), b=float(b), e=float(e): ridge_potential(
                    s[0], a, b, e, self._antiderivative, _JAX),
                name=f"module{k + 1}",
            )
            for k, (alpha, a, b, e) in enumerate(zip(self.vectors, self.a, self.b, self.e))
        )



