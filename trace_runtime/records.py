"""The TRACE records: one pydantic model per layer of a decision cycle, plus the seal.

The layer records (``Perception``, ``Belief``, ``Action``, ``Execution``) are what a robot
builds. The logger stamps each with the cycle number and time, so the message on the wire is
the ``*Message`` variant (``cycle`` and ``t_ns`` first). ``schemas/*.json`` are generated
from the ``*Message`` models; see ``schemas/PROFILE.md`` for the normative format.

Models are frozen: a record handed to the logger is serialised on the writer thread, so a
robot must not be able to change it after ``commit()``. Floats reject NaN and infinity.
Constructing a model with bad fields raises ``RecordError`` (a ``TraceError``).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from trace_runtime.record_model import RecordModel, Stamp
from trace_runtime.recording_records import TOPIC_RECORDING, RecordingSeal

PROFILE = "trace"
PROFILE_VERSION = "1.5"
"""Major.minor (schemas/PROFILE.md §10). Minor revisions only add optional fields: every
version 1 log is read as before, and a version 1 reader reads 1.1 logs (ignoring what it
does not know). 1.2 adds each robot's Merkle tree to its checkpoints; 1.3 seals every
sensor reading (the seal's ``sensors``); 1.4 declares the recordings a robot cites
(``trace.session`` ``recordings``) and seals every message in them (``/trace/recording``)."""

TOPIC_PERCEPTION = "/trace/perception"
TOPIC_BELIEF = "/trace/belief"
TOPIC_ACTION = "/trace/action"
TOPIC_EXECUTION = "/trace/execution"
TOPIC_SEAL = "/trace/seal"
LAYER_TOPICS = (TOPIC_PERCEPTION, TOPIC_BELIEF, TOPIC_ACTION, TOPIC_EXECUTION)
SENSOR_PREFIX = "/sensors/"

Scalar = float | int | bool | str

Comparison = Literal["<", "<=", ">", ">=", "==", "!="]


# --- shared pieces ---------------------------------------------------------------------


class Pose(RecordModel):
    """A pose in SE(3): position in metres and a unit quaternion (x, y, z, w)."""

    position: tuple[float, float, float] = Field(description="x, y, z in metres, in ``frame``")
    orientation: tuple[float, float, float, float] = Field(
        default=(0.0, 0.0, 0.0, 1.0), description="unit quaternion x, y, z, w"
    )
    frame: str = Field(default="map", description="the coordinate frame, e.g. map, base_link")


class EvidenceRef(RecordModel):
    """Names one sensor message: topic + log time (+ sequence, + content digest).

    Without ``recording`` the message is in the TRACE log itself (a ``/sensors/...``
    channel). With ``recording`` it is in another MCAP file, e.g. a rosbag2 recording made
    beside the log: ``recording`` is that file's name, ``topic`` the topic there (a ROS 2
    topic such as ``/front_camera/image_raw``), and ``digest`` the SHA-256 of the message's
    stored data (its CDR bytes for ROS 2). PROFILE.md section 11.
    """

    topic: str = Field(
        min_length=1,
        description="the MCAP topic of the sensor message, e.g. /sensors/lidar "
        "(the topic in the recording when one is named)",
    )
    log_time_ns: int = Field(ge=0, description="the MCAP log_time of that message, ns")
    sequence: int | None = Field(
        default=None, ge=0, description="the MCAP sequence of that message (per topic)"
    )
    digest: str | None = Field(default=None, description="sha256 hex of the message data")
    recording: str | None = Field(
        default=None,
        description="file name of the external MCAP recording holding the message; "
        "null when it is in this log",
    )


class Region(RecordModel):
    """The part of a sensor reading that supported a detection.

    ``kind`` says how to read ``values``: ``beams`` = [first_beam, last_beam] of a scan,
    ``box`` = [xmin, ymin, xmax, ymax] in ``frame``, ``cone`` = [bearing_rad, half_width_rad,
    range_m], ``pixels`` = [u0, v0, u1, v1].
    """

    kind: Literal["beams", "box", "cone", "pixels"] = Field(
        description="how to read values: beams, box, cone or pixels (see above)"
    )
    values: list[float] = Field(description="the region's numbers, in the order kind gives")
    frame: str = Field(default="base_link", description="the frame a box or cone is in")


class Evidence(RecordModel):
    """One member of an entity's evidence set (Def. 1): sensor, weight, region and ref."""

    sensor: str = Field(
        min_length=1,
        description="the sensor's name as the robot calls it (e.g. lidar, wrist_camera); "
        "not a topic: the topic of the reading is in ref.topic",
    )
    weight: float = Field(
        ge=0.0, le=1.0, description="this sensor's share of the entity's evidence, in [0, 1]"
    )
    region: Region | None = Field(
        default=None, description="the part of the reading that supported the detection"
    )
    ref: EvidenceRef | None = Field(
        default=None, description="null when the link to the sensor reading was not recorded"
    )


