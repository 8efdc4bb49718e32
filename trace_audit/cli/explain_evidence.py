"""What ``explain`` shows of the readings a decision cited: its evidence in recordings
(resolved and decoded, with the region it cited), the messages its actuator channels were
read from, and its sensors (used, unavailable, and how old each cited reading was).

The library decides (``trace_audit.evidence``, ``trace_audit.readings``,
``trace_audit.sensor_health``); this module chooses the words and styles. Times are in the
log's clock, as every other time ``explain`` shows (``fmt_t`` with the log's ``LogClock``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_audit.cli.doc import Doc, Line, Seg, fmt_duration, fmt_t

if TYPE_CHECKING:
    from trace_audit.evidence import ExternalEvidence
    from trace_audit.explanation import Explanation
    from trace_audit.sensor_health import CitedAge

__all__ = ["channel_evidence", "external_evidence", "sensors"]

_STYLE = {"resolved": "green", "broken": "bold red", "unresolved": "yellow"}


def external_evidence(doc: Doc, r: Explanation) -> None:
    """Evidence refs into recordings: resolved (decoded), broken, or not checked."""
    doc.heading("External evidence (recordings the refs name)")
    for e in r.external_evidence:
        who = f"{e.entity} {e.sensor}".strip()
        _reading(doc, r, e, f"{who}: ")


def channel_evidence(doc: Doc, r: Explanation) -> None:
    """The message each actuator channel says its actual value was read from."""
    for e in r.channel_evidence:
        _reading(doc, r, e, f"{e.channel}: actual read from ")


def _reading(doc: Doc, r: Explanation, e: ExternalEvidence, lead: str) -> None:
    where = f"{e.recording} {e.topic}" if e.recording else f"{e.topic} (this log)"
    t = fmt_t(e.log_time_ns, r.log_clock) if e.log_time_ns is not None else "?"
    doc.line([f"{lead}{where} @ {t}  ", Seg(_state(e), _STYLE[e.state])], 2)
    if e.detail:
        doc.line(e.detail, 4)
    if e.schema:
        doc.line(e.schema, 4)
    for line in e.lines:
        doc.line(line, 6 if e.schema else 4)
    if e.region is not None:
        doc.line(Seg(e.region.text, "bold"), 4)


def _state(e: ExternalEvidence) -> str:
    if e.state == "resolved":
        return "resolved, digest verified" if e.recording else "resolved"
    if e.state == "broken":
        return "BROKEN"
    return "not checked"


def sensors(doc: Doc, r: Explanation) -> None:
    """Sensors used and unavailable, and the age of each cited reading at the decision."""
    health = r.sensors
    if health is None or not (health.used or health.unavailable or health.cited):
        return
    doc.heading("Sensors")
    unavailable: Line = (
        Seg(", ".join(health.unavailable), "bold yellow") if health.unavailable else "none"
    )
    rows: list[tuple[str, Line]] = [
        ("Used", ", ".join(health.used) or "none named"),
        ("Unavailable", unavailable),
    ]
    doc.fields(rows)
    if health.cited:
        limit = health.stale_after_ns
        doc.line(
            "Cited readings, age at the decision"
            + (f" (stale beyond {fmt_duration(limit)}: 1.5 periods)" if limit else ""),
            2,
        )
    for cited in health.cited:
        doc.line(_age_line(cited), 4)


def _age_line(c: CitedAge) -> Line:
    who = f"entity {c.entity}, {c.sensor}" if c.entity else f"channel {c.channel}"
    where = f"{c.recording} {c.topic}" if c.recording else c.topic
    if c.age_ns < 0:
        return [f"{where} ({who}): ", Seg(f"{fmt_duration(c.age_ns)} AFTER the decision", "red")]
    age = f"{fmt_duration(c.age_ns)} old"
    return [f"{where} ({who}): ", Seg(f"{age}, STALE", "bold yellow") if c.stale else age]
