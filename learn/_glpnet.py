r"""G-LPNets (paper section "G-LPNets: Derivation and test cases"): compositions of modules
$\widetilde{\mathbb T}_s y = \exp\!\big(\tfrac hM\,q_s(y)\,\mathbb M(\alpha_s)\big)y$,
$q_s = a_s\,\sigma(\langle\alpha_s, y\rangle) + b_s$ (eq. G_LPNets_moduli).

Each module is the exact flow of $\varphi_s(\langle\alpha_s, y\rangle)$ with
$\varphi_s' = a_s\sigma + b_s$, because $\langle\alpha_s, y\rangle$ is conserved along the flow
of a linear test Hamiltonian $\langle\alpha_s, y\rangle$: every module, hence the network, is an
exact Poisson map.
"""

from __future__ import annotations

import time
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap, TrainingRecord, replace
from ._data import prepare
from ._mlp import ACTIVATIONS, as_key, check_activation
from ._quasi_newton import check_method, minimiser
from ._rollout import state_mse
from ._validation import check_system, positive_float, positive_int


def _check_order(order: Any, n_modules: int, dim: int) -> tuple[int, ...]:
    if order is None:
        return tuple(s % dim for s in range(n_modules))
    try:
        order = tuple(order)
    except TypeError as err:
        raise TypeError(f"order must be a sequence of basis indices; got {order!r}") from err
    if len(order) != n_modules:
        raise ValueError(f"order must have n_modules = {n_modules} entries; got {len(order)}")
    for s, k in enumerate(order):
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < dim:
            raise ValueError(f"order[{s}] must be a basis index in [0, {dim}); got {k!r}")
    return tuple(int(k) for k in order)


