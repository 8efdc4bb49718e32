"""One rtamt specification judges every stretch of a robot (``Formula.monitor``): its answer
on each stretch must be that of a specification parsed for that stretch alone, whatever
stretches it judged before (rtamt's offline evaluation keeps no state between calls)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from trace_audit.rules import compile_formula

PERIOD_NS = 100_000_000
FORMULA = compile_formula(
    "r",
    "always((historically[0:0.5](nearest.person < 3.0) and prev(command.STOP > 0.5)) "
    "implies eventually[0:0.3](channel.speed.actual <= 0.55))",
)
values = st.floats(min_value=0.0, max_value=6.0, allow_nan=False)
stretch = st.integers(min_value=1, max_value=30).flatmap(
    lambda n: st.fixed_dictionaries(
        {
            "nearest.person": st.lists(values, min_size=n, max_size=n),
            "command.STOP": st.lists(st.sampled_from([0.0, 1.0]), min_size=n, max_size=n),
            "channel.speed.actual": st.lists(values, min_size=n, max_size=n),
        }
    )
)


@settings(max_examples=25, deadline=None)
@given(st.lists(stretch, min_size=1, max_size=6))
def test_a_reused_monitor_answers_each_stretch_as_a_fresh_one(stretches: list) -> None:
    for engine in ("rtamt", "auto"):
        monitor = FORMULA.monitor(PERIOD_NS, engine=engine)
        for columns in stretches:
            assert monitor(columns).tolist() == FORMULA.evaluate(columns, PERIOD_NS, engine=engine)
