"""trace_runtime: the embeddable TRACE audit logger and the one reader of its format.

Names are imported on first use (PEP 562), so ``import trace_runtime.errors`` (what the
investigator's CLI needs to start) does not build the pydantic record models, and a robot
pays only for what it touches.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_runtime.lazy import lazy_exports

_EXPORTS = {
    "Cycle": "trace_runtime.encoding.cycles",
    "RawMessage": "trace_runtime.encoding.cycles",
    "LogLimitError": "trace_runtime.errors",
    "LogLockedError": "trace_runtime.errors",
    "LogReadError": "trace_runtime.errors",
    "NotTraceLogError": "trace_runtime.errors",
    "RecordError": "trace_runtime.errors",
    "TimeOutOfRangeError": "trace_runtime.errors",
    "TraceError": "trace_runtime.errors",
    "UsageError": "trace_runtime.errors",
    "SealStatus": "trace_runtime.encoding.seal_check",
    "verify_cycle": "trace_runtime.encoding.seal_check",
    "Ed25519Signer": "trace_runtime.tlog.keys",
    "PublicKey": "trace_runtime.tlog.keys",
    "Signer": "trace_runtime.tlog.keys",
    "generate_keypair": "trace_runtime.tlog.keys",
    "load_public_key": "trace_runtime.tlog.keys",
    "load_signer": "trace_runtime.tlog.keys",
    "open_signer": "trace_runtime.tlog.signers",
    "AuditLogger": "trace_runtime.logger.api",
    "CycleBuilder": "trace_runtime.logger.cycle_builder",
    "LoggerConfig": "trace_runtime.logger.config",
    "LoggerStats": "trace_runtime.logger.config",
    "Log": "trace_runtime.reading.logset",
    "open_log": "trace_runtime.reading.logset",
    "Segment": "trace_runtime.reading.reader",
    "SegmentInfo": "trace_runtime.reading.reader",
    "open_segment": "trace_runtime.reading.reader",
    "Recordings": "trace_runtime.reading.recordings",
    "external_ref": "trace_runtime.reading.recordings",
    "Action": "trace_runtime.records",
    "Alternative": "trace_runtime.records",
    "Belief": "trace_runtime.records",
    "BeliefEdge": "trace_runtime.records",
    "ActuatorChannel": "trace_runtime.records",
    "BeliefNode": "trace_runtime.records",
    "Checkpoint": "trace_runtime.records",
    "ComplianceCheck": "trace_runtime.records",
    "Counterfactual": "trace_runtime.records",
    "DecisionTree": "trace_runtime.records",
    "Entity": "trace_runtime.records",
    "Evidence": "trace_runtime.records",
    "EvidenceRef": "trace_runtime.records",
    "Execution": "trace_runtime.records",
    "Factor": "trace_runtime.records",
    "Motion": "trace_runtime.records",
    "Perception": "trace_runtime.records",
    "Pose": "trace_runtime.records",
    "Rationale": "trace_runtime.records",
    "Region": "trace_runtime.records",
    "Seal": "trace_runtime.records",
    "TreeEdge": "trace_runtime.records",
    "TreeNode": "trace_runtime.records",
    "SessionInfo": "trace_runtime.session",
}

__all__ = [
    "Action",
    "ActuatorChannel",
    "Alternative",
    "AuditLogger",
    "Belief",
    "BeliefEdge",
    "BeliefNode",
    "Checkpoint",
    "ComplianceCheck",
    "Counterfactual",
    "Cycle",
    "CycleBuilder",
    "DecisionTree",
    "Ed25519Signer",
    "Entity",
    "Evidence",
    "EvidenceRef",
    "Execution",
    "Factor",
    "Log",
    "LogLimitError",
    "LogLockedError",
    "LogReadError",
    "LoggerConfig",
    "LoggerStats",
    "Motion",
    "NotTraceLogError",
    "Perception",
    "Pose",
    "PublicKey",
    "Rationale",
    "RawMessage",
    "RecordError",
    "Recordings",
    "Region",
    "Seal",
    "SealStatus",
    "Segment",
    "SegmentInfo",
    "SessionInfo",
    "Signer",
    "TimeOutOfRangeError",
    "TraceError",
    "TreeEdge",
    "TreeNode",
    "UsageError",
    "external_ref",
    "generate_keypair",
    "load_public_key",
    "load_signer",
    "open_log",
    "open_segment",
    "open_signer",
    "verify_cycle",
]

if TYPE_CHECKING:
    from trace_runtime.encoding.cycles import Cycle, RawMessage
    from trace_runtime.encoding.seal_check import SealStatus, verify_cycle
    from trace_runtime.errors import (
        LogLimitError,
        LogLockedError,
        LogReadError,
        NotTraceLogError,
        RecordError,
        TimeOutOfRangeError,
        TraceError,
        UsageError,
    )
    from trace_runtime.logger.api import AuditLogger
    from trace_runtime.logger.config import LoggerConfig, LoggerStats
    from trace_runtime.logger.cycle_builder import CycleBuilder
    from trace_runtime.reading.logset import Log, open_log
    from trace_runtime.reading.reader import Segment, SegmentInfo, open_segment
    from trace_runtime.reading.recordings import Recordings, external_ref
    from trace_runtime.records import (
        Action,
        ActuatorChannel,
        Alternative,
        Belief,
        BeliefEdge,
        BeliefNode,
        Checkpoint,
        ComplianceCheck,
        Counterfactual,
        DecisionTree,
        Entity,
        Evidence,
        EvidenceRef,
        Execution,
        Factor,
        Motion,
        Perception,
        Pose,
        Rationale,
        Region,
        Seal,
        TreeEdge,
        TreeNode,
    )
    from trace_runtime.session import SessionInfo
    from trace_runtime.tlog.keys import (
        Ed25519Signer,
        PublicKey,
        Signer,
        generate_keypair,
        load_public_key,
        load_signer,
    )
    from trace_runtime.tlog.signers import open_signer


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, __all__)
