r"""Expression trees: a formula written against the namespace `xp` (a Hamiltonian
`H(mu, xp)`, a splitting piece $\varphi(s)$), evaluated once on symbols, becomes plain data
that can be saved in a file and evaluated again by numpy, JAX or heyoka.

A tree is JSON: a number (a finite constant), `["y", i]` (the $i$-th argument), or
`[op, *arguments]` with `op` one of `add, sub, mul, div, pow, neg, sqrt, sin, cos, exp, log`.

Tracing also catches a formula that does not use `xp` (`np.sqrt`, `jnp.cos`, `math.exp`,
branches on the state): such a formula would fail later, deep inside JAX or heyoka.
"""

from __future__ import annotations

import math
import numbers
import types
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

_FUNCTIONS = ("sqrt", "sin", "cos", "exp", "log")
_BINARY = {"add", "sub", "mul", "div", "pow"}
_UNARY = {"neg", *_FUNCTIONS}
# numpy ufuncs that are plain arithmetic (e.g. `np.float64(2.0) * mu[0]`): allowed.
_UFUNC_OPS = {"add": "add", "subtract": "sub", "multiply": "mul", "true_divide": "div",
              "divide": "div", "power": "pow", "negative": "neg"}


class NotSymbolicError(TypeError):
    """A formula that does not evaluate on symbols (it bypasses `xp` or branches on the state)."""


def _hint(what: str) -> str:
    return (
        f"{what}; write the formula with Python operators and the functions of the namespace "
        "xp it is given (xp.sqrt, xp.sin, xp.cos, xp.exp, xp.log), not numpy, jax.numpy or math, "
        "and without branching on the state, so that numpy, JAX and heyoka can all evaluate it"
    )


def _operand(x: Any) -> Any:
    if isinstance(x, Symbol):
        return x.tree
    if isinstance(x, np.ndarray) and x.ndim == 0:
        x = x[()]
    if isinstance(x, numbers.Integral) and not isinstance(x, bool):
        return int(x)  # kept exact: `y ** 2` stays an integer power in JAX and heyoka
    if isinstance(x, numbers.Real) and not isinstance(x, bool):
        x = float(x)
        if not math.isfinite(x):
            raise NotSymbolicError(_hint(f"a constant in the formula is not finite ({x})"))
        return x
    raise NotSymbolicError(
        _hint(f"the formula combines a state component with a {type(x).__name__} ({x!r:.60})")
    )


class Symbol:
    """A node of an expression tree with Python's arithmetic operators."""

    __slots__ = ("tree",)
    __array_priority__ = 1000  # numpy defers `ndarray op Symbol` to us

    def __init__(self, tree: Any):
        self.tree = tree

    def _op(self, op: str, *others: Any) -> Symbol:
        return Symbol([op, self.tree, *(_operand(o) for o in others)])

    def _rop(self, op: str, other: Any) -> Symbol:
        return Symbol([op, _operand(other), self.tree])

    def __add__(self, o): return self._op("add", o)  # noqa: E704
    def __radd__(self, o): return self._rop("add", o)  # noqa: E704
    def __sub__(self, o): return self._op("sub", o)  # noqa: E704
    def __rsub__(self, o): return self._rop("sub", o)  # noqa: E704
    def __mul__(self, o): return self._op("mul", o)  # noqa: E704
    def __rmul__(self, o): return self._rop("mul", o)  # noqa: E704
    def __truediv__(self, o): return self._op("div", o)  # noqa: E704
    def __rtruediv__(self, o): return self._rop("div", o)  # noqa: E704
    def __pow__(self, o): return self._op("pow", o)  # noqa: E704
    def __rpow__(self, o): return self._rop("pow", o)  # noqa: E704
    def __neg__(self): return Symbol(["neg", self.tree])  # noqa: E704
    def __pos__(self): return self  # noqa: E704

    def _refuse(self, *_: Any) -> Any:
        raise NotSymbolicError(_hint("the formula branches on, or converts, a state component"))

    __bool__ = __float__ = __int__ = __index__ = __complex__ = _refuse
    __lt__ = __le__ = __gt__ = __ge__ = __abs__ = __floordiv__ = __mod__ = _refuse

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        op = _UFUNC_OPS.get(ufunc.__name__)
        if method != "__call__" or op is None or kwargs:
            raise NotSymbolicError(
                _hint(f"the formula calls numpy.{ufunc.__name__} on a state component")
            )
        if op == "neg":
            return Symbol(["neg", _operand(inputs[0])])
        return Symbol([op, _operand(inputs[0]), _operand(inputs[1])])

    def __array__(self, *_: Any, **__: Any):
        raise NotSymbolicError(_hint("the formula converts a state component to a numpy array"))

    def __jax_array__(self):
        raise NotSymbolicError(_hint("the formula passes a state component to jax.numpy"))

    def __repr__(self) -> str:
        return f"Symbol({self.tree!r})"


