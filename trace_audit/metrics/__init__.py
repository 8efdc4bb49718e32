"""Auditability metrics from logged artifacts only: ET, ET_partial, TC, DR and TCS.

Definitions (docs/metrics.md is the long form; every number here comes from the log):

- A *decision* is a cycle the reader yields: sealed, or an unsealed tail of a crashed writer.
  Its factors F_d are ``rationale.factors`` of its ``/trace/action`` record.
- **ET(d)**: share of F_d whose chain (``trace_audit.chains``) is documented down to a
  sensor reading its evidence ref resolves to. No action or no factors: ET(d) = 0.
- **ET_partial(d)**: mean over F_d of documented depth / expected depth (5 for a factor on a
  derived-state node, 4 for one on an entity node).
- **TC** = 1 - sum(gaps) / window over the sealed cycles of each robot, in time order. The
  interval between two consecutive sealed cycles is a gap when it exceeds the nominal period
  (``trace.session`` ``period_ns``) by more than ``gap_tolerance`` periods; the gap is the
  time beyond one period (the rule is ``trace_runtime.gaps``). The window is last - first
  sealed time + one period; a clock restart between segments (``trace_runtime.clock``)
  opens a new window, as the first sealed cycle does. A gap is counted in the group of the
  sealed cycle that ends it.
  Seals' ``dropped`` counts are summed separately as declared drops.
- **DR(d)** = 1 when the action is logged (a command), its alternatives are logged (at
  least one), and its rationale is complete: not truncated, factors present, and
  counterfactuals present or ``counterfactuals_none_applicable``. A sealed cycle without an
  action is not reconstructable.
- **Integrity(d)** = 1 when the one seal check (``trace_runtime.encoding.seal_check.verify_cycle``)
  passes: sealed, every layer payload it holds has the digest its seal names, every layer
  the seal names is present, evidenced readings match their refs, and the seal's ``prev``
  is the digest of the robot's previous seal (the segment's ``prev_seal`` for the first).
- **TCS(d)** = weighted mean of ET, ET_partial, DR, continuity and integrity (``TCSWeights``),
  forced to 0 when integrity fails and ``integrity_gate`` is on. Continuity(d) is 1, or
  period / interval when the interval that ends at d holds a gap.

- **Failed checks**: per robot and rule, the checks of its ``/trace/execution`` records
  whose ``passed`` is false: how many, and the first and last to fail (time and cycle, in
  the robot's chain order).

On a log of several robots and no ``by``, the groups are the robots. Stds are population
stds (ddof = 0); each ``Stat`` says what it is taken across. Nothing here reads an
injected-fault flag or a simulator's ground truth.

The modules, in import order: ``config`` (how to score), ``results`` (the report's types),
``decision`` (what one decision scores), ``sums`` (what a scan adds up), ``scan`` (a
robot's segments in order), ``report`` (sums into a report), ``fanout`` (the entry point).
"""

from __future__ import annotations

from trace_audit.metrics.config import (
    GROUP_BYS,
    METRIC_NAMES,
    GroupBy,
    MetricsConfig,
    TCSWeights,
    parse_thresholds,
)
from trace_audit.metrics.decision import (
    NO_SCENARIO,
    dr_problems,
    integrity_problems,
    scenario_of,
    trust_score,
)
from trace_audit.metrics.fanout import ProgressCallback, compute_metrics
from trace_audit.metrics.report import report_from_sums
from trace_audit.metrics.results import (
    AcrossGroups,
    ChannelDeviation,
    DecisionFailure,
    FailedChecks,
    GroupMetrics,
    LoggingCost,
    MetricsReport,
    RuleFailures,
    Stat,
    ThresholdCheck,
)
from trace_audit.metrics.scan import score_segment
from trace_audit.metrics.sums import (
    DecisionSink,
    GroupSums,
    ScanResult,
    ScoredDecision,
    SealOutcome,
)
from trace_runtime.gaps import Gap

__all__ = [
    "GROUP_BYS",
    "METRIC_NAMES",
    "NO_SCENARIO",
    "AcrossGroups",
    "ChannelDeviation",
    "DecisionFailure",
    "DecisionSink",
    "FailedChecks",
    "Gap",
    "GroupBy",
    "GroupMetrics",
    "GroupSums",
    "LoggingCost",
    "MetricsConfig",
    "MetricsReport",
    "ProgressCallback",
    "RuleFailures",
    "ScanResult",
    "ScoredDecision",
    "SealOutcome",
    "Stat",
    "TCSWeights",
    "ThresholdCheck",
    "compute_metrics",
    "dr_problems",
    "integrity_problems",
    "parse_thresholds",
    "report_from_sums",
    "scenario_of",
    "score_segment",
    "trust_score",
]
