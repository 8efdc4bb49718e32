"""Tamper evidence for TRACE logs: signed checkpoints over the per-cycle hash chain.

Every cycle's seal names the SHA-256 of its layer messages and of the previous seal, so a
change, removal or reordering breaks a link. Anyone can recompute such a chain, though; a
*checkpoint* (``/trace/checkpoint``) states the chain head (the digest of the last seal) and
is signed with the robot's Ed25519 key, like a Certificate Transparency signed tree head or
a CloudTrail digest file. A signed head vouches for every cycle the chain reaches back to.

This module holds the primitives a logger, a storage gateway or the investigator needs:
key files, building and signing checkpoints, checking a signature, and ``verify_cycle``,
the check of one cycle against its seal. The whole-log verification built on it lives in
``trace_runtime.verification`` (``trace-audit verify`` and retention both use it).
``cryptography`` is imported only when a key is used, so a robot logging unsigned
checkpoints does not pay for it. The byte formats are specified in docs/integrity.md.
"""

from __future__ import annotations

import hashlib
import logging
import os
import stat
from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol, runtime_checkable

import orjson

from trace_runtime.chain import digest
from trace_runtime.errors import RecordError, UsageError
from trace_runtime.records import (
    LAYER_TOPICS,
    TOPIC_CHECKPOINT,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
    Checkpoint,
    validate_record,
)

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import (
        Ed25519PrivateKey,
    )

    from trace_runtime.cycles import Cycle, RawMessage
    from trace_runtime.reader import Segment

__all__ = [
    "CHECKPOINT_FORMAT",
    "CheckpointState",
    "Ed25519Signer",
    "KeyPair",
    "PublicKey",
    "SealState",
    "SealStatus",
    "Signer",
    "check_checkpoint",
    "decode_checkpoint",
    "encode_checkpoint",
    "generate_keypair",
    "iter_checkpoints",
    "key_id_of",
    "load_public_key",
    "load_signer",
    "make_checkpoint",
    "signing_bytes",
    "verify_cycle",
]

log = logging.getLogger("trace_runtime")

CHECKPOINT_FORMAT = "trace-checkpoint/1"
"""First line of the signed bytes; bumped if the signed fields ever change."""

PRIVATE_SUFFIX = ".key"
PUBLIC_SUFFIX = ".pub"


# --- keys ----------------------------------------------------------------------------------


def key_id_of(raw_public_key: bytes) -> str:
    """The key id of an Ed25519 public key: SHA-256 hex of its raw 32 bytes."""
    return hashlib.sha256(raw_public_key).hexdigest()


@runtime_checkable
class Signer(Protocol):
    """What the logger needs to sign checkpoints; an HSM or TPM can stand behind it."""

    @property
    def key_id(self) -> str: ...

    def sign(self, data: bytes) -> bytes: ...


@dataclass(frozen=True, slots=True)
class PublicKey:
    """An Ed25519 public key that checks checkpoint signatures."""

    raw: bytes
    key_id: str

    @classmethod
    def from_raw(cls, raw: bytes) -> PublicKey:
        if len(raw) != 32:
            raise UsageError(f"an Ed25519 public key is 32 bytes, got {len(raw)}")
        return cls(raw, key_id_of(raw))

    def verify(self, signature: bytes, data: bytes) -> bool:
        """True when ``signature`` is this key's Ed25519 signature of ``data``."""
        from cryptography.exceptions import InvalidSignature
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

        try:
            Ed25519PublicKey.from_public_bytes(self.raw).verify(signature, data)
        except (InvalidSignature, ValueError):
            return False
        return True


class Ed25519Signer:
    """Signs with an Ed25519 private key held in memory."""

    __slots__ = ("_key", "key_id", "public_key")

    def __init__(self, key: Ed25519PrivateKey) -> None:
        from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

        self._key = key
        raw = key.public_key().public_bytes(Encoding.Raw, PublicFormat.Raw)
        self.public_key = PublicKey.from_raw(raw)
        self.key_id = self.public_key.key_id

    @classmethod
    def generate(cls) -> Ed25519Signer:
        """A signer with a fresh random key (tests, or a key the caller stores itself)."""
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

        return cls(Ed25519PrivateKey.generate())

    def sign(self, data: bytes) -> bytes:
        return self._key.sign(data)

    def private_pem(self) -> bytes:
        """The private key as unencrypted PKCS#8 PEM (what ``keygen`` writes)."""
        from cryptography.hazmat.primitives.serialization import (
            Encoding,
            NoEncryption,
            PrivateFormat,
        )

        return self._key.private_bytes(Encoding.PEM, PrivateFormat.PKCS8, NoEncryption())

    def public_pem(self) -> bytes:
        """The public key as SubjectPublicKeyInfo PEM."""
        from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

        return self._key.public_key().public_bytes(Encoding.PEM, PublicFormat.SubjectPublicKeyInfo)


