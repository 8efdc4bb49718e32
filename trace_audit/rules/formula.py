"""A rule's STL formula, parsed and evaluated by rtamt, and how far in time it looks.

``rtamt.StlDiscreteTimeSpecification`` parses the formula and defines its robustness in
discrete time, with the sampling period set to the log's; rtamt's interpreter computes it
sample by sample, and ``rules.vector`` computes the same values over whole columns for the
operators it covers (pinned to rtamt by the tests). This module

- checks the rule's shape: ``always(<body>)``, the body's temporal operators all bounded
  (``eventually[0:0.5]``, ``once[0:2]``, ``prev``, ``next``), so that every cycle's verdict
  depends on a known stretch of time around it (docs/rules.md, "The STL subset");
- renames the signals (``nearest.person``: rtamt reads a dot as a field of a variable) to
  plain identifiers and back;
- measures the body's horizon, how far into the past and the future its value at a cycle
  reads (``Horizon``), from the bounds in rtamt's own syntax tree: a cycle whose horizon
  reaches a gap or an end of the log is not decidable (``trace_audit.rules.check``).

rtamt is imported only when a rules file is read (the ``rules`` extra).
"""

from __future__ import annotations

import importlib
import logging
import math
import re
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from types import ModuleType
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trace_audit.rules.signals import FAMILIES, SIGNAL_PATTERN, bad_signal, signal_names
from trace_audit.rules.vector import BoundedNode, StlNode, compile_columns, is_bounded
from trace_runtime.errors import UsageError

__all__ = ["Formula", "Horizon", "RulesError", "compile_formula", "rtamt_module"]


class RulesError(UsageError):
    """A rules file, one of its rules or its formula cannot be used (exit 2); the message
    names the file and the rule."""


_UNITS = {"": Fraction(1), "s": Fraction(1), "ms": Fraction(1, 1000)}
_UNITS |= {"us": Fraction(1, 10**6), "ns": Fraction(1, 10**9)}

_FUTURE = frozenset(("TimedAlways", "TimedEventually", "TimedUntil"))
_PAST = frozenset(("TimedHistorically", "TimedOnce", "TimedSince", "TimedPrecedes"))
_STEP_FUTURE = frozenset(("Next", "StrongNext"))
_STEP_PAST = frozenset(("Previous", "StrongPrevious", "Rise", "Fall"))
_UNBOUNDED = frozenset(("Always", "Eventually", "Until", "Historically", "Once", "Since"))
_KEYWORDS = {kind: kind.lower() for kind in _UNBOUNDED}
_BOUNDED = _FUTURE | _PAST


class _StlAst(Protocol):
    @property
    def specs(self) -> Sequence[StlNode]: ...


class _Specification(Protocol):
    """What is used of an ``rtamt.StlDiscreteTimeSpecification`` (rtamt ships no type
    information): declare the signals, set the formula and the period, parse, evaluate
    offline (one ``[time, robustness]`` pair a sample)."""

    spec: str

    @property
    def ast(self) -> _StlAst: ...
    @property
    def free_vars(self) -> Iterable[str]: ...
    def declare_var(self, name: str, var_type: str) -> None: ...
    def set_sampling_period(self, period: int, unit: str, tolerance: float) -> None: ...
    def parse(self) -> None: ...
    def evaluate(self, dataset: Mapping[str, list[float]]) -> Sequence[Sequence[float]]: ...


_DOTTED = re.compile(r"(?<![\w.])[A-Za-z_]\w*(?:\.\w+)+")
_FAMILIES_HELP = "signals: " + ", ".join(f"{f}.*" for f in FAMILIES)

_SIGNALS_HELP = (
    "signals are command.<ACTION>, channel.<name>.intended|actual|deviation, "
    "nearest.<class>, factor.<name>, check.<rule>, flag.<name>, "
    "perception.sensors_unavailable|sensors_used[.<sensor>], evidence.age_s[.<sensor>]; "
    "docs/rules.md"
)

_ALWAYS = re.compile(r"\s*(?:always|G)\s*\(")


@dataclass(frozen=True, slots=True)
class Horizon:
    """How far a formula's value at a cycle reads around it: seconds of bounds plus single
    steps (``prev``/``next``, ``rise``/``fall``), into the past and into the future."""

    past_s: Fraction = Fraction(0)
    past_steps: int = 0
    future_s: Fraction = Fraction(0)
    future_steps: int = 0

    def steps(self, period_ns: int) -> tuple[int, int]:
        """(past, future) in cycles at ``period_ns``."""
        period_s = Fraction(period_ns, 10**9)
        return (
            math.ceil(self.past_s / period_s) + self.past_steps,
            math.ceil(self.future_s / period_s) + self.future_steps,
        )

    def span_ns(self, period_ns: int) -> tuple[int, int]:
        """(past, future) in ns at ``period_ns``: how much log to read around a window."""
        past, future = self.steps(period_ns)
        return past * period_ns, future * period_ns

    def widest(self, other: Horizon) -> Horizon:
        return Horizon(
            max(self.past_s, other.past_s),
            max(self.past_steps, other.past_steps),
            max(self.future_s, other.future_s),
            max(self.future_steps, other.future_steps),
        )