# --- layer 1: perception ---------------------------------------------------------------


class Entity(RecordModel):
    """An evidence-grounded entity (Def. 1).

    The class is ``cls`` in Python (``class`` is a keyword) and ``class`` in JSON; a dict
    handed to the logger may use either key.
    """

    id: str = Field(min_length=1, description="the entity's id, stable across cycles")
    cls: str = Field(
        alias="class", min_length=1, description="the most likely class, e.g. person, box"
    )
    pose: Pose = Field(description="where the entity is")
    velocity: tuple[float, float, float] | None = Field(
        default=None, description="vx, vy, vz in m/s in the pose's frame, when tracked"
    )
    confidence: dict[str, float] = Field(
        description="calibrated confidence per class, each in [0, 1]"
    )
    evidence: list[Evidence] = Field(
        default_factory=list, description="the sensor readings the entity was derived from"
    )


class Perception(RecordModel):
    """Layer 1: the entity set E_t and its evidence aggregation record."""

    entities: list[Entity] = Field(default_factory=list, description="the entity set E_t")
    sensors_used: list[str] = Field(
        default_factory=list, description="names of the sensors that contributed this cycle"
    )
    sensors_unavailable: list[str] = Field(
        default_factory=list, description="names of the sensors that were expected but missing"
    )
    robot_pose: Pose | None = Field(
        default=None,
        description="the robot's own pose at this cycle, in the frame of the entities' poses",
    )


# --- layer 2: belief -------------------------------------------------------------------


class BeliefNode(RecordModel):
    """A node of the belief graph: an entity, or a derived state such as ``collision_risk``."""

    id: str = Field(min_length=1, description="the node's id, unique in this cycle's graph")
    kind: Literal["entity", "state"] = Field(
        description="entity (stands for a perceived entity) or state (derived)"
    )
    label: str = Field(default="", description="a human-readable name")
    p: float = Field(ge=0.0, le=1.0, description="P(node holds) / confidence")
    value: Scalar | None = Field(default=None, description="the state's value, if it has one")
    unit: str | None = Field(default=None, description="the unit of value, e.g. m, m/s, N")
    entity: str | None = Field(default=None, description="entity id, for kind == entity")


class BeliefEdge(RecordModel):
    """A documented inference: ``child`` was derived from ``parent`` by ``rule``."""

    parent: str = Field(min_length=1, description="id of the node inferred from")
    child: str = Field(min_length=1, description="id of the node inferred")
    p: float = Field(ge=0.0, le=1.0, description="P(child | parent)")
    rule: str = Field(min_length=1, description="the name of the rule or model that inferred it")


class Belief(RecordModel):
    """Layer 2: the probabilistic scene / causal graph B_t = (V, E, P) (Def. 2)."""

    nodes: list[BeliefNode] = Field(default_factory=list, description="the graph's nodes V")
    edges: list[BeliefEdge] = Field(default_factory=list, description="the graph's edges E")


# --- layer 3: action -------------------------------------------------------------------


