"""TRACE against post-hoc explanation baselines (LIME, SHAP, attention), measured.

``run_baselines(BaselinesConfig())`` trains a learned policy and an attention model on
simulator runs, explains their decisions on the paper's scenario runs, scores every
method's output with the same metrics TRACE is scored with, and measures TRACE's own cost
per cycle (logging on and off) and how it grows with entities and candidate actions.

This package is an evaluation harness, not part of the robot: it reads the logs with the
investigator's chain walker and metrics (``trace_audit``), which the simulator proper
never imports. Its ML libraries are the ``[baselines]`` extra.
"""

from __future__ import annotations

from evaluation.baselines.evaluate import (
    BaselinesConfig,
    BaselinesReport,
    MethodResult,
    SeedResult,
    run_baselines,
)
from evaluation.baselines.scoring import (
    Citation,
    ExplanationRecord,
    ExplanationScore,
    as_action,
    score_explanation,
)

__all__ = [
    "BaselinesConfig",
    "BaselinesReport",
    "Citation",
    "ExplanationRecord",
    "ExplanationScore",
    "MethodResult",
    "SeedResult",
    "as_action",
    "run_baselines",
    "score_explanation",
]