def _read_key_file(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError as err:
        raise UsageError(f"{what} {path}: no such file") from err
    except OSError as err:
        raise UsageError(f"{what} {path}: cannot read ({err.strerror or err})") from err


def load_signer(path: str | Path) -> Ed25519Signer:
    """Load an Ed25519 private key: PKCS#8 PEM (``keygen``, ``openssl genpkey``) or 32 raw bytes."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
    from cryptography.hazmat.primitives.serialization import load_pem_private_key

    path = Path(path)
    data = _read_key_file(path, "private key")
    try:
        mode = path.stat().st_mode
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            log.warning("private key %s is readable by others (mode %o)", path, mode & 0o777)
    except OSError:
        pass
    if len(data) == 32 and not data.startswith(b"-----"):
        return Ed25519Signer(Ed25519PrivateKey.from_private_bytes(data))
    try:
        key = load_pem_private_key(data, password=None)
    except (ValueError, TypeError) as err:
        raise UsageError(f"private key {path}: not an unencrypted PEM or raw Ed25519 key") from err
    if not isinstance(key, Ed25519PrivateKey):
        raise UsageError(f"private key {path}: not an Ed25519 key")
    return Ed25519Signer(key)


def load_public_key(path: str | Path) -> PublicKey:
    """Load an Ed25519 public key: PEM (SubjectPublicKeyInfo), OpenSSH, or 32 raw bytes."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import (
        Encoding,
        PublicFormat,
        load_pem_public_key,
        load_ssh_public_key,
    )

    path = Path(path)
    data = _read_key_file(path, "public key")
    if len(data) == 32 and not data.startswith((b"-----", b"ssh-")):
        return PublicKey.from_raw(data)
    if b"PRIVATE KEY" in data:
        raise UsageError(f"{path} is a private key; verify with the public key (.pub)")
    try:
        key: object = (
            load_ssh_public_key(data) if data.startswith(b"ssh-") else load_pem_public_key(data)
        )
    except (ValueError, TypeError) as err:
        raise UsageError(f"public key {path}: not a PEM, OpenSSH or raw Ed25519 key") from err
    if not isinstance(key, Ed25519PublicKey):
        raise UsageError(f"public key {path}: not an Ed25519 key")
    return PublicKey.from_raw(key.public_bytes(Encoding.Raw, PublicFormat.Raw))


@dataclass(frozen=True, slots=True)
class KeyPair:
    """Where ``generate_keypair`` wrote a key pair, and its key id."""

    private_path: Path
    public_path: Path
    key_id: str


def generate_keypair(
    directory: str | Path, *, name: str = "trace-ed25519", overwrite: bool = False
) -> KeyPair:
    """Write ``NAME.key`` (PKCS#8 PEM, mode 0600) and ``NAME.pub`` (PEM) into ``directory``."""
    if not name or "/" in name or name.startswith("."):
        raise UsageError(f"key name must be a plain file name: {name!r}")
    directory = Path(directory)
    private_path = directory / f"{name}{PRIVATE_SUFFIX}"
    public_path = directory / f"{name}{PUBLIC_SUFFIX}"
    if not overwrite:
        for path in (private_path, public_path):
            if path.exists():
                raise UsageError(f"{path} exists; refusing to overwrite a key (use --force)")
    signer = Ed25519Signer.generate()
    try:
        directory.mkdir(parents=True, exist_ok=True)
        _write_private(private_path, signer.private_pem(), overwrite=overwrite)
        public_path.write_bytes(signer.public_pem())
    except OSError as err:
        raise UsageError(f"cannot write keys to {directory}: {err.strerror or err}") from err
    return KeyPair(private_path, public_path, signer.key_id)


def _write_private(path: Path, data: bytes, *, overwrite: bool) -> None:
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
    fd = os.open(path, flags, 0o600)
    try:
        os.fchmod(fd, 0o600)  # also when overwriting a file that had a looser mode
        os.write(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)


# --- checkpoints ----------------------------------------------------------------------------