class Factor(RecordModel):
    """A belief node the decision depended on, with the value the policy saw."""

    node: str = Field(min_length=1, description="id of a node in this cycle's belief graph")
    name: str = Field(default="", description="a human-readable name of the factor")
    value: Scalar = Field(description="the value the policy saw")
    unit: str | None = Field(default=None, description="the unit of value")


class Rationale(RecordModel):
    """Why the command was chosen: text plus the structured factors (R in Def. 3)."""

    text: str = Field(description="the reason in words")
    factors: list[Factor] = Field(
        default_factory=list, description="the factors the choice depended on, leading first"
    )
    truncated: bool = Field(
        default=False, description="set by the writer of the rationale when it ran out of room"
    )


class Alternative(RecordModel):
    """A command that was considered and lost, with its score and the reason."""

    command: str = Field(min_length=1, description="the command considered")
    score: float = Field(description="its score under the policy (higher wins)")
    rejected_because: str = Field(description="why it lost")


class Counterfactual(RecordModel):
    """``would_select`` would have been chosen had ``factor`` satisfied the comparison."""

    factor: str = Field(min_length=1, description="belief node id of the factor")
    comparison: Comparison = Field(description="how the factor's value is compared")
    threshold: Scalar = Field(description="the value it is compared with")
    would_select: str = Field(min_length=1, description="the command that would then be chosen")


class TreeNode(RecordModel):
    """A node of the counterfactual decision tree: a test, or a leaf naming a command."""

    id: str = Field(min_length=1, description="the node's id, unique in the tree")
    label: str = Field(description="what the node says, for people")
    test: str | None = Field(default=None, description="the test an inner node makes")
    command: str | None = Field(default=None, description="the command a leaf selects")


class TreeEdge(RecordModel):
    """An edge of the counterfactual decision tree: one outcome of the parent's test."""

    parent: str = Field(description="id of the tree node tested")
    child: str = Field(description="id of the tree node that outcome leads to")
    label: str = Field(default="", description="the outcome, e.g. yes / no")


class DecisionTree(RecordModel):
    """The counterfactual decision tree (paper Fig. 2) with the path the policy took."""

    nodes: list[TreeNode] = Field(description="tests and leaves")
    edges: list[TreeEdge] = Field(description="outcomes")
    taken_path: list[str] = Field(description="node ids from root to the chosen leaf")


class Action(RecordModel):
    """Layer 3: the justified action a*_t = <cmd, A_alt, R, CF> (Def. 3)."""

    command: str = Field(min_length=1, description="the command chosen, e.g. SLOW, GRASP")
    parameters: dict[str, float] = Field(
        default_factory=dict, description="the command's numeric parameters, by name"
    )
    score: float | None = Field(default=None, description="the chosen command's score")
    alternatives: list[Alternative] = Field(
        default_factory=list, description="the commands considered that lost"
    )
    rationale: Rationale = Field(description="why this command was chosen")
    counterfactuals: list[Counterfactual] = Field(
        default_factory=list, description="what would have changed the choice"
    )
    counterfactuals_none_applicable: bool = Field(
        default=False, description="true when no factor value could change the choice"
    )
    tree: DecisionTree | None = Field(
        default=None, description="the counterfactual decision tree with the taken path"
    )


# --- layer 4: execution ----------------------------------------------------------------


class Motion(RecordModel):
    """A planar motion command or measurement: linear m/s, angular rad/s.

    The shape of a mobile base. Other robots (arms, grippers, drones) name their own
    quantities with ``ActuatorChannel`` in ``Execution.channels``.
    """

    linear: float = Field(description="forward speed, m/s")
    angular: float = Field(default=0.0, description="yaw rate, rad/s (counter-clockwise)")


