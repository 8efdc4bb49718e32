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

from typing import Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from trace_runtime.errors import RecordError

PROFILE = "trace"
PROFILE_VERSION = "1.1"

TOPIC_PERCEPTION = "/trace/perception"
TOPIC_BELIEF = "/trace/belief"
TOPIC_ACTION = "/trace/action"
TOPIC_EXECUTION = "/trace/execution"
TOPIC_SEAL = "/trace/seal"
LAYER_TOPICS = (TOPIC_PERCEPTION, TOPIC_BELIEF, TOPIC_ACTION, TOPIC_EXECUTION)
SENSOR_PREFIX = "/sensors/"

Scalar = float | int | bool | str

Comparison = Literal["<", "<=", ">", ">=", "==", "!="]


class _Record(BaseModel):
    model_config = ConfigDict(
        frozen=True,
        extra="forbid",
        allow_inf_nan=False,
        populate_by_name=True,
        ser_json_inf_nan="null",
    )

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as err:
            raise RecordError(_describe(type(self).__name__, err)) from err

    # Tell pydantic this __init__ only wraps errors: nested records validated from dicts then
    # stay on pydantic's fast path instead of calling back into Python once per object.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]


def _describe(model: str, err: ValidationError) -> str:
    first = err.errors()[0]
    where = ".".join(str(p) for p in first["loc"]) or "<root>"
    more = f" (and {err.error_count() - 1} more)" if err.error_count() > 1 else ""
    return f"invalid {model}: {where}: {first['msg']}{more}"


R = TypeVar("R", bound=_Record)


def validate_record(model: type[R], data: Any) -> R:
    """Validate ``data`` (a dict or already a model) as ``model``; raise ``RecordError``."""
    if isinstance(data, model):
        return data
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise RecordError(_describe(model.__name__, err)) from err


# --- shared pieces ---------------------------------------------------------------------


class Pose(_Record):
    """A pose in SE(3): position in metres and a unit quaternion (x, y, z, w)."""

    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    frame: str = "map"


class EvidenceRef(_Record):
    """Names one sensor message: topic + log time (+ sequence, + content digest).

    Without ``recording`` the message is in the TRACE log itself (a ``/sensors/...``
    channel). With ``recording`` it is in another MCAP file, e.g. a rosbag2 recording made
    beside the log: ``recording`` is that file's name, ``topic`` the topic there (a ROS 2
    topic such as ``/front_camera/image_raw``), and ``digest`` the SHA-256 of the message's
    stored data (its CDR bytes for ROS 2). PROFILE.md section 11.
    """

    topic: str = Field(min_length=1, description="the topic the message was logged on")
    log_time_ns: int = Field(ge=0, description="the message's MCAP log time, ns")
    sequence: int | None = Field(default=None, ge=0, description="the message's MCAP sequence")
    digest: str | None = Field(default=None, description="sha256 hex of the message data")
    recording: str | None = Field(
        default=None,
        description="file name of the external MCAP recording holding the message; "
        "null when it is in this log",
    )


class Region(_Record):
    """The part of a sensor reading that supported a detection.

    ``kind`` says how to read ``values``: ``beams`` = [first_beam, last_beam] of a scan,
    ``box`` = [xmin, ymin, xmax, ymax] in ``frame``, ``cone`` = [bearing_rad, half_width_rad,
    range_m], ``pixels`` = [u0, v0, u1, v1].
    """

    kind: Literal["beams", "box", "cone", "pixels"]
    values: list[float]
    frame: str = "base_link"


class Evidence(_Record):
    """One member of an entity's evidence set (Def. 1): sensor, weight, region and ref."""

    sensor: str = Field(min_length=1)
    weight: float = Field(ge=0.0, le=1.0)
    region: Region | None = None
    ref: EvidenceRef | None = Field(
        default=None, description="null when the link to the sensor reading was not recorded"
    )


# --- layer 1: perception ---------------------------------------------------------------


class Entity(_Record):
    """An evidence-grounded entity (Def. 1)."""

    id: str = Field(min_length=1)
    cls: str = Field(alias="class", min_length=1)
    pose: Pose
    velocity: tuple[float, float, float] | None = None
    confidence: dict[str, float] = Field(
        description="calibrated confidence per class, each in [0, 1]"
    )
    evidence: list[Evidence] = Field(default_factory=list)


class Perception(_Record):
    """Layer 1: the entity set E_t and its evidence aggregation record."""

    entities: list[Entity] = Field(default_factory=list)
    sensors_used: list[str] = Field(default_factory=list)
    sensors_unavailable: list[str] = Field(default_factory=list)
    robot_pose: Pose | None = Field(
        default=None,
        description="the robot's own pose at this cycle, in the frame of the entities' poses",
    )


# --- layer 2: belief -------------------------------------------------------------------


class BeliefNode(_Record):
    """A node of the belief graph: an entity, or a derived state such as ``collision_risk``."""

    id: str = Field(min_length=1)
    kind: Literal["entity", "state"]
    label: str = ""
    p: float = Field(ge=0.0, le=1.0, description="P(node holds) / confidence")
    value: Scalar | None = None
    unit: str | None = None
    entity: str | None = Field(default=None, description="entity id, for kind == entity")


class BeliefEdge(_Record):
    """A documented inference: ``child`` was derived from ``parent`` by ``rule``."""

    parent: str = Field(min_length=1)
    child: str = Field(min_length=1)
    p: float = Field(ge=0.0, le=1.0, description="P(child | parent)")
    rule: str = Field(min_length=1)


class Belief(_Record):
    """Layer 2: the probabilistic scene / causal graph B_t = (V, E, P) (Def. 2)."""

    nodes: list[BeliefNode] = Field(default_factory=list)
    edges: list[BeliefEdge] = Field(default_factory=list)


