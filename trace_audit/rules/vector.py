"""rtamt's discrete-time offline semantics over whole numpy columns.

rtamt parses every rule and defines what it means; its offline interpreter computes the
robustness one sample at a time in Python (about 10 us a sample and rule here), which puts
a fleet's days of cycles out of reach. This module walks the syntax tree rtamt parsed and
computes each node's robustness over a stretch's columns at once, with rtamt's own
definitions (``rtamt/semantics/stl/discrete_time/offline/ast_visitor.py``):

- a comparison ``l < r`` or ``l <= r`` is ``r - l``, ``>``/``>=`` is ``l - r``, ``==`` is
  ``-|l - r|``, ``!==`` is ``|l - r|``; ``not`` negates; ``and``/``or`` are the minimum and
  maximum; ``implies`` is ``max(-l, r)``, ``iff`` ``-|l - r|``, ``xor`` ``|l - r|``;
- ``always[a:b]`` at step ``i`` is the minimum over steps ``i+a .. i+b``, ``eventually[a:b]``
  the maximum; ``historically[a:b]`` the minimum over ``i-b .. i-a``, ``once[a:b]`` the
  maximum; ``l since[a:b] r`` the maximum over ``d`` in ``a .. b`` of
  ``min(r[i-d], l[i-d+1 .. i])``; ``prev``/``next`` the step before or after;
- ``+``, ``-``, ``*`` and ``abs`` as IEEE doubles, the same operations in the same order as
  rtamt's, so the values are the same bits.

Only steps whose horizon lies inside the stretch are ever read (``rules.judge``), and there
every value is rtamt's; what either computes at a truncated edge is never used. A formula
using any other operator (``until``, ``rise``, ``fall``, ``/``, ``sqrt``, ``exp``, ``pow``:
where Python raises on a zero or a negative, numpy would go on) is not compiled here:
``compile_columns`` returns None and rtamt evaluates it sample by sample.
``tests/trace_audit/rules/test_vector_matches_rtamt.py`` pins the two to each other.
"""

from __future__ import annotations

from collections.abc import Callable, Container, Mapping, Sequence
from fractions import Fraction
from typing import Protocol, TypeGuard

import numpy as np
from numpy.typing import NDArray

from trace_runtime.errors import TraceError

__all__ = ["BoundedNode", "Columns", "StlNode", "compile_columns", "is_bounded"]

Columns = Callable[[Mapping[str, NDArray[np.float64]], int], NDArray[np.float64]]
"""Robustness at each step of a stretch: its columns by rtamt identifier, and its length."""

_Column = NDArray[np.float64]
_Binary = Callable[[_Column, _Column], _Column]


# --- rtamt's syntax tree, as read here and by ``rules.formula`` --------------------------
# rtamt ships no type information; these say what is read of its nodes
# (``rtamt/syntax/node``). A node's kind is its class name; the guards below narrow a node
# to the attributes its kind has.


class StlNode(Protocol):
    """A node of the tree rtamt parsed: every kind has its operands as ``children``."""

    @property
    def children(self) -> Sequence[StlNode]: ...


class BoundedNode(StlNode, Protocol):
    """A temporal operator with an interval (``always[a:b]``: rtamt's ``Interval``); a bound
    is a ``Fraction`` of its unit (``""`` or None: seconds)."""

    @property
    def begin(self) -> Fraction | int: ...
    @property
    def end(self) -> Fraction | int: ...
    @property
    def begin_unit(self) -> str | None: ...
    @property
    def end_unit(self) -> str | None: ...


class _VariableNode(StlNode, Protocol):
    @property
    def var(self) -> str: ...
    @property
    def field(self) -> str | None: ...


class _ConstantNode(StlNode, Protocol):
    @property
    def val(self) -> float: ...


class _Operator(Protocol):
    @property
    def value(self) -> int: ...


class _PredicateNode(StlNode, Protocol):
    @property
    def operator(self) -> _Operator: ...


def is_bounded(node: StlNode, kinds: Container[str]) -> TypeGuard[BoundedNode]:
    """Whether ``node`` is of one of ``kinds``, temporal operators with an interval."""
    return type(node).__name__ in kinds


def _is_variable(node: StlNode) -> TypeGuard[_VariableNode]:
    return type(node).__name__ == "Variable"


def _is_constant(node: StlNode) -> TypeGuard[_ConstantNode]:
    return type(node).__name__ == "Constant"


def _is_predicate(node: StlNode) -> TypeGuard[_PredicateNode]:
    return type(node).__name__ == "Predicate"


_UNITS = {"": Fraction(1), "s": Fraction(1), "ms": Fraction(1, 1000), "us": Fraction(1, 10**6)}
_UNITS["ns"] = Fraction(1, 10**9)
_BINARY: dict[str, _Binary] = {
    "Addition": np.add,
    "Subtraction": np.subtract,
    "Multiplication": np.multiply,
    "Conjunction": np.minimum,
    "Disjunction": np.maximum,
    "Implies": lambda left, right: np.maximum(-left, right),
    "Iff": lambda left, right: -np.abs(left - right),
    "Xor": lambda left, right: np.abs(left - right),
}
_UNARY: dict[str, Callable[[_Column], _Column]] = {
    "Neg": np.negative,
    "Abs": np.abs,
}
_WINDOWS = {
    # operator -> (reduction, looks ahead, value beyond the stretch)
    "TimedAlways": (np.minimum, True, np.inf),
    "TimedEventually": (np.maximum, True, -np.inf),
    "TimedHistorically": (np.minimum, False, np.inf),
    "TimedOnce": (np.maximum, False, -np.inf),
}
_STEPS = {
    # operator -> (looks ahead, value beyond the stretch)
    "Previous": (False, np.inf),
    "StrongPrevious": (False, -np.inf),
    "Next": (True, np.inf),
    "StrongNext": (True, -np.inf),
}


