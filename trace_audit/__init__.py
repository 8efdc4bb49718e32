"""trace_audit: the investigator's library behind the ``trace-audit`` command.

Open a log (a segment, a directory or a log root, in any tier), then ask it questions::

    from trace_audit import open_log, explain, why, compute_metrics, verify_log

    result = explain("run.mcap", t="20.5")        # in force at t = 20.5 s (int: nanoseconds)
    stops = why("run.mcap", "STOP")               # every transition into STOP, with its reason
    report = compute_metrics(["run.mcap"])        # ET, ET_partial, TC, DR, TCS
    integrity = verify_log("logs/")               # chain, checkpoints, signatures
    conformance = doctor_log("run.mcap")          # every rule of schemas/PROFILE.md
    frame = decision_table("logs/", robots=["amr-7"], start="+5").to_pandas()

``iter_decisions`` yields the typed ``Decision`` of every cycle the CLI renders; the
``*_table`` functions give whole layers as Arrow tables (the ``fleet`` extra). docs/api.md
is the long form.

Names are imported on first use, so ``import trace_audit`` (and the CLI's start-up) stays fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_runtime.lazy import lazy_exports

_EXPORTS = {
    "open_log": "trace_runtime.reading.logset",
    "Selection": "trace_audit.selection",
    "SeveralRobotsError": "trace_audit.selection",
    "per_robot": "trace_audit.selection",
    "LogClock": "trace_audit.log_time",
    "iter_decisions": "trace_audit.layers",
    "iter_decision_fields": "trace_audit.layers",
    "RobotDecision": "trace_audit.layers",
    "RobotDecisionFields": "trace_audit.layers",
    "decision_table": "trace_audit.layers",
    "entity_table": "trace_audit.layers",
    "channel_table": "trace_audit.layers",
    "check_table": "trace_audit.layers",
    "gap_table": "trace_audit.layers",
    "explain": "trace_audit.explanation",
    "Explanation": "trace_audit.explanation",
    "why": "trace_audit.transitions",
    "timeline": "trace_audit.transitions",
    "WhyResult": "trace_audit.transitions",
    "Timeline": "trace_audit.transitions",
    "log_info": "trace_audit.info",
    "LogInfo": "trace_audit.info",
    "export_decision": "trace_audit.export",
    "read_decision": "trace_audit.causal",
    "causal_graph": "trace_audit.causal",
    "tree_graph": "trace_audit.causal",
    "trace_cycle": "trace_audit.chains",
    "DecisionChains": "trace_audit.chains",
    "compute_metrics": "trace_audit.metrics",
    "MetricsConfig": "trace_audit.metrics",
    "MetricsReport": "trace_audit.metrics",
    "verify_log": "trace_audit.verify",
    "VerifyReport": "trace_audit.verify",
    "doctor_log": "trace_audit.doctor",
    "DoctorReport": "trace_audit.doctor",
    "describe_refs": "trace_audit.evidence",
    "ExternalEvidence": "trace_audit.evidence",
}

__all__ = [
    "DecisionChains",
    "DoctorReport",
    "Explanation",
    "ExternalEvidence",
    "LogClock",
    "LogInfo",
    "MetricsConfig",
    "MetricsReport",
    "RobotDecision",
    "RobotDecisionFields",
    "Selection",
    "SeveralRobotsError",
    "Timeline",
    "VerifyReport",
    "WhyResult",
    "causal_graph",
    "channel_table",
    "check_table",
    "compute_metrics",
    "decision_table",
    "describe_refs",
    "doctor_log",
    "entity_table",
    "explain",
    "export_decision",
    "gap_table",
    "iter_decision_fields",
    "iter_decisions",
    "log_info",
    "open_log",
    "per_robot",
    "read_decision",
    "timeline",
    "trace_cycle",
    "tree_graph",
    "verify_log",
    "why",
]

if TYPE_CHECKING:
    from trace_audit.causal import causal_graph, read_decision, tree_graph
    from trace_audit.chains import DecisionChains, trace_cycle
    from trace_audit.doctor import DoctorReport, doctor_log
    from trace_audit.evidence import ExternalEvidence, describe_refs
    from trace_audit.explanation import Explanation, explain
    from trace_audit.export import export_decision
    from trace_audit.info import LogInfo, log_info
    from trace_audit.layers import (
        RobotDecision,
        RobotDecisionFields,
        channel_table,
        check_table,
        decision_table,
        entity_table,
        gap_table,
        iter_decision_fields,
        iter_decisions,
    )
    from trace_audit.log_time import LogClock
    from trace_audit.metrics import MetricsConfig, MetricsReport, compute_metrics
    from trace_audit.selection import Selection, SeveralRobotsError, per_robot
    from trace_audit.transitions import Timeline, WhyResult, timeline, why
    from trace_audit.verify import VerifyReport, verify_log
    from trace_runtime.reading.logset import open_log


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, __all__)
