"""Explain one decision: what the robot did at t, why, what else it weighed, and can we trust it.

``explain(log, t=...)`` finds the decision in force at ``t`` (the last cycle at or before it,
through the segment's chunk index: one chunk is decoded, however long the log) and gathers:
the action and its rationale, factors, alternatives and why each lost, counterfactuals, the
counterfactual decision tree with the taken path, every factor's causal chain down to the
sensor reading (each link documented or not), the causal graph, the execution record, this
decision's ET / ET_partial (and DR / TCS from the metrics library), whether its seal
verifies, and since when the action has held.

Looking back is bounded: one reverse walk from the decision, at most ``lookback_s`` of log
time, finds the previous seal (for the hash chain), the sensor readings of the cycles before
(evidence refs may point at them), and the cycle where the current action began. When the
walk reaches the bound first, the action has held "at least since" the oldest cycle seen.
"""

from __future__ import annotations

from trace_audit.explanation.gather import DEFAULT_LOOKBACK_S, explain, find_cycle
from trace_audit.explanation.result import DecisionScores, Explanation, HeldSince, SealCheck

__all__ = [
    "DEFAULT_LOOKBACK_S",
    "DecisionScores",
    "Explanation",
    "HeldSince",
    "SealCheck",
    "explain",
    "find_cycle",
]