ENGINES = ("auto", "rtamt")
"""How ``Formula.monitor`` computes robustness (``check --engine``)."""

Monitor = Callable[[Mapping[str, "ArrayLike"]], "NDArray[np.float64]"]
"""A rule's robustness at each step of one stretch, from its columns by signal name."""


@dataclass(frozen=True, slots=True)
class Formula:
    """A rule's checked formula: the body under its ``always``, the signals it reads and
    its horizon. ``evaluate`` runs rtamt over one gap-free stretch of cycles."""

    rule: str
    stl: str
    body: str
    signals: tuple[str, ...]
    horizon: Horizon
    bounds: tuple[tuple[str, Fraction], ...] = ()
    """Each temporal bound, as shown in errors (``0.5 s``) and in seconds."""
    origin: str = ""
    """The rules file the rule is read from (named in errors found at evaluation)."""

    def evaluate(
        self, columns: Mapping[str, Sequence[float]], period_ns: int, *, engine: str = "auto"
    ) -> list[float]:
        """rtamt's robustness of the body at each sample of ``columns`` (one value per
        signal per consecutive cycle), in discrete time at ``period_ns``."""
        return [float(v) for v in self.monitor(period_ns, engine=engine)(columns)]

    def monitor(self, period_ns: int, *, engine: str = "auto") -> Monitor:
        """``evaluate`` at ``period_ns`` for many stretches: rtamt parses the formula once
        (its offline evaluation keeps no state between calls, so the one specification
        serves every stretch). ``engine``: ``auto`` computes rtamt's semantics over whole
        columns where ``rules.vector`` covers the formula's operators, and has rtamt's own
        interpreter evaluate the rest (and any stretch where a value is NaN, e.g. +inf
        minus +inf, whose ordering rules differ); ``rtamt`` always asks rtamt."""
        if engine not in ENGINES:
            raise RulesError(f"unknown rules engine {engine!r} (use {', '.join(ENGINES)})")
        spec = self._spec(period_ns)
        columns_fn = compile_columns(spec.ast.specs[0], period_ns) if engine == "auto" else None
        idents = {name: _ident(i) for i, name in enumerate(self.signals)}

        def run(columns: Mapping[str, ArrayLike]) -> NDArray[np.float64]:
            data = {idents[k]: np.asarray(v, dtype=np.float64) for k, v in columns.items()}
            n = len(next(iter(data.values()))) if data else 0
            if columns_fn is not None and n:
                with np.errstate(all="ignore"):
                    out = columns_fn(data, n) + 0.0  # + 0.0: no -0 robustness
                if not np.isnan(out).any():
                    return out
            return np.array(self._robustness(spec, columns, period_ns), dtype=np.float64)

        return run

    def _robustness(
        self, spec: _Specification, given: Mapping[str, ArrayLike], period_ns: int
    ) -> list[float]:
        columns = {k: np.asarray(v, dtype=np.float64).tolist() for k, v in given.items()}
        n = len(next(iter(columns.values()))) if columns else 0
        if n == 0:
            return []
        columns = {k: np.asarray(v, dtype=np.float64).tolist() for k, v in columns.items()}
        # rtamt's offline evaluate fails on a single sample (it measures the sampling period
        # between samples: UnboundLocalError). A one-cycle stretch is given twice; the copy's
        # values are never read back, and the one cycle is decidable only when the horizon
        # is 0 (no prev/next, no bound), where its value depends on that cycle alone.
        m = max(n, 2)
        data: dict[str, list[float]] = {"time": [i * period_ns / 1e9 for i in range(m)]}
        for i, name in enumerate(self.signals):
            values = list(columns[name])
            data[_ident(i)] = values + values[-1:] * (m - n)
        try:
            out = spec.evaluate(data)
        except _rtamt_errors() as err:
            raise RulesError(f"rule {self.rule!r}: {_message(err, self.signals)}") from err
        except Exception as err:
            raise RulesError(
                f"rule {self.rule!r}: rtamt could not evaluate it over {n} cycle"
                f"{'s' if n != 1 else ''} ({type(err).__name__}: {err})"
            ) from err
        return [float(value) + 0.0 for _, value in out[:n]]  # + 0.0: no -0 robustness

    def _spec(self, period_ns: int) -> _Specification:
        period_s = Fraction(period_ns, 10**9)
        for text, seconds in self.bounds:
            if seconds % period_s:
                where = f"{self.origin}: " if self.origin else ""
                raise RulesError(
                    f"{where}rule {self.rule!r}: the bound {text} is not a multiple of the "
                    f"sampling period, the log's cycle period {float(period_s):g} s (rtamt "
                    "steps in whole cycles)"
                )
        spec = _specification(self.signals)
        spec.set_sampling_period(period_ns, "ns", 0.5)
        spec.spec = _renamed(self.body, self.signals)
        _parse(spec, self.rule, self.signals)
        return spec