class ActuatorChannel(RecordModel):
    """One commanded-and-measured quantity of any actuator: a joint velocity, a gripper
    force, an end-effector speed, a thrust. ``intended`` and ``actual`` are in ``unit``;
    ``ref`` may cite the message ``actual`` was read from, as an entity's evidence does."""

    name: str = Field(min_length=1, description="the robot's name for it, e.g. joint_3, grip")
    unit: str = Field(description="unit of intended, actual and deviation, e.g. rad/s, N")
    intended: float | None = Field(default=None, description="the commanded value")
    actual: float | None = Field(default=None, description="the measured value")
    deviation: float | None = Field(
        default=None,
        ge=0.0,
        description="how far actual was from intended, in unit (usually |actual - intended|)",
    )
    ref: EvidenceRef | None = Field(
        default=None,
        description="the sensor message the actual value was read from (e.g. /joint_states "
        "or /odom, in this log or a recording); null when not recorded (profile 1.4)",
    )


class ComplianceCheck(RecordModel):
    """One safety or compliance rule checked against this cycle's execution."""

    rule: str = Field(min_length=1, description="the rule's name, e.g. max_speed_near_person")
    passed: bool = Field(description="whether the execution met the rule")
    value: float | None = Field(default=None, description="the value the rule was checked on")
    limit: float | None = Field(default=None, description="the rule's limit for that value")
    detail: str = Field(default="", description="anything else the check reports")


class Execution(RecordModel):
    """Layer 4: intended vs actual behaviour, deviation delta_t, compliance, flags.

    A mobile base logs ``intended`` and ``actual`` as planar ``Motion``s (profile 1.0).
    Any other actuator set logs ``channels`` (profile 1.1), one ``ActuatorChannel`` per
    quantity, each with its unit and its own deviation; a robot may log both.
    """

    intended: Motion | None = Field(
        default=None, description="the planar motion commanded (mobile bases)"
    )
    actual: Motion | None = Field(
        default=None, description="the planar motion measured (mobile bases)"
    )
    deviation: float = Field(
        ge=0.0, description="overall deviation delta_t of actual from intended (>= 0)"
    )
    checks: list[ComplianceCheck] = Field(
        default_factory=list, description="the compliance checks run on this execution"
    )
    flags: list[str] = Field(
        default_factory=list, description="labels for anything notable, e.g. e_stop"
    )
    channels: list[ActuatorChannel] = Field(
        default_factory=list,
        description="intended vs actual per named actuator quantity, with units (profile 1.1)",
    )
    deviation_unit: str | None = Field(
        default=None,
        description="unit of the overall deviation, e.g. m/s; null: not stated (profile 1.1)",
    )


# --- messages on the wire --------------------------------------------------------------


class PerceptionMessage(Stamp, Perception):
    """``/trace/perception``"""


class BeliefMessage(Stamp, Belief):
    """``/trace/belief``"""


class ActionMessage(Stamp, Action):
    """``/trace/action``"""


class ExecutionMessage(Stamp, Execution):
    """``/trace/execution``"""


class SensorCover(RecordModel):
    """A seal's ``sensors`` (profile 1.3): every sensor reading the cycle logged, cited by
    evidence or not, so that a reading which detected nothing is in the chain too."""

    count: int = Field(ge=0, description="the sensor messages of the cycle (PROFILE §5)")
    digest: str = Field(
        description="sha256 hex over their lines (UTF-8 length of the topic, ':', topic, "
        "sequence, log time, sha256 hex of the data, each ended by a newline) in file "
        "order (PROFILE §6)"
    )


class Seal(Stamp):
    """``/trace/seal``: T_t, closing one cycle and linking it into the hash chain."""

    digests: dict[str, str] = Field(description="layer topic -> sha256 hex of its message data")
    prev: str = Field(description="sha256 hex of the previous seal's data; 64 zeros at genesis")
    dropped: int = Field(default=0, ge=0, description="cycles dropped since the previous seal")
    sensors: SensorCover | None = Field(
        default=None,
        description="the cycle's sensor readings (profile 1.3; absent in earlier seals)",
    )


LayerRecord = Perception | Belief | Action | Execution