def signing_bytes(checkpoint: Checkpoint) -> bytes:
    """The exact bytes an Ed25519 checkpoint signature covers (docs/integrity.md).

    Not JSON: one ``name=value`` line per field of the unsigned body, in fixed order, decimal
    integers, lowercase hex digests, ``true``/``false``, empty for an absent key id. Every
    language produces these bytes the same way; the message's own JSON never has to be
    re-serialised to check a signature.
    """
    c = checkpoint
    lines = (
        CHECKPOINT_FORMAT,
        f"robot_id={c.robot_id}",
        f"segment={c.segment}",
        f"first_cycle={c.first_cycle}",
        f"cycle={c.cycle}",
        f"t_ns={c.t_ns}",
        f"sealed={c.sealed}",
        f"head={c.head}",
        f"final={'true' if c.final else 'false'}",
        f"key_id={c.key_id or ''}",
    )
    return ("\n".join(lines) + "\n").encode()


def make_checkpoint(
    *,
    robot_id: str,
    segment: int,
    first_cycle: int,
    cycle: int,
    t_ns: int,
    sealed: int,
    head: str,
    final: bool = False,
    signer: Signer | None = None,
) -> Checkpoint:
    """Build a checkpoint of the chain head; signed when ``signer`` is given."""
    body = Checkpoint(
        cycle=cycle,
        t_ns=t_ns,
        robot_id=robot_id,
        segment=segment,
        first_cycle=first_cycle,
        sealed=sealed,
        head=head,
        final=final,
        key_id=None if signer is None else signer.key_id,
    )
    if signer is None:
        return body
    return body.model_copy(update={"signature": signer.sign(signing_bytes(body)).hex()})


def encode_checkpoint(checkpoint: Checkpoint) -> bytes:
    """The message data of a checkpoint: compact JSON of the model, like a seal."""
    return checkpoint.model_dump_json(by_alias=True).encode()


def decode_checkpoint(data: bytes) -> Checkpoint:
    """Parse checkpoint message data; ``RecordError`` when it is not a valid checkpoint."""
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError as err:
        raise RecordError(f"invalid Checkpoint: not JSON ({err})") from err
    return validate_record(Checkpoint, value)


CheckpointState = Literal["valid", "unchecked", "unsigned", "bad_signature", "key_mismatch"]
"""``valid``: signed by the expected key; ``unchecked``: no key to check against;
``unsigned``: a key was expected but the checkpoint has no signature; ``key_mismatch``: it
names another key; ``bad_signature``: it names the key but the signature does not verify."""


def check_checkpoint(checkpoint: Checkpoint, key: PublicKey | None) -> CheckpointState:
    """Check a checkpoint's signature against the expected public key (None: cannot check)."""
    if key is None:
        return "unchecked"
    if not checkpoint.signature:
        return "unsigned"
    if checkpoint.key_id != key.key_id:
        return "key_mismatch"
    try:
        signature = bytes.fromhex(checkpoint.signature)
    except ValueError:
        return "bad_signature"
    return "valid" if key.verify(signature, signing_bytes(checkpoint)) else "bad_signature"


def iter_checkpoints(segment: Segment) -> Iterator[RawMessage]:
    """The raw ``/trace/checkpoint`` messages of a segment, in reading order."""
    for message in segment.iter_messages():
        if message.topic == TOPIC_CHECKPOINT:
            yield message


# --- one cycle against its seal -----------------------------------------------------------------

SealState = Literal["verified", "summarised", "modified", "broken_link", "unsealed"]