class GLPNet(AbstractLearnedMap):
    r"""Global Lie-Poisson network: $M$ modules $\widetilde{\mathbb T}_s$, each a rescaled exact
    test flow over $h/M$ (paper eqs. G_LPNets_moduli, Loss_function_G_LPNets).

    By default $\alpha_s = c_s\,e_{k(s)}$ with $k$ cycling over the basis ($e_1, e_2, e_3, e_1,
    \ldots$, paper eq. Rot_sequence): three scalars $(a_s, c_s, b_s)$ per module, 18 parameters
    for 6 modules. `full_vectors=True` learns $\alpha_s\in\mathbb R^n$. Exactly Poisson and
    Casimir-conserving for any parameters.

    **Arguments:** `system`; `n_modules` $M$; `order` of the basis vectors (default cycling);
    `key`; `full_vectors`; `activation` $\sigma$ (paper: sigmoid); `h` (set by `fit`).
    """

    a: jax.Array
    c: jax.Array
    b: jax.Array
    system: AbstractPoissonSystem = eqx.field(static=True)
    order: tuple[int, ...] = eqx.field(static=True)
    full_vectors: bool = eqx.field(static=True)
    activation: str = eqx.field(static=True)
    h: float | None = eqx.field(static=True)
    record: TrainingRecord | None = eqx.field(static=True)

    def __init__(
        self,
        system: Any,
        n_modules: int = 6,
        order: Any = None,
        key: Any = 0,
        *,
        full_vectors: bool = False,
        activation: str = "sigmoid",
        h: float | None = None,
    ):
        self.system = check_system(system)
        n_modules = positive_int(n_modules, "n_modules")
        self.order = _check_order(order, n_modules, system.dim)
        self.full_vectors = bool(full_vectors)
        self.activation = check_activation(activation)
        self.h = None if h is None else positive_float(h, "h")
        self.a, self.c, self.b = self._initial(as_key(key), n_modules)
        self.record = None

    def _initial(self, key, n_modules):
        ka, kc, kb = jax.random.split(key, 3)
        shape = (n_modules, self.system.dim) if self.full_vectors else (n_modules,)
        a = jax.random.normal(ka, (n_modules,), jnp.float64)
        c = jax.random.normal(kc, shape, jnp.float64)
        b = 0.1 * jax.random.normal(kb, (n_modules,), jnp.float64)
        return a, c, b

    @property
    def n_modules(self) -> int:
        return len(self.order)

    def module_vectors(self) -> jax.Array:
        r"""The vectors $\alpha_s$, shape `(n_modules, dim)`."""
        if self.full_vectors:
            return self.c
        return self.c[:, None] * jnp.eye(self.system.dim)[jnp.asarray(self.order)]

    def _step(self, y):
        act = ACTIVATIONS[self.activation]
        vectors = self.module_vectors()
        dt = self.h / self.n_modules
        for s in range(self.n_modules):
            alpha = vectors[s]
            q = self.a[s] * act(jnp.dot(alpha, y)) + self.b[s]
            y = self.system.test_flow(q * alpha, dt, y)
        return y

    def hyperparameters(self):
        return {
            "n_modules": self.n_modules,
            "order": list(self.order),
            "full_vectors": self.full_vectors,
            "activation": self.activation,
        }

    @classmethod
    def _skeleton(cls, system, hp):
        return cls(system, hp["n_modules"], hp["order"], 0, full_vectors=hp["full_vectors"],
                   activation=hp["activation"])

    def fit(
        self,
        data: Any,
        method: str = "bfgs",
        max_iter: int = 3500,
        restarts: int = 4,
        seed: int = 0,
        h: float | None = None,
        progress: bool = True,
        validation_fraction: float = 0.0,
        warm_start: bool = True,
    ) -> GLPNet:
        r"""Minimise the state MSE (paper eq. Loss_function_G_LPNets) with a quasi-Newton method
        and JAX gradients; returns the fitted network (a new object).

        **Arguments:**

        - `data`: an `integrators.Trajectories`, or `(y0, y1)` arrays with `h`.
        - `method`: `"bfgs"` (SciPy BFGS, `jac=True`, the paper's choice), `"lbfgsb"` (SciPy
          L-BFGS-B) or `"lbfgs"` (optax L-BFGS with zoom line search, compiled in chunks).
        - `max_iter` iterations per start; `restarts` starts in total: the first from the
          current parameters, the others from random ones seeded by `seed`; the best kept
          (lowest validation loss if `validation_fraction > 0`, else training loss).
        - `validation_fraction`: held-out pairs (default 0: the paper trains on all pairs).
        - `warm_start`: each start first fits the same network with the identity activation
          (modules are then flows of quadratics $\tfrac a2 s^2 + bs$, a smooth problem BFGS
          solves to high accuracy from random starts) for half of `max_iter`, then maps it onto
          the linear regime of $\sigma$ (`linear_to_activation`) and refines with $\sigma$ for
          the other half. From random sigmoid starts BFGS stalls in a first-order-splitting
          basin (MSE ~1e-6 on E6); the warm start reaches the paper's < 5e-10.
        """
        method = check_method(method)
        max_iter = positive_int(max_iter, "max_iter")
        restarts = positive_int(restarts, "restarts")
        seed = positive_int(seed, "seed", minimum=0)
        pairs = prepare(data, self.system, h, validation_fraction, seed)
        net = replace(self, h=pairs.h)
        X, Y = jnp.asarray(pairs.y0), jnp.asarray(pairs.y1)
        Xv, Yv = jnp.asarray(pairs.y0_val), jnp.asarray(pairs.y1_val)
        params, static = eqx.partition(net, eqx.is_inexact_array)
        flat0, unravel = ravel_pytree(params)

        def loss(x, X, Y):
            return state_mse(eqx.combine(unravel(x), static), X, Y)

        evaluate = jax.jit(loss)
        # Compiled once per fit and reused by every start (and stage).
        minimise = minimiser(method, loss, X, Y)
        use_warm_start = warm_start and self.activation != "identity"
        if use_warm_start:
            lin_params, lin_static = eqx.partition(replace(net, activation="identity"), eqx.is_inexact_array)
            lin_unravel = ravel_pytree(lin_params)[1]  # same flat layout, other static metadata

            def linear_loss(x, X, Y):
                return state_mse(eqx.combine(lin_unravel(x), lin_static), X, Y)

            minimise_linear = minimiser(method, linear_loss, X, Y)
        start = time.perf_counter()
        results = []
        base = jax.random.PRNGKey(seed)
        for r in range(restarts):
            if r == 0:
                x0 = flat0
            else:
                a, c, b = net._initial(jax.random.fold_in(base, r), net.n_modules)
                x0 = ravel_pytree(eqx.filter(replace(net, a=a, c=c, b=b), eqx.is_inexact_array))[0]
            desc = f"GLPNet {method} start {r + 1}/{restarts}"
            if use_warm_start:
                x, hist = _warm_start(
                    net, unravel, static, lin_unravel, lin_static, x0, X, minimise_linear, minimise,
                    max_iter, progress, desc,
                )
            else:
                x, hist = minimise(x0, max_iter, progress, desc)
            train = float(evaluate(x, X, Y))
            val = float(evaluate(x, Xv, Yv)) if pairs.has_validation else float("nan")
            crit = val if pairs.has_validation else train
            results.append((crit if np.isfinite(crit) else np.inf, r, x, hist, train, val))
        wall = time.perf_counter() - start
        crit, best_r, x, hist, train, val = min(results, key=lambda t: (t[0], t[1]))
        if not np.isfinite(crit):
            raise FloatingPointError("GLPNet.fit: every start diverged (non-finite loss)")
        fitted = eqx.combine(unravel(jnp.asarray(x)), static)
        info = {
            "method": method,
            "max_iter": max_iter,
            "restarts": restarts,
            "seed": seed,
            "warm_start": bool(warm_start),
            "h": pairs.h,
            "best_restart": best_r,
            "restart_train_losses": [t[4] for t in sorted(results, key=lambda t: t[1])],
            "iterations": int(hist["epoch"][-1]) if len(hist["epoch"]) else 0,
            "n_train": int(X.shape[0]),
            "n_val": int(Xv.shape[0]),
        }
        history = dict(hist)
        history["val_loss"] = np.full_like(history["train_loss"], np.nan)
        if pairs.has_validation and len(history["val_loss"]):
            history["val_loss"][-1] = val
        return replace(fitted, record=TrainingRecord(history, train, val, wall, info))