def _function(name: str) -> Callable[[Any], Any]:
    def f(x: Any) -> Any:
        if isinstance(x, Symbol):
            return Symbol([name, x.tree])
        return getattr(np, name)(_operand(x))  # a constant subexpression, e.g. xp.sqrt(2.0)

    f.__name__ = name
    return f


#: The namespace `xp` that records a formula as a tree.
SYMBOLIC = types.SimpleNamespace(name="symbolic", **{f: _function(f) for f in _FUNCTIONS})


def symbols(n: int) -> list[Symbol]:
    """`n` argument symbols `["y", 0] .. ["y", n-1]`."""
    return [Symbol(["y", i]) for i in range(n)]


def to_tree(value: Any, what: str) -> Any:
    """The tree of a traced result (a `Symbol` or a constant); `NotSymbolicError` otherwise."""
    if isinstance(value, Symbol):
        return value.tree
    try:
        return _operand(value)
    except NotSymbolicError:
        raise NotSymbolicError(
            _hint(f"{what} returned a {type(value).__name__}, not a scalar expression")
        ) from None


def trace(formula: Callable[[], Any], what: str) -> Any:
    """The tree of `formula()`, a zero-argument call of the user's formula on `symbols(...)`
    and `SYMBOLIC`; `NotSymbolicError` naming `what` (e.g. "hamiltonian") if it does not
    evaluate on symbols, whatever it raised."""
    try:
        return to_tree(formula(), what)
    except NotSymbolicError as err:
        raise NotSymbolicError(f"{what}: {err}") from None
    except Exception as err:  # jax.numpy, heyoka or user code refusing a Symbol
        raise NotSymbolicError(
            f"{what}: " + _hint(f"evaluating it on symbolic components raised {type(err).__name__}: "
                                f"{str(err).splitlines()[0] if str(err) else ''}")
        ) from err


def check_tree(tree: Any, n: int, what: str = "tree") -> Any:
    """`tree` if it is a well-formed tree in `n` arguments; `ValueError` naming `what` otherwise
    (e.g. a tree read from a damaged file)."""
    if isinstance(tree, bool) or not isinstance(tree, (int, float, list)):
        raise ValueError(f"{what} is not an expression tree: {tree!r:.80}")  # noqa: TRY004 (damaged data, not a wrong argument type)
    if isinstance(tree, (int, float)):
        if not math.isfinite(tree):
            raise ValueError(f"{what} holds a non-finite constant {tree}")
        return tree
    if not tree:
        raise ValueError(f"{what} holds an empty node")
    op, args = tree[0], tree[1:]
    if op == "y":
        if len(args) != 1 or isinstance(args[0], bool) or not isinstance(args[0], int) or not 0 <= args[0] < n:
            raise ValueError(f"{what} refers to argument {args!r}; expected one index in 0..{n - 1}")
        return tree
    arity = 2 if op in _BINARY else 1 if op in _UNARY else None
    if arity is None or len(args) != arity:
        raise ValueError(f"{what} holds an unknown node {op!r} with {len(args)} arguments")
    for a in args:
        check_tree(a, n, what)
    return tree


