"""Causal chains of one decision: from each factor the action names down to a sensor reading.

This is the one chain walker of the investigator. It reads plain JSON dicts (what
``Cycle.layer(topic)`` returns, for full and warm-summary cycles alike) with dicts and sets
only, so metrics over a long log stay fast.

The documented chain of a factor, top to bottom (one *level* per line):

1. ``factor_node``    the factor's ``node`` is a node of this cycle's belief graph;
2. ``belief_path``    belief edges (parent -> child), walked from the factor node up through
                      parents, reach a node with ``kind == "entity"``;
3. ``entity``         that entity node's ``entity`` names an entity of this cycle's perception;
4. ``evidence_ref``   that entity has evidence whose ``ref`` is recorded (not null);
5. ``sensor_reading`` the ref resolves to a logged ``/sensors`` message: same topic and
                      ``log_time_ns``, and, when the ref carries them, the same sequence and
                      the SHA-256 of the message data.

Expected depth is 5 for a factor on a derived-state node, and 4 for a factor whose node is
itself an entity node (it has no belief path to document). A factor whose node is not in
the belief graph is taken as a state factor (expected 5): nothing logged says otherwise.
The documented depth is the number of consecutive documented levels from the top; a level
below the first missing one is reported as missing ("not reached"), never skipped, because
without it nothing says which entity or evidence the chain would have continued to.

Where a factor has several routes (a node with several parents, an entity with several
evidence items), the chain reported is the deepest one; the first fully documented route
in breadth-first order (nearest entity first) wins ties.

Evidence refs resolve against the sensor messages of the decision's own cycle and of the
``SensorWindow.cycles`` cycles before it (default 50, i.e. 5 s at 10 Hz); a ref to a
reading older than that or to a later cycle does not resolve. A ref into an external
recording (PROFILE.md section 11, e.g. a rosbag2 MCAP) resolves when the window was given
that recording (the log's declared recordings, ``evidence.recordings_for``) and the
message there matches the ref; when the recording cannot be read it stays
undocumented, with a reason that says it was not checked rather than broken, and marked
``Link.unknown``: such a chain's traceability is unknown (``FactorChain.unknown``), so the
decision's ET is unknown (``DecisionChains.known_et`` None, ``DecisionScore.unknown``), not 0.

``label_chain`` names a chain's nodes and links in the labels of its decision's causal graph
(``trace_audit.causal``), the words ``trace-audit explain`` draws it with.

What a chain is lives in ``chains.model``, the walk in ``chains.walk``, the labels in
``chains.labels``; every name is imported from here.
"""

from __future__ import annotations

from trace_audit.chains.labels import LabelledChain, LabelledLink, label_chain
from trace_audit.chains.model import (
    EXPECTED_DEPTH_ENTITY,
    EXPECTED_DEPTH_STATE,
    LEVELS,
    DecisionChains,
    DecisionScore,
    FactorChain,
    Link,
)
from trace_audit.chains.walk import score_layers, trace_cycle, trace_layers
from trace_audit.sensor_window import DEFAULT_SENSOR_WINDOW, SensorWindow

__all__ = [
    "DEFAULT_SENSOR_WINDOW",
    "EXPECTED_DEPTH_ENTITY",
    "EXPECTED_DEPTH_STATE",
    "LEVELS",
    "DecisionChains",
    "DecisionScore",
    "FactorChain",
    "LabelledChain",
    "LabelledLink",
    "Link",
    "SensorWindow",
    "label_chain",
    "score_layers",
    "trace_cycle",
    "trace_layers",
]