def linear_to_activation(net: GLPNet, linear: GLPNet, X: jax.Array, width: float = 0.05) -> GLPNet:
    r"""The `net` (activation $\sigma$) that reproduces the identity-activation `linear` to
    first order in the linear regime of $\sigma$.

    With $\alpha'_s = \epsilon_s\alpha_s$ the rate $q'_s\alpha'_s$ must equal $q_s\alpha_s$, so
    $q'_s = (a_s\langle\alpha_s, y\rangle + b_s)/\epsilon_s$. With
    $\sigma(x) \approx \sigma_0 + \sigma_1 x$: $a'_s = a_s/(\sigma_1\epsilon_s^2)$,
    $b'_s = b_s/\epsilon_s - \sigma_0 a'_s$. $\epsilon_s$ keeps
    $|\epsilon_s\langle\alpha_s, y\rangle| \le$ `width` on the data, where the neglected
    curvature is a relative $O(\text{width}^2)$.
    """
    act = ACTIVATIONS[net.activation]
    s0, s1 = float(act(0.0)), float(jax.grad(act)(0.0))
    if s1 == 0.0:
        raise ValueError(f"warm start needs an activation with sigma'(0) != 0; {net.activation!r} has 0")
    vectors = linear.module_vectors()
    spread = jnp.max(jnp.abs(X @ vectors.T), axis=0)  # max |<alpha_s, y>| over the data
    eps = width / jnp.maximum(spread, 1e-300)
    a = linear.a / (s1 * eps**2)
    b = linear.b / eps - s0 * a
    c = linear.c * (eps[:, None] if net.full_vectors else eps)
    return replace(net, a=a, c=c, b=b)


def _warm_start(net, unravel, static, lin_unravel, lin_static, x0, X, minimise_linear, minimise,
                max_iter, progress, desc):
    """Identity-activation fit, mapped onto sigma's linear regime, then refined with sigma.

    The identity and sigma networks share their flat parameter layout (`a`, `c`, `b`); only the
    static activation (part of the pytree metadata) differs."""
    first = max(1, max_iter // 2)
    x_lin, h1 = minimise_linear(x0, first, progress, f"{desc} (identity)")
    mapped = linear_to_activation(
        eqx.combine(unravel(x0), static), eqx.combine(lin_unravel(x_lin), lin_static), X
    )
    x_init = ravel_pytree(eqx.filter(mapped, eqx.is_inexact_array))[0]
    x, h2 = minimise(x_init, max(1, max_iter - first), progress, f"{desc} ({net.activation})")
    hist = {
        "epoch": np.concatenate([h1["epoch"], h2["epoch"] + (h1["epoch"][-1] if len(h1["epoch"]) else 0)]),
        "train_loss": np.concatenate([h1["train_loss"], h2["train_loss"]]),
    }
    return x, hist
