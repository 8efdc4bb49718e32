"""Omitted optional fields take their schema defaults in every reader and renderer: a log
written by another language's robot, with the plain ``mcap`` library, that leaves every
optional field out reads as the same record with the defaults of ``trace_runtime.records``."""

from __future__ import annotations

from pathlib import Path

from tests.trace_audit.metrics.test_scan import HandLog, layers, t
from trace_audit.cli.explain import explain_doc
from trace_audit.cli.render import render_plain
from trace_audit.cli.timeline import timeline_doc
from trace_audit.cli.why import why_doc
from trace_audit.explanation import explain
from trace_audit.export import export_decision
from trace_audit.transitions import timeline, why


def _minimal_log(tmp_path: Path) -> Path:
    """What another language's robot writes: every optional field left out."""
    log = HandLog(tmp_path / "minimal.mcap")
    for i in range(3):
        full = layers(log.sensor(t(i), {"i": i}))
        log.cycle(
            i,
            t(i),
            {
                "perception": {
                    "entities": [
                        {
                            "id": "ped_1",
                            "class": "person",
                            "pose": {"position": [1.5, 0.0, 0.0]},
                            "confidence": {"person": 0.9},
                            "evidence": full["perception"]["entities"][0]["evidence"],
                        }
                    ]
                },
                "belief": {
                    "nodes": [
                        {"id": "ped_1", "kind": "entity", "p": 0.9, "entity": "ped_1"},
                        {"id": "dist", "kind": "state", "p": 0.95, "value": 1.5},
                    ],
                    "edges": [{"parent": "ped_1", "child": "dist", "p": 0.95, "rule": "range"}],
                },
                "action": {
                    "command": "STOP",
                    "rationale": {
                        "text": "pedestrian",
                        "factors": [{"node": "dist", "value": 1.5}],
                    },
                },
                "execution": {
                    "intended": {"linear": 0.5},
                    "actual": {"linear": 0.4},
                    "deviation": 0.1,
                },
            },
        )
    log.close()
    return log.path


def test_omitted_fields_show_their_schema_defaults(tmp_path: Path) -> None:
    path = _minimal_log(tmp_path)
    result = explain(path, cycle=1)
    execution = result.decision.execution
    assert execution is not None
    assert execution.intended == (0.5, 0.0) and execution.actual == (0.4, 0.0)
    assert execution.checks == () and execution.flags == ()
    d = result.decision
    assert d.parameters == {} and d.alternatives == () and d.counterfactuals == ()
    assert d.truncated is False and d.counterfactuals_none_applicable is False
    text = render_plain(explain_doc(result), 120)
    assert "0.5 m/s, 0.0 rad/s" in text and "? rad/s" not in text
    assert "?" not in text.split("Execution", 1)[1].split("Auditability", 1)[0]
    # the same record through the other renderers
    for text in (
        render_plain(timeline_doc(timeline(path)), 120),
        render_plain(why_doc(why(path, "STOP")), 120),
    ):
        assert "dist = 1.5" in text and "= ?" not in text
    exported = export_decision(path, cycle=1, fmt="json").text
    assert '"?' not in exported