@dataclass(frozen=True, slots=True)
class SealStatus:
    """Whether one cycle matches its seal, and its seal the previous one.

    ``state``: ``verified`` (every layer message and evidenced sensor reading matches the
    seal; the link to the previous seal holds or was not asked about), ``summarised`` (a warm
    summary cycle: the seal and its link verify, the layer payloads are not retained),
    ``modified`` (a message differs from what the seal names, or the seal is malformed),
    ``broken_link`` (content matches, but the seal does not name ``prev_seal_digest``),
    ``unsealed`` (layer messages without a seal). ``seal_digest`` is what the next cycle's
    seal must name as ``prev``. Sensor readings are not sealed themselves; the evidence refs
    that name them (sealed with the perception message) carry their digests, and
    ``evidence_mismatch`` lists the readings that differ from them.
    """

    cycle: int
    t_ns: int
    state: SealState
    seal_digest: str | None = None
    prev: str | None = None
    link: Literal["ok", "broken", "unchecked"] = "unchecked"
    dropped: int = 0
    modified: tuple[str, ...] = ()
    missing: tuple[str, ...] = ()
    extra: tuple[str, ...] = ()
    summarised: tuple[str, ...] = ()
    evidence_checked: int = 0
    evidence_unresolved: int = 0
    evidence_mismatch: tuple[str, ...] = ()
    sensors_uncited: int = 0
    """Sensor readings in the cycle that no digest-carrying evidence ref names: the chain
    does not cover them."""
    external: tuple[dict[str, Any], ...] = ()
    """Evidence refs naming a message in an external recording (PROFILE section 11), as
    JSON: sealed with the perception message, checked only against the recording itself
    (``trace_runtime.recordings``)."""
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.state in ("verified", "summarised") and not self.evidence_mismatch

    def describe(self) -> str:
        """One line for people, e.g. ``modified: /trace/action differs from its seal``."""
        evidence = ""
        if self.evidence_mismatch:
            evidence = (
                f"; sensor reading {', '.join(self.evidence_mismatch)} does not match "
                "the digest its evidence ref names"
            )
        if self.state == "verified":
            link = "" if self.link == "ok" else " (link to the previous seal not checked)"
            return f"seal verifies{link}{evidence}"
        if self.state == "summarised":
            return f"summarised (chain verified, payloads not retained){evidence}"
        return f"{self.state.replace('_', ' ')}: {self.detail}{evidence}"


def _parse_seal(data: bytes) -> tuple[int, int, dict[str, str], str, int] | None:
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError:
        return None
    if not isinstance(value, dict):
        return None
    cycle, t_ns = value.get("cycle"), value.get("t_ns")
    digests, prev, dropped = value.get("digests"), value.get("prev"), value.get("dropped", 0)
    if not (
        type(cycle) is int
        and type(t_ns) is int
        and isinstance(digests, dict)
        and isinstance(prev, str)
        and type(dropped) is int
    ):
        return None
    for topic, named in digests.items():  # a loop, not all(...): no generator a cycle
        if not (isinstance(topic, str) and isinstance(named, str)):
            return None
    return cycle, t_ns, digests, prev, dropped


def verify_cycle(
    cycle: Cycle,
    prev_seal_digest: str | None = None,
    *,
    perception_json: Any = None,
    sensor_digest: Callable[[RawMessage], str] | None = None,
) -> SealStatus:
    """Check one cycle: its layer messages (and evidenced sensor readings) against its seal,
    and, when ``prev_seal_digest`` is given, the seal's link to the previous seal.

    Works on every tier through the reader's ``Cycle``: for a warm summary cycle the layer
    digests cannot be recomputed, so it is ``summarised`` when its seal and link hold.
    ``perception_json``: the cycle's perception message already parsed by the caller (the
    evidence check then does not parse it a second time); it must be the parse of the stored
    bytes, which the seal check covers. ``sensor_digest``: gives the SHA-256 hex of a sensor
    message's data, for a caller that already hashed the cycle's readings (the metrics'
    sensor window); it must be the digest of the stored data.
    """
    seal_data = cycle.payloads.get(TOPIC_SEAL)
    if seal_data is None:
        topics = ", ".join(sorted(cycle.payloads)) or "no layer messages"
        return SealStatus(cycle.cycle, cycle.t_ns, "unsealed", detail=f"no seal ({topics})")
    seal_digest = digest(seal_data)
    parsed = _parse_seal(seal_data)
    if parsed is None:
        return SealStatus(
            cycle.cycle,
            cycle.t_ns,
            "modified",
            seal_digest,
            modified=(TOPIC_SEAL,),
            detail="the seal is not a valid seal record",
        )
    number, t_ns, digests, prev, dropped = parsed
    problems: list[str] = []
    if number != cycle.cycle or t_ns != cycle.t_ns:
        problems.append(
            f"the seal says cycle {number} at {t_ns} ns, the log stores it as cycle "
            f"{cycle.cycle} at {cycle.t_ns} ns"
        )
    modified: list[str] = []
    missing: list[str] = []
    summarised: list[str] = []
    for topic, expected in digests.items():
        data = cycle.payloads.get(topic)
        if data is None:
            (summarised if cycle.summary is not None else missing).append(topic)
        elif digest(data) != expected:
            modified.append(topic)
    # A layer the seal does not name was added. A /trace channel this reader does not know
    # and the seal does not name is ignored, as PROFILE section 10 asks of every reader.
    extra = [t for t in cycle.payloads if t in LAYER_TOPICS and t not in digests]
    checked, unresolved, uncited = 0, 0, len(cycle.sensors)
    bad: list[str] = []
    external: list[dict[str, Any]] = []
    perception = cycle.payloads.get(TOPIC_PERCEPTION)
    if perception is not None and TOPIC_PERCEPTION not in modified:
        # Sensor readings are not sealed themselves: the evidence refs that name them carry
        # their digests, and the refs are sealed with the perception message.
        checked, unresolved, bad, uncited = _check_evidence(
            cycle, perception, perception_json, external, sensor_digest
        )
    if modified:
        verb = "differs" if len(modified) == 1 else "differ"
        problems.append(f"{', '.join(modified)} {verb} from the seal's digest")
    if missing:
        problems.append(", ".join(missing) + " named by the seal but not in the log")
    if extra:
        problems.append(", ".join(extra) + " not named by the seal")

    link: Literal["ok", "broken", "unchecked"] = "unchecked"
    if prev_seal_digest is not None:
        link = "ok" if prev == prev_seal_digest else "broken"
    state: SealState
    if problems:
        state, detail = "modified", "; ".join(problems)
    elif link == "broken":
        state = "broken_link"
        assert prev_seal_digest is not None
        detail = (
            f"the seal names previous seal {prev[:12]}…, the chain has {prev_seal_digest[:12]}…"
        )
    else:
        state = "summarised" if summarised else "verified"
        detail = ""
    return _seal_status(
        cycle.cycle,
        cycle.t_ns,
        state,
        seal_digest,
        prev,
        link,
        dropped,
        tuple(modified),
        tuple(missing),
        tuple(extra),
        tuple(summarised),
        checked,
        unresolved,
        tuple(bad),
        uncited,
        tuple(external),
        detail,
    )