def compile_formula(rule: str, stl: str, *, origin: str = "") -> Formula:
    """``stl`` checked as a rule (``always`` of a body with bounded operators), or
    ``RulesError`` naming ``rule`` and what is wrong (``origin``: the rules file, named in
    errors found when the rule is evaluated)."""
    for m in _DOTTED.finditer(stl):
        if m.group(0).partition(".")[0] not in FAMILIES:
            raise RulesError(f"rule {rule!r}: unknown signal {m.group(0)!r} ({_FAMILIES_HELP})")
    names = signal_names(stl)
    for name in names:
        problem = bad_signal(name)
        if problem is not None:
            raise RulesError(f"rule {rule!r}: {problem}")
    body = _body(rule, stl)
    spec = _specification(names)
    spec.spec = _renamed(body, names)
    _parse(spec, rule, names)
    unknown = sorted(set(spec.free_vars) - {_ident(i) for i in range(len(names))})
    if unknown:
        raise RulesError(f"rule {rule!r}: unknown signal {unknown[0]!r} ({_SIGNALS_HELP})")
    if not names:
        raise RulesError(f"rule {rule!r}: the formula reads no signal")
    _check_intervals(spec.ast.specs[0], rule)
    horizon = _horizon(spec.ast.specs[0], rule)
    return Formula(rule, stl, body, names, horizon, _bounds(spec.ast.specs[0]), origin)


def _check_intervals(node: StlNode, rule: str) -> None:
    """Every bounded operator's interval is ``[a:b]`` with ``0 <= a <= b`` (rtamt takes a
    reversed or negative one and evaluates every cycle to an infinity)."""
    kind = type(node).__name__
    if is_bounded(node, _BOUNDED):
        begin = Fraction(node.begin) * _UNITS.get(str(node.begin_unit or ""), Fraction(1))
        end = _end(node)
        if begin < 0 or end < begin:
            op = kind.removeprefix("Timed").lower()
            raise RulesError(
                f"rule {rule!r}: the interval of {op}[{float(begin):g}:{float(end):g}] must "
                "be [a:b] with 0 <= a <= b (seconds)"
            )
    for child in node.children:
        _check_intervals(child, rule)


def _bounds(node: StlNode) -> tuple[tuple[str, Fraction], ...]:
    """Every temporal bound under ``node``: as shown (``0.05 s``) and in seconds."""
    out: list[tuple[str, Fraction]] = []
    if is_bounded(node, _BOUNDED):
        for value, unit in ((node.begin, node.begin_unit), (node.end, node.end_unit)):
            seconds = Fraction(value) * _UNITS.get(str(unit or ""), Fraction(1))
            out.append((f"{float(seconds):g} s", seconds))
    for child in node.children:
        out.extend(_bounds(child))
    return tuple(out)


def _body(rule: str, stl: str) -> str:
    """The formula under the rule's top-level ``always(...)``."""
    start = _ALWAYS.match(stl)
    if start is not None:
        depth = 0
        for i in range(start.end() - 1, len(stl)):
            depth += {"(": 1, ")": -1}.get(stl[i], 0)
            if depth == 0:
                if not stl[i + 1 :].strip():
                    return stl[start.end() : i]
                break
    if stl.count("(") != stl.count(")"):
        raise RulesError(
            f"rule {rule!r}: unbalanced parentheses ({stl.count('(')} opened, "
            f"{stl.count(')')} closed) in {stl.strip()!r}"
        )
    raise RulesError(
        f"rule {rule!r}: a rule is always(<formula>), a requirement on every cycle "
        f"(got {stl.strip()!r})"
    )