class _UnsupportedError(TraceError):
    """An operator this module does not compute: rtamt evaluates the formula."""


def compile_columns(node: StlNode, period_ns: int) -> Columns | None:
    """The robustness of rtamt's parsed ``node`` over whole columns, at ``period_ns``; None
    when ``node`` uses an operator only rtamt's own interpreter computes."""
    try:
        return _compile(node, Fraction(period_ns, 10**9))
    except _UnsupportedError:
        return None


def _compile(node: StlNode, period_s: Fraction) -> Columns:
    kind = type(node).__name__
    children = [_compile(c, period_s) for c in _operands(node, kind)]
    if _is_variable(node):
        if node.field:
            raise _UnsupportedError(kind)
        name = node.var
        return lambda columns, n: columns[name]
    if _is_constant(node):
        value = float(node.val)
        return lambda columns, n: np.full(n, value)
    if _is_predicate(node):
        left, right = children
        compare = _comparison(node.operator.value)
        return lambda columns, n: compare(left(columns, n), right(columns, n))
    if kind in _BINARY:
        left, right = children
        binary = _BINARY[kind]
        return lambda columns, n: binary(left(columns, n), right(columns, n))
    if kind in _UNARY:
        (inner,) = children
        unary = _UNARY[kind]
        return lambda columns, n: unary(inner(columns, n))
    if is_bounded(node, _WINDOWS):
        (inner,) = children
        reduce, ahead, beyond = _WINDOWS[kind]
        begin, end = _steps(node, period_s)
        return lambda columns, n: _window(
            inner(columns, n), begin, end, reduce, ahead=ahead, beyond=beyond
        )
    if kind in _STEPS:
        (inner,) = children
        ahead, beyond = _STEPS[kind]
        return lambda columns, n: _shift(inner(columns, n), 1 if ahead else -1, beyond)
    if is_bounded(node, ("TimedSince",)):
        left, right = children
        begin, end = _steps(node, period_s)
        return lambda columns, n: _since(left(columns, n), right(columns, n), begin, end)
    raise _UnsupportedError(kind)


def _operands(node: StlNode, kind: str) -> list[StlNode]:
    """The operands rtamt's interpreter reads: the first one or two children (its parser
    can attach an operand more than once, e.g. to ``not`` and to ``x + x``)."""
    arity = 2 if kind in _BINARY or kind in ("Predicate", "TimedSince") else 1
    return list(node.children)[:arity] if node.children else []


def _comparison(
    operator: int,
) -> Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]:
    """By the operator's number, as rtamt's interpreter compares them: 0 ``<``, 1 ``<=``,
    2 ``==``, 3 ``!==``, 4 ``>``, 5 ``>=``."""
    if operator in (0, 1):
        return lambda left, right: right - left
    if operator in (4, 5):
        return lambda left, right: left - right
    if operator == 2:
        return lambda left, right: -np.abs(left - right)
    if operator == 3:
        return lambda left, right: np.abs(left - right)
    raise _UnsupportedError(str(operator))


def _steps(node: BoundedNode, period_s: Fraction) -> tuple[int, int]:
    """A bounded operator's ``[begin, end]`` in whole steps (the bounds are multiples of the
    period: ``Formula`` checked them before rtamt would have)."""
    begin_unit = str(node.begin_unit or node.end_unit or "")
    end_unit = str(node.end_unit or "")
    if begin_unit not in _UNITS or end_unit not in _UNITS:
        raise _UnsupportedError(begin_unit or end_unit)
    begin = Fraction(node.begin) * _UNITS[begin_unit] / period_s
    end = Fraction(node.end) * _UNITS[end_unit] / period_s
    if begin.denominator != 1 or end.denominator != 1:
        raise _UnsupportedError("bound")
    return int(begin), int(end)


def _shift(x: NDArray[np.float64], by: int, beyond: float) -> NDArray[np.float64]:
    """``x`` read ``by`` steps later (earlier when negative), ``beyond`` outside it."""
    n = len(x)
    out = np.full(n, beyond)
    if by == 0:
        out[:] = x
    elif abs(by) < n:
        if by > 0:
            out[: n - by] = x[by:]
        else:
            out[-by:] = x[: n + by]
    return out


def _window(
    x: NDArray[np.float64],
    begin: int,
    end: int,
    reduce: _Binary,
    *,
    ahead: bool,
    beyond: float,
) -> NDArray[np.float64]:
    """The reduction of ``x`` over steps ``i+begin .. i+end`` (ahead) or ``i-end .. i-begin``
    at each step ``i``; a window reaching outside ``x`` reads ``beyond`` there."""
    sign = 1 if ahead else -1
    out = _shift(x, sign * begin, beyond)
    for offset in range(begin + 1, end + 1):
        out = reduce(out, _shift(x, sign * offset, beyond))
    return out


def _since(
    left: NDArray[np.float64], right: NDArray[np.float64], begin: int, end: int
) -> NDArray[np.float64]:
    """``left since[begin:end] right``: the best ``d`` steps back in ``begin .. end`` at
    which ``right`` held, with ``left`` holding at every step after it up to now."""
    held = np.full(len(left), np.inf)  # min of left over the steps i-d+1 .. i
    out = np.full(len(left), -np.inf)
    for d in range(end + 1):
        if d > 0:
            held = np.minimum(held, _shift(left, -(d - 1), np.inf))
        if d >= begin:
            out = np.maximum(out, np.minimum(_shift(right, -d, -np.inf), held))
    return out
