"""Math namespaces, so that a formula is written once and evaluated by numpy, JAX or heyoka.

A Hamiltonian or a Poisson tensor is written against the *components* of the state
(`y[0], y[1], ...`) and a namespace `xp` offering `sqrt, sin, cos, exp, log`. The components
may be numpy arrays, JAX arrays (batched or traced) or heyoka expressions.
"""

from __future__ import annotations

import types

import heyoka as _hy
import jax.numpy as _jnp
import numpy as _np

NUMPY = types.SimpleNamespace(
    name="numpy", sqrt=_np.sqrt, sin=_np.sin, cos=_np.cos, exp=_np.exp, log=_np.log
)
JAX = types.SimpleNamespace(
    name="jax", sqrt=_jnp.sqrt, sin=_jnp.sin, cos=_jnp.cos, exp=_jnp.exp, log=_jnp.log
)
HEYOKA = types.SimpleNamespace(
    name="heyoka", sqrt=_hy.sqrt, sin=_hy.sin, cos=_hy.cos, exp=_hy.exp, log=_hy.log
)