def evaluate(tree: Any, y: Sequence[Any], xp: Any) -> Any:
    """The value of `tree` at the arguments `y[0..n-1]` with the namespace `xp` (numpy, JAX,
    heyoka or `SYMBOLIC`)."""
    if isinstance(tree, (int, float)):
        return tree
    op = tree[0]
    if op == "y":
        return y[tree[1]]
    a = [evaluate(t, y, xp) for t in tree[1:]]
    if op == "add":
        return a[0] + a[1]
    if op == "sub":
        return a[0] - a[1]
    if op == "mul":
        return a[0] * a[1]
    if op == "div":
        return a[0] / a[1]
    if op == "pow":
        return a[0] ** a[1]
    if op == "neg":
        return -a[0]
    return getattr(xp, op)(a[0])


class TreeFunction:
    r"""A formula `(y, xp) -> value` rebuilt from its tree (what a loaded file gives back for a
    Hamiltonian written by the user); it traces to the same tree again."""

    def __init__(self, tree: Any, n: int):
        self.tree = check_tree(tree, n)
        self.n = n

    def __call__(self, y: Sequence[Any], xp: Any) -> Any:
        return evaluate(self.tree, y, xp)

    def __repr__(self) -> str:
        return f"TreeFunction({self.tree!r:.80})"


def addends(tree: Any) -> list[Any]:
    """The terms of the top-level sum of `tree` (differences and negations folded in as
    `["neg", t]`), in order: `a - (b + c)` -> `[a, neg b, neg c]`."""
    if isinstance(tree, list) and tree[0] == "add":
        return addends(tree[1]) + addends(tree[2])
    if isinstance(tree, list) and tree[0] == "sub":
        return addends(tree[1]) + [_negate(t) for t in addends(tree[2])]
    if isinstance(tree, list) and tree[0] == "neg":
        return [_negate(t) for t in addends(tree[1])]
    return [tree]


def _negate(tree: Any) -> Any:
    if isinstance(tree, (int, float)):
        return -tree
    return tree[1] if tree[0] == "neg" else ["neg", tree]


def polynomial_degree(tree: Any) -> int | None:
    """The degree of `tree` as a polynomial in its arguments, or None if it is not one (a
    function of an argument, a division by one, a non-integer power)."""
    if isinstance(tree, (int, float)):
        return 0
    op, args = tree[0], tree[1:]
    if op == "y":
        return 1
    d = [polynomial_degree(a) for a in args]
    if any(x is None for x in d):
        return None
    if op in ("add", "sub"):
        return max(d)
    if op == "neg":
        return d[0]
    if op == "mul":
        return d[0] + d[1]
    if op == "div":
        return d[0] if d[1] == 0 else None
    if op == "pow":
        e = args[1]
        if d[1] == 0 and d[0] == 0:
            return 0
        if isinstance(e, (int, float)) and float(e).is_integer() and e >= 0:
            return d[0] * int(e)
        return None
    return 0 if d[0] == 0 else None  # sqrt, sin, ... of a constant


_PRECEDENCE = {"add": 1, "sub": 1, "mul": 2, "div": 2, "neg": 3, "pow": 4}
_INFIX = {"add": " + ", "sub": " - ", "mul": "*", "div": "/", "pow": "**"}


def to_text(tree: Any, names: Sequence[str]) -> str:
    """`tree` as a Python formula in the argument `names` (for messages)."""

    def go(t: Any, outer: int) -> str:
        if isinstance(t, (int, float)):
            text = repr(t)
            return f"({text})" if t < 0 and outer > 1 else text
        op = t[0]
        if op == "y":
            return names[t[1]]
        if op in _INFIX:
            p = _PRECEDENCE[op]
            text = go(t[1], p) + _INFIX[op] + go(t[2], p + 1)
        elif op == "neg":
            p = _PRECEDENCE[op]
            text = "-" + go(t[1], p)
        else:
            return f"{op}({go(t[1], 0)})"
        return f"({text})" if p < outer else text

    return go(tree, 0)
