"""``rules.vector`` computes rtamt's robustness over whole columns; rtamt's own interpreter
is the oracle. Random formulas of every operator the vector engine covers, over random
stretches, must give rtamt's value, to the bit, at every step whose horizon lies inside the
stretch (the only steps ``rules.judge`` reads); a formula it does not cover is left to
rtamt (``compile_columns`` is None)."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from trace_audit.rules import compile_formula
from trace_audit.rules.vector import compile_columns

PERIOD_NS = 100_000_000
SIGNALS = ("nearest.person", "channel.speed.actual", "command.STOP")
BOUNDS = st.tuples(st.integers(0, 4), st.integers(0, 4)).map(
    lambda ab: (min(ab) / 10, max(ab) / 10)
)


def _atom(draw: st.DrawFn) -> str:
    signal = draw(st.sampled_from(SIGNALS))
    op = draw(st.sampled_from(["<", "<=", ">", ">=", "==", "!=="]))
    value = draw(st.sampled_from(["0.5", "1.0", "2", "-1.5"]))
    term = draw(
        st.sampled_from(
            [signal, f"abs({signal} - 1)", f"{signal} + {signal}", f"2 * {signal}", f"0 - {signal}"]
        )
    )
    return f"({term} {op} {value})"


@st.composite
def formulas(draw: st.DrawFn, depth: int = 3) -> str:
    if depth == 0 or draw(st.integers(0, 3)) == 0:
        return _atom(draw)
    kind = draw(st.integers(0, 5))
    a = draw(formulas(depth - 1))
    if kind == 0:
        return f"not {a}"
    if kind == 1:
        b = draw(formulas(depth - 1))
        op = draw(st.sampled_from(["and", "or", "implies", "iff", "xor"]))
        return f"({a} {op} {b})"
    if kind == 2:
        lo, hi = draw(BOUNDS)
        op = draw(st.sampled_from(["always", "eventually", "historically", "once"]))
        return f"{op}[{lo:g}:{hi:g}]({a})"
    if kind == 3:
        return f"{draw(st.sampled_from(['prev', 'next']))}({a})"
    if kind == 4:
        b = draw(formulas(depth - 1))
        lo, hi = draw(BOUNDS)
        return f"({a} since[{lo:g}:{hi:g}] {b})"
    return a


values = st.one_of(
    st.floats(-3, 3, allow_nan=False).map(lambda v: round(v, 3)),
    st.sampled_from([0.0, 1.0, 0.5, 2.0, math.inf]),
)


@settings(max_examples=300, deadline=None)
@given(
    formulas(),
    st.integers(1, 25).flatmap(
        lambda n: st.lists(st.lists(values, min_size=3, max_size=3), min_size=n, max_size=n)
    ),
)
def test_the_vector_engine_gives_rtamts_values(body: str, rows: list[list[float]]) -> None:
    formula = compile_formula("r", f"always({body})")
    columns = {s: [row[i] for row in rows] for i, s in enumerate(SIGNALS) if s in formula.signals}
    if not columns:
        return
    expected = formula.evaluate(columns, PERIOD_NS, engine="rtamt")
    got = formula.evaluate(columns, PERIOD_NS, engine="auto")
    past, future = formula.horizon.steps(PERIOD_NS)
    for i in range(past, len(rows) - future):
        a, b = expected[i], got[i]
        assert a == b or (math.isnan(a) and math.isnan(b)), (body, i, a, b)


def _compiled(body: str) -> object:
    formula = compile_formula("r", f"always({body})")
    return compile_columns(formula._spec(PERIOD_NS).ast.specs[0], PERIOD_NS)


def test_every_operator_of_the_strategy_is_computed_over_columns() -> None:
    body = (
        "(not (S < 1) and (S <= 1) or (S > 1) implies (S >= 1) iff (S == 1) xor (S !== 1)) "
        "and always[0:0.2](S < 1) and eventually[0.1:0.3](abs(S - 1) < 1) "
        "and historically[0:0.2](2 * S + S - S < 1) and once[0:0.1](S < 1) "
        "and prev(S < 1) and next(S < 1) and ((S < 1) since[0:0.2] (S > 0))"
    )
    assert _compiled(body.replace("S", "nearest.person")) is not None


def test_an_operator_it_does_not_compute_is_left_to_rtamt() -> None:
    for body in (
        "rise(nearest.person < 1)",
        "exp(nearest.person) < 2",
        "nearest.person / 2 < 1",
        "sqrt(nearest.person) < 1",
    ):
        assert _compiled(body) is None, body