# --- layer 3: action -------------------------------------------------------------------


class Factor(_Record):
    """A belief node the decision depended on, with the value the policy saw."""

    node: str = Field(min_length=1, description="id of a node in this cycle's belief graph")
    name: str = ""
    value: Scalar
    unit: str | None = None


class Rationale(_Record):
    """Why the command was chosen: text plus the structured factors (R in Def. 3)."""

    text: str
    factors: list[Factor] = Field(default_factory=list)
    truncated: bool = Field(
        default=False, description="set by the writer of the rationale when it ran out of room"
    )


class Alternative(_Record):
    """A command that was considered and lost, with its score and the reason."""

    command: str = Field(min_length=1)
    score: float
    rejected_because: str


class Counterfactual(_Record):
    """``would_select`` would have been chosen had ``factor`` satisfied the comparison."""

    factor: str = Field(min_length=1, description="belief node id of the factor")
    comparison: Comparison
    threshold: Scalar
    would_select: str = Field(min_length=1)


class TreeNode(_Record):
    """A node of the counterfactual decision tree: a test, or a leaf naming a command."""

    id: str = Field(min_length=1)
    label: str
    test: str | None = None
    command: str | None = None


class TreeEdge(_Record):
    parent: str
    child: str
    label: str = ""


class DecisionTree(_Record):
    """The counterfactual decision tree (paper Fig. 2) with the path the policy took."""

    nodes: list[TreeNode]
    edges: list[TreeEdge]
    taken_path: list[str] = Field(description="node ids from root to the chosen leaf")


class Action(_Record):
    """Layer 3: the justified action a*_t = <cmd, A_alt, R, CF> (Def. 3)."""

    command: str = Field(min_length=1)
    parameters: dict[str, float] = Field(default_factory=dict)
    score: float | None = None
    alternatives: list[Alternative] = Field(default_factory=list)
    rationale: Rationale
    counterfactuals: list[Counterfactual] = Field(default_factory=list)
    counterfactuals_none_applicable: bool = Field(
        default=False, description="true when no factor value could change the choice"
    )
    tree: DecisionTree | None = None


# --- layer 4: execution ----------------------------------------------------------------


class Motion(_Record):
    """A planar motion command or measurement: linear m/s, angular rad/s."""

    linear: float
    angular: float = 0.0


class ComplianceCheck(_Record):
    rule: str = Field(min_length=1)
    passed: bool
    value: float | None = None
    limit: float | None = None
    detail: str = ""


class Execution(_Record):
    """Layer 4: intended vs actual behaviour, deviation delta_t, compliance, flags."""

    intended: Motion
    actual: Motion
    deviation: float = Field(ge=0.0)
    checks: list[ComplianceCheck] = Field(default_factory=list)
    flags: list[str] = Field(default_factory=list)


# --- messages on the wire --------------------------------------------------------------


class _Stamp(_Record):
    cycle: int = Field(ge=0)
    t_ns: int = Field(ge=0)


class PerceptionMessage(_Stamp, Perception):
    """``/trace/perception``"""


class BeliefMessage(_Stamp, Belief):
    """``/trace/belief``"""


class ActionMessage(_Stamp, Action):
    """``/trace/action``"""


class ExecutionMessage(_Stamp, Execution):
    """``/trace/execution``"""


class Seal(_Stamp):
    """``/trace/seal``: T_t, closing one cycle and linking it into the hash chain."""

    digests: dict[str, str] = Field(description="layer topic -> sha256 hex of its message data")
    prev: str = Field(description="sha256 hex of the previous seal's data; 64 zeros at genesis")
    dropped: int = Field(default=0, ge=0, description="cycles dropped since the previous seal")


LayerRecord = Perception | Belief | Action | Execution

MESSAGE_MODELS: dict[str, type[_Stamp]] = {
    TOPIC_PERCEPTION: PerceptionMessage,
    TOPIC_BELIEF: BeliefMessage,
    TOPIC_ACTION: ActionMessage,
    TOPIC_EXECUTION: ExecutionMessage,
    TOPIC_SEAL: Seal,
}

LAYER_MODELS: dict[str, type[_Record]] = {
    TOPIC_PERCEPTION: Perception,
    TOPIC_BELIEF: Belief,
    TOPIC_ACTION: Action,
    TOPIC_EXECUTION: Execution,
}

GENESIS = "0" * 64


# --- integrity: signed checkpoints -------------------------------------------------------

TOPIC_CHECKPOINT = "/trace/checkpoint"


class Checkpoint(_Stamp):
    """``/trace/checkpoint``: a (signed) statement of the chain head, CT's signed tree head.

    ``cycle``/``t_ns`` are those of the head seal; ``head`` is the SHA-256 of that seal's data,
    so the checkpoint vouches for every cycle the chain reaches back to. A checkpoint is not
    part of any cycle. The signature is Ed25519 over ``trace_runtime.integrity.signing_bytes``
    (see docs/integrity.md); both it and ``key_id`` are null when the logger has no key.
    """

    robot_id: str = Field(min_length=1)
    segment: int = Field(ge=0, description="number of the segment the checkpoint was written in")
    first_cycle: int = Field(ge=0, description="first cycle of that segment")
    sealed: int = Field(ge=0, description="seals written in the segment, first_cycle..cycle")
    head: str = Field(description="sha256 hex of the head seal's data")
    final: bool = Field(default=False, description="written when the segment was closed")
    key_id: str | None = Field(
        default=None, description="sha256 hex of the raw 32-byte Ed25519 public key"
    )
    signature: str | None = Field(default=None, description="Ed25519 signature, hex")


MESSAGE_MODELS[TOPIC_CHECKPOINT] = Checkpoint