MESSAGE_MODELS: dict[str, type[Stamp]] = {
    TOPIC_PERCEPTION: PerceptionMessage,
    TOPIC_BELIEF: BeliefMessage,
    TOPIC_ACTION: ActionMessage,
    TOPIC_EXECUTION: ExecutionMessage,
    TOPIC_SEAL: Seal,
}

LAYER_MODELS: dict[str, type[RecordModel]] = {
    TOPIC_PERCEPTION: Perception,
    TOPIC_BELIEF: Belief,
    TOPIC_ACTION: Action,
    TOPIC_EXECUTION: Execution,
}

GENESIS = "0" * 64


# --- integrity: signed checkpoints -------------------------------------------------------

TOPIC_CHECKPOINT = "/trace/checkpoint"


class Checkpoint(Stamp):
    """``/trace/checkpoint``: a (signed) statement of the chain head, CT's signed tree head.

    ``cycle``/``t_ns`` are those of the head seal; ``head`` is the SHA-256 of that seal's data,
    so the checkpoint vouches for every cycle the chain reaches back to. A checkpoint is not
    part of any cycle. The signature is Ed25519 over ``trace_runtime.integrity.signing_bytes``
    (see docs/integrity.md); both it and ``key_id`` are null when the logger has no key.

    Profile 1.2 adds the robot's Merkle tree through the head seal (``tree_size``, ``root``,
    ``range``) and the same statement as a C2SP tlog checkpoint (``origin``, ``note``), so any
    signed-note verifier checks it; all null in 1.0/1.1 checkpoints.

    Profile 1.5 adds key rotation: a checkpoint may announce the key that signs the robot's
    later checkpoints (``next_key``), signed by its own key (``next_key_signature``, over
    ``tlog.rotation.rotation_bytes``).
    """

    robot_id: str = Field(min_length=1, description="the robot whose chain this is")
    segment: int = Field(ge=0, description="number of the segment the checkpoint was written in")
    first_cycle: int = Field(ge=0, description="first cycle of that segment")
    sealed: int = Field(ge=0, description="seals written in the segment, first_cycle..cycle")
    head: str = Field(description="sha256 hex of the head seal's data")
    final: bool = Field(default=False, description="written when the segment was closed")
    key_id: str | None = Field(
        default=None, description="sha256 hex of the raw 32-byte Ed25519 public key"
    )
    signature: str | None = Field(default=None, description="Ed25519 signature, hex")
    tree_size: int | None = Field(
        default=None,
        ge=0,
        description="leaves of the robot's Merkle tree (its seals from genesis) through the "
        "head seal (profile 1.2)",
    )
    root: str | None = Field(
        default=None,
        pattern=r"^[0-9a-f]{64}$",
        description="RFC 6962 root hash of that tree, lowercase hex (profile 1.2)",
    )
    range: list[Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]] | None = Field(
        default=None,
        max_length=64,
        description="the tree's compact range at tree_size: the roots of its complete "
        "subtrees, largest first, hex; what a restarted writer continues from (profile 1.2)",
    )
    origin: str | None = Field(
        default=None,
        min_length=1,
        description="the C2SP checkpoint origin naming the robot's log (profile 1.2)",
    )
    note: str | None = Field(
        default=None,
        description="the C2SP signed note of (origin, tree_size, root), signed with the "
        "checkpoint key under the key name origin; null when unsigned (profile 1.2)",
    )
    next_key: str | None = Field(
        default=None,
        min_length=1,
        description="key rotation: the C2SP verifier key (under origin) of the key that signs "
        "the robot's checkpoints after this one (profile 1.5)",
    )
    next_key_signature: str | None = Field(
        default=None,
        pattern=r"^[0-9a-f]{128}$",
        description="Ed25519 signature, hex, by this checkpoint's key over the key rotation "
        "bytes announcing next_key (profile 1.5)",
    )


MESSAGE_MODELS[TOPIC_CHECKPOINT] = Checkpoint
MESSAGE_MODELS[TOPIC_RECORDING] = RecordingSeal