def _horizon(node: StlNode, rule: str) -> Horizon:
    kind = type(node).__name__
    if kind in _UNBOUNDED:
        op = _KEYWORDS[kind]
        example = f"a {op}[0:0.5] b" if kind in ("Until", "Since") else f"{op}[0:0.5](...)"
        raise RulesError(
            f"rule {rule!r}: an unbounded {op} inside the rule reads the whole log; "
            f"give it a bound, e.g. {example}"
        )
    inner = Horizon()
    for child in node.children:
        inner = inner.widest(_horizon(child, rule))
    if is_bounded(node, _FUTURE):
        return Horizon(
            inner.past_s, inner.past_steps, inner.future_s + _end(node), inner.future_steps
        )
    if is_bounded(node, _PAST):
        return Horizon(
            inner.past_s + _end(node), inner.past_steps, inner.future_s, inner.future_steps
        )
    if kind in _STEP_FUTURE:
        return Horizon(inner.past_s, inner.past_steps, inner.future_s, inner.future_steps + 1)
    if kind in _STEP_PAST:
        return Horizon(inner.past_s, inner.past_steps + 1, inner.future_s, inner.future_steps)
    return inner


def _end(node: BoundedNode) -> Fraction:
    """A temporal operator's upper bound in seconds."""
    return Fraction(node.end) * _UNITS.get(str(node.end_unit or ""), Fraction(1))


def _ident(i: int) -> str:
    return f"trace_signal_{i}"


def _renamed(formula: str, names: Sequence[str]) -> str:
    index = {name: i for i, name in enumerate(names)}
    return _steps_grouped(SIGNAL_PATTERN.sub(lambda m: _ident(index[m.group(0)]), formula))


_STEP_CALL = re.compile(r"(?<![\w.])(?:prev|next|sprev|snext|rise|fall)\s*\(")


def _steps_grouped(formula: str) -> str:
    """``formula`` with each single-step operator's application in parentheses.

    rtamt's grammar takes ``prev``/``next`` (and ``rise``/``fall``) as prefix operators of
    the lowest precedence, not as functions: ``next(x) - x <= 0`` is parsed as
    ``next((x) - x <= 0)``, so ``next(x) - x`` is always 0. Written as a call, the operator
    applies to its parenthesised argument only: ``(next(x)) - x <= 0``."""
    opens: dict[int, int] = {}  # insert "(" before -> how many
    closes: dict[int, int] = {}  # insert ")" after -> how many
    for m in _STEP_CALL.finditer(formula):
        depth = 0
        for i in range(m.end() - 1, len(formula)):
            depth += {"(": 1, ")": -1}.get(formula[i], 0)
            if depth == 0:
                opens[m.start()] = opens.get(m.start(), 0) + 1
                closes[i] = closes.get(i, 0) + 1
                break
    out: list[str] = []
    for i, ch in enumerate(formula):
        out.append("(" * opens.get(i, 0) + ch + ")" * closes.get(i, 0))
    return "".join(out)


def rtamt_module() -> ModuleType:
    """The ``rtamt`` module (imported on first use; ``RulesError`` when it is missing)."""
    return _rtamt()


def _rtamt() -> ModuleType:
    try:
        with warnings.catch_warnings():
            # rtamt's pinned parser runtime (antlr4 4.7) imports ``typing.io``, deprecated
            # since Python 3.8: a warning about rtamt's dependency, not about the rules.
            warnings.simplefilter("ignore", DeprecationWarning)
            return importlib.import_module("rtamt")
    except ImportError as err:
        raise RulesError(
            f"checking rules needs rtamt: pip install 'trace-audit[rules]' ({err})"
        ) from err


def _rtamt_errors() -> tuple[type[Exception], ...]:
    """What rtamt raises for a formula it cannot parse or evaluate (its own exception, and
    a ``KeyError`` for an undeclared name in some versions)."""
    return (_rtamt().RTAMTException, KeyError, ValueError, ZeroDivisionError)


def _specification(names: Sequence[str]) -> _Specification:
    spec: _Specification = _rtamt().StlDiscreteTimeSpecification()
    for i in range(len(names)):
        spec.declare_var(_ident(i), "float")
    return spec


def _parse(spec: _Specification, rule: str, names: Sequence[str]) -> None:
    # rtamt logs a warning (on the root logger) for each undeclared name before it declares
    # it itself; the unknown name is reported here instead, as one line.
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        spec.parse()
    except _rtamt_errors() as err:
        raise RulesError(f"rule {rule!r}: {_message(err, names)}") from err
    except Exception as err:
        raise RulesError(
            f"rule {rule!r}: rtamt could not parse it ({type(err).__name__}: "
            f"{_message(err, names)})"
        ) from err
    finally:
        logging.disable(previous)


def _message(err: Exception, names: Sequence[str]) -> str:
    """rtamt's message in the rule's own words (its signal names, on one line)."""
    text = str(err).replace("RTAMT Exception:", "").strip()
    text = re.sub(r"trace_signal_(\d+)", lambda m: names[int(m.group(1))], text)
    if isinstance(err, KeyError):
        return f"unknown signal {text} ({_SIGNALS_HELP})"
    return " ".join(text.split()) or type(err).__name__