# The slot setters of SealStatus in field order. Its frozen dataclass __init__ sets each of
# the 17 fields through object.__setattr__ (3-5 us); metrics checks every cycle's seal, so
# verify_cycle fills the slots directly (about half of that).
_SEAL_STATUS_SETTERS = tuple(getattr(SealStatus, f.name).__set__ for f in fields(SealStatus))


def _seal_status(*values: Any) -> SealStatus:
    """``SealStatus(*values)``, every field given in order: the same value, built faster."""
    status = object.__new__(SealStatus)
    for set_field, value in zip(_SEAL_STATUS_SETTERS, values, strict=True):
        set_field(status, value)
    return status


def _check_evidence(
    cycle: Cycle,
    perception: bytes,
    parsed: Any = None,
    external: list[Any] | None = None,
    sensor_digest: Callable[[RawMessage], str] | None = None,
) -> tuple[int, int, list[str], int]:
    """Check the evidence refs that carry a digest against the cycle's sensor messages.

    Returns (refs checked, refs unresolved, readings that differ, readings no ref cites).
    Refs into an external recording are not looked for in the cycle: they are appended to
    ``external`` (when given) for the caller to check against the recording.
    """
    try:
        value = parsed if parsed is not None else orjson.loads(perception)
        entities = value.get("entities") or ()
    except (orjson.JSONDecodeError, AttributeError):
        return 0, 0, [], len(cycle.sensors)
    sensors = cycle.sensors
    by_sequence = {(m.topic, m.sequence): i for i, m in enumerate(sensors)}
    by_time: dict[tuple[Any, Any], int] | None = None  # built on the first ref without a match
    digests: dict[int, str] = {}
    checked = unresolved = 0
    bad: list[str] = []
    for entity in entities:
        for evidence in entity.get("evidence") or ():
            ref = evidence.get("ref")
            if not ref:
                continue
            if isinstance(ref.get("recording"), str):
                if external is not None:
                    external.append(ref)
                continue
            if not ref.get("digest"):
                continue
            topic, seq = ref.get("topic"), ref.get("sequence")
            index = by_sequence.get((topic, seq)) if seq is not None else None
            if index is None:
                if by_time is None:
                    by_time = {(m.topic, m.log_time_ns): i for i, m in enumerate(sensors)}
                index = by_time.get((topic, ref.get("log_time_ns")))
            if index is None:
                unresolved += 1
                continue
            checked += 1
            if index not in digests:
                reading = cycle.sensors[index]
                digests[index] = (
                    digest(reading.data) if sensor_digest is None else sensor_digest(reading)
                )
            if digests[index] != ref["digest"]:
                label = f"{topic}#{cycle.sensors[index].sequence}"
                if label not in bad:
                    bad.append(label)
    return checked, unresolved, bad, len(cycle.sensors) - len(digests)
