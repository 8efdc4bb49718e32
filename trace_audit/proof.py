"""A proof bundle: one decision cycle, checkable without the log (``trace-audit prove`` and
``trace-audit verify-proof``; the format is in docs/integrity.md, "Proof bundles").

A bundle holds the cycle's stored messages (base64 of a raw DEFLATE stream of their bytes,
with their topics), the sensor readings its profile 1.3 seal covers (each with its topic,
sequence and log time), the recording messages its evidence refs cite (``proof_readings``),
its seal, the seal's leaf index in the robot's RFC 6962 tree, the inclusion proof of that
leaf in the tree of the newest signed profile 1.2 checkpoint (a cosigned one where the
root's witness store holds one that covers it), and that checkpoint's note (since
``trace-proof/5`` the leaf index, proof and note as one C2SP tlog-proof text, and the key
rotations announced before that checkpoint, ``proof_keys``): about 8 KB at most on a 24 h
simulator log. ``check_bundle`` checks, in order: each message's digest
against the seal, the readings against the seal's ``sensors`` and the recording messages
against the sealed refs, the seal's leaf in the tree (inclusion proof to the note's root),
the note's signature by the robot's key (moved on through the carried key rotations) under
its origin and, given a witness key, the witness's cosignature.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypedDict, TypeVar

import orjson

from trace_audit.evidence import recordings_for
from trace_audit.proof_data import BadBundleError, DataReader, b64, deflated, field_of, unb64
from trace_audit.proof_keys import followed_key, rotations_before
from trace_audit.proof_readings import check_readings, check_recorded, readings_of, recorded_of
from trace_audit.witness.tree import LevelTree
from trace_runtime.boundary import read_side_file, write_new
from trace_runtime.clock import iso_utc
from trace_runtime.errors import LogReadError, NoteError, StorageError, UsageError
from trace_runtime.reading.chain_tree import prove_pass
from trace_runtime.reading.logset import Log, open_log
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tlog.cosignature_store import read_cosigned
from trace_runtime.tlog.keys import PublicKey, load_public_key
from trace_runtime.tlog.merkle import leaf_hash, verify_inclusion
from trace_runtime.tlog.signed_note import (
    COSIGNATURE,
    NoteVerifier,
    OpenedNote,
    open_note,
    parse_checkpoint,
    parse_verifier_key,
)
from trace_runtime.tlog.tlog_proof import format_tlog_proof, parse_tlog_proof

__all__ = [
    "BUNDLE_FORMAT",
    "MAX_BUNDLE_BYTES",
    "BundleCheck",
    "ProofBundle",
    "WrittenBundle",
    "check_bundle",
    "make_bundle",
    "read_bundle",
    "verify_proof",
    "write_bundle",
]

BUNDLE_FORMAT = "trace-proof/5"
"""The format ``prove`` writes: ``trace-proof/4`` (``/3``, itself ``/2`` with each message's
and reading's data deflated, with the recording messages the cycle's refs cite,
``recorded``) whose inclusion proof and checkpoint note are one C2SP tlog-proof text
(``tlog_proof``, c2sp.org/tlog-proof@v1), which any tlog client checks as it is, and the
key rotations the robot's chain announced before its checkpoint (``key_rotations``)."""
BUNDLE_FORMATS = (
    "trace-proof/1",
    "trace-proof/2",
    "trace-proof/3",
    "trace-proof/4",
    BUNDLE_FORMAT,
)
T = TypeVar("T")


class ProofBundle(TypedDict):
    """A bundle as ``make_bundle`` builds it (``BUNDLE_FORMAT``); one read from a file is
    untrusted JSON (``read_bundle``) until ``check_bundle`` has checked every field."""

    format: str
    cycle: int
    t_ns: int
    messages: list[dict[str, str]]  # topic, data
    sensors: list[dict[str, str | int]]  # topic, sequence, log_time_ns, data
    recorded: list[dict[str, str | int]]  # recording, topic, log_time_ns, sequence, data
    seal: str
    leaf_index: int
    tree_size: int
    root: str
    tlog_proof: str  # index, inclusion hashes, the checkpoint note (c2sp.org/tlog-proof@v1)
    cosigned: bool
    key_rotations: list[dict[str, str | int]]  # proof_keys.ROTATION_FIELDS, in chain order


_FIELDS_4 = ProofBundle.__required_keys__ - {"tlog_proof", "key_rotations"} | {
    "inclusion",
    "note",
}
_FIELDS_1 = _FIELDS_4 - {"sensors", "recorded"}
BUNDLE_FIELDS = {
    "trace-proof/1": _FIELDS_1,
    "trace-proof/2": _FIELDS_1 | {"sensors"},
    "trace-proof/3": _FIELDS_1 | {"sensors"},
    "trace-proof/4": _FIELDS_4,
    BUNDLE_FORMAT: ProofBundle.__required_keys__,
}
"""Every field of a bundle of each format, all required; any other is refused (nothing in a
bundle goes unchecked: the robot is named by the note's origin, which the robot's key
signs)."""
MAX_BUNDLE_BYTES = 16 << 20

"""All of a bundle's data together, inflated: a bomb stops here."""


def make_bundle(
    log_path: str | Path,
    cycle: int,
    *,
    robot: str | None = None,
    evidence: Sequence[str | Path] = (),
) -> ProofBundle:
    """The proof bundle of ``cycle`` of ``robot`` (the log's only robot when None), carrying
    the recording messages its refs cite (the recordings the log declares, or ``evidence``)."""
    log = open_log(log_path)
    robot_id = _one_robot(log, robot)
    proved = prove_pass(log, robot_id, cycle)
    found, index = proved.cycle, proved.index
    if found is None or index is None:
        raise UsageError(f"robot {robot_id} has no sealed cycle {cycle} in {log_path}")
    seal = found.payloads[TOPIC_SEAL]
    tree = LevelTree(proved.leaves)
    del proved
    note, size, cosigned = _covering_note(log, robot_id, index, tree)
    messages: list[dict[str, str]] = [
        {"topic": topic, "data": deflated(data)}
        for topic, data in sorted(found.payloads.items())
        if topic != TOPIC_SEAL
    ]
    covered = b'"sensors":{' in seal  # a 1.3 seal: the readings can be checked alone
    return {
        "format": BUNDLE_FORMAT,
        "cycle": cycle,
        "t_ns": found.t_ns,
        "messages": messages,
        "sensors": readings_of(found, covered),
        "recorded": recorded_of(found, recordings_for(log, evidence)),
        "seal": b64(seal),
        "leaf_index": index,
        "tree_size": size,
        "root": tree.root(size).hex(),
        "tlog_proof": format_tlog_proof(index, tree.inclusion_proof(index, size), note),
        "cosigned": cosigned,
        "key_rotations": rotations_before(log, robot_id, note),
    }


@dataclass(frozen=True, slots=True)
class WrittenBundle:
    """What ``write_bundle`` wrote: the file, its size, and the proof it holds."""

    path: str
    bytes: int
    cycle: int
    leaf_index: int
    tree_size: int
    proof_hashes: int
    cosigned: bool


def write_bundle(
    log_path: str | Path,
    cycle: int,
    out: str | Path,
    *,
    robot: str | None = None,
    evidence: Sequence[str | Path] = (),
) -> WrittenBundle:
    """Write the proof bundle of ``cycle`` (``make_bundle``) to ``out`` as indented JSON.

    ``out`` must not exist: ``StorageError`` before the log is read when it does (and again
    at the end, should the name be taken meanwhile: a bundle never replaces a file)."""
    out = Path(out)
    if os.path.lexists(out):
        raise StorageError(str(out), "it exists, and is never overwritten")
    bundle = make_bundle(log_path, cycle, robot=robot, evidence=evidence)
    data = orjson.dumps(bundle, option=orjson.OPT_INDENT_2) + b"\n"
    write_new(out, data)
    return WrittenBundle(
        path=str(out),
        bytes=len(data),
        cycle=bundle["cycle"],
        leaf_index=bundle["leaf_index"],
        tree_size=bundle["tree_size"],
        proof_hashes=len(parse_tlog_proof(bundle["tlog_proof"]).hashes),
        cosigned=bundle["cosigned"],
    )


def _one_robot(log: Log, robot: str | None) -> str:
    """``robot``, or the log's only robot; a ``UsageError`` naming the log's robots when
    there is no such robot or several to choose from (as ``publish --robot`` does)."""
    robots = log.robots
    if robot is not None and robot not in robots:
        held = ", ".join(robots) or "no robot"
        raise UsageError(f"no robot {robot} in {log.root} (it holds {held})")
    if robot is None and len(robots) != 1:
        named = f" ({', '.join(robots)})" if robots else ""
        raise UsageError(f"the log holds {len(robots)} robots{named}: name one with --robot")
    return robot or robots[0]


def _covering_note(log: Log, robot: str, index: int, tree: LevelTree) -> tuple[str, int, bool]:
    """The note of a tree covering leaf ``index``: the smallest cosigned one in the root's
    store that matches the seals, else the robot's newest signed checkpoint."""
    from trace_audit.witness.push import robot_checkpoints

    for record in sorted(read_cosigned(log.root, robot), key=lambda r: r.tree_size):
        fits = index < record.tree_size <= tree.size
        if fits and tree.root(record.tree_size).hex() == record.root:
            return record.note, record.tree_size, True
    signed = robot_checkpoints(log, robot)
    for checkpoint in reversed(signed):
        size = checkpoint.tree_size or 0
        if index < size <= tree.size and checkpoint.root == tree.root(size).hex():
            return checkpoint.note or "", size, False
    if not signed:
        raise UsageError(
            f"robot {robot}'s checkpoints are not signed, so nothing vouches for its tree: "
            "log with a checkpoint key (LoggerConfig.checkpoint_key, trace-audit keygen)"
        )
    raise UsageError(
        f"no signed profile 1.2 checkpoint of robot {robot} covers leaf {index} yet "
        "(a later checkpoint is needed)"
    )


@dataclass(slots=True)
class BundleCheck:
    """What ``check_bundle`` found: each step in order, ``ok`` when all passed."""

    path: str
    cycle: int | None = None
    t_ns: int | None = None
    tree_size: int | None = None
    leaf_index: int | None = None
    origin: str = ""
    steps: list[tuple[str, bool, str]] = field(default_factory=list)
    witness: str | None = None
    witnessed_at: str | None = None
    ok: bool = False


def read_bundle(path: str | Path) -> dict[str, object]:
    data = read_side_file(Path(path), limit=MAX_BUNDLE_BYTES)
    if data is None:
        raise LogReadError(str(path), "no such proof bundle")
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError as err:
        raise LogReadError(str(path), f"not a proof bundle: not JSON ({err})") from err
    if not isinstance(value, dict):
        raise LogReadError(str(path), "not a proof bundle: its JSON is not an object")
    if value.get("format") not in BUNDLE_FORMATS:
        raise LogReadError(str(path), f"not a proof bundle: {_format_of(value)}")
    return value


def _format_of(bundle: Mapping[str, object]) -> str:
    """What a bundle says its format is, against the ones this version reads (the value
    shown as JSON and shortened: it is the file's, so it may be anything)."""
    if "format" not in bundle:
        has = "it has no format field"
    else:
        shown = orjson.dumps(bundle["format"]).decode()
        has = f"its format is {shown if len(shown) <= 40 else shown[:37] + '...'}"
    return f"{has}; the formats read are {', '.join(BUNDLE_FORMATS)}"


def verify_proof(
    bundle_path: str | Path, key_path: str | Path, *, witness_key: str | None = None
) -> BundleCheck:
    """``verify-proof``: the bundle file checked (``check_bundle``) with the robot's public
    key file and, given, the witness's verifier key (``UsageError`` when it is not one)."""
    public = load_public_key(Path(key_path))
    verifier = None
    if witness_key is not None:
        try:
            verifier = parse_verifier_key(witness_key)
        except NoteError as err:
            raise UsageError(f"--witness-key: {err}") from err
    data = read_bundle(bundle_path)
    return check_bundle(data, public, witness_key=verifier, path=str(bundle_path))


def check_bundle(
    bundle: Mapping[str, object],
    key: PublicKey,
    *,
    witness_key: NoteVerifier | None = None,
    path: str = "",
) -> BundleCheck:
    """Check a bundle (see the module doc); never raises for what the bundle holds."""
    result = BundleCheck(path)
    try:
        _check(bundle, key, witness_key, result)
    except BadBundleError as err:
        result.steps.append(("bundle", False, str(err)))
    result.ok = bool(result.steps) and all(ok for _name, ok, _detail in result.steps)
    return result


def _check(
    bundle: Mapping[str, object], key: PublicKey, witness_key: NoteVerifier | None, r: BundleCheck
) -> None:
    """Each step in order (the module doc); a failed one ends the check."""
    fmt = bundle.get("format")
    expected = BUNDLE_FIELDS.get(fmt) if isinstance(fmt, str) else None
    if expected is None:
        raise BadBundleError(_format_of(bundle))
    if set(bundle) != expected:
        odd = sorted(set(bundle) ^ expected)
        raise BadBundleError(f"fields missing or unknown: {', '.join(odd)}")
    r.cycle = field_of(bundle, "cycle", int)
    r.t_ns = field_of(bundle, "t_ns", int)
    seal_bytes = unb64(bundle.get("seal"), "seal")
    read = DataReader(deflated=bundle["format"] not in ("trace-proof/1", "trace-proof/2"))
    if not _check_digests(bundle, seal_bytes, r, read):
        return
    included = _check_inclusion(bundle, seal_bytes, r)
    if included is None:
        return
    root, note = included
    opened = _check_note(bundle, note=note, key=key, witness_key=witness_key, root=root, r=r)
    if opened is not None and witness_key is not None:
        _check_cosignature(opened, witness_key, r)


def _check_digests(
    bundle: Mapping[str, object], seal_bytes: bytes, r: BundleCheck, read: DataReader
) -> bool:
    """The messages (and the readings a 1.3 seal covers) against the seal's digests."""
    try:
        seal = orjson.loads(seal_bytes)
    except orjson.JSONDecodeError as err:
        raise BadBundleError("the seal is not JSON") from err
    digests = seal.get("digests") if isinstance(seal, dict) else None
    if not isinstance(digests, dict):
        raise BadBundleError("the seal has no digests")
    if seal.get("cycle") != r.cycle or seal.get("t_ns") != r.t_ns:
        r.steps.append(("digests", False, "the seal is of another cycle or time"))
        return False
    given: dict[str, bytes] = {}
    for m in field_of(bundle, "messages", list):
        if not isinstance(m, dict) or set(m) != {"topic", "data"} or type(m["topic"]) is not str:
            raise BadBundleError("a message has no topic")
        if m["topic"] in given:
            raise BadBundleError(f"two messages on {m['topic']}")
        given[m["topic"]] = read(m.get("data"), f"message {m['topic']}")
    wrong = sorted(t for t, d in given.items() if digests.get(t) != hashlib.sha256(d).hexdigest())
    absent = sorted(set(digests) - set(given))
    if wrong or absent:
        problems = [f"digest differs: {', '.join(wrong)}"] if wrong else []
        problems += [f"sealed but absent: {', '.join(absent)}"] if absent else []
        r.steps.append(("digests", False, "; ".join(problems)))
        return False
    r.steps.append(("digests", True, f"{len(given)} message(s) match the seal"))
    if "sensors" in bundle and not check_readings(bundle, seal, r.steps, read):
        return False
    return "recorded" not in bundle or check_recorded(bundle, given, r.steps, read)


def _check_inclusion(
    bundle: Mapping[str, object], seal: bytes, r: BundleCheck
) -> tuple[bytes, str] | None:
    """The seal's leaf in the tree: the root it proves to and the checkpoint note, or None
    when it does not."""
    r.leaf_index = field_of(bundle, "leaf_index", int)
    r.tree_size = field_of(bundle, "tree_size", int)
    root_hex = field_of(bundle, "root", str)
    if len(root_hex) != 64 or not set(root_hex) <= set("0123456789abcdef"):
        raise BadBundleError("the root is not 64 lowercase hex digits")
    root = bytes.fromhex(root_hex)
    proof, note = _inclusion_of(bundle, r.leaf_index)
    if not verify_inclusion(r.leaf_index, r.tree_size, leaf_hash(seal), proof, root):
        tree = f"leaf {r.leaf_index} of the tree of {r.tree_size} at that root"
        r.steps.append(("inclusion", False, f"the seal is not {tree}"))
        return None
    r.steps.append(
        ("inclusion", True, f"leaf {r.leaf_index} of {r.tree_size}, {len(proof)} hash(es)")
    )
    return root, note


def _inclusion_of(bundle: Mapping[str, object], leaf_index: int) -> tuple[list[bytes], str]:
    """The inclusion proof and checkpoint note: a ``/5`` bundle's tlog-proof (of the leaf
    the bundle names, with no extra data: nothing would check it), earlier ones' fields."""
    if bundle["format"] != BUNDLE_FORMAT:
        hashes = [unb64(h, "an inclusion hash") for h in field_of(bundle, "inclusion", list)]
        return hashes, _ends_a_line(field_of(bundle, "note", str), "the note")
    try:
        text = _ends_a_line(field_of(bundle, "tlog_proof", str), "the tlog-proof")
        proof = parse_tlog_proof(text)
    except NoteError as err:
        raise BadBundleError(f"the tlog-proof: {err}") from err
    if proof.extra is not None:
        raise BadBundleError("the tlog-proof carries extra data, which nothing checks")
    if proof.index != leaf_index:
        raise BadBundleError("the tlog-proof is of another leaf than leaf_index")
    return list(proof.hashes), proof.note


def _ends_a_line(text: str, what: str) -> str:
    """``text``, which ends as a checkpoint note does, with a newline: the note's parser
    would only say that its signature block is empty, not what is missing."""
    if not text.endswith("\n"):
        raise BadBundleError(
            f"{what} does not end with a newline (a checkpoint note's last line ends with one)"
        )
    return text


def _check_note(
    bundle: Mapping[str, object],
    *,
    note: str,
    key: PublicKey,
    witness_key: NoteVerifier | None,
    root: bytes,
    r: BundleCheck,
) -> OpenedNote | None:
    """The checkpoint note: of the proof's tree, signed by the robot's key under its origin,
    and ``cosigned`` saying what it carries. The opened note, or None when it fails."""
    split = note.rfind("\n\n")
    for line in note[split + 2 :].splitlines() if split >= 0 else ():
        unb64(line.rpartition(" ")[2], "a note signature")  # canonical: one spelling only
    try:
        body = parse_checkpoint(note[: split + 1] if split >= 0 else note)
    except NoteError as err:
        r.steps.append(("note", False, f"not a checkpoint note: {err}"))
        return None
    r.origin = body.origin
    if (body.size, body.root) != (r.tree_size, root):
        r.steps.append(("note", False, "the note states another tree than the proof's"))
        return None
    followed = followed_key(bundle, key, body.origin, r.steps)  # after a key rotation
    if followed is None:
        return None
    verifiers = [NoteVerifier.of(body.origin, followed.raw)]
    if witness_key is not None:
        verifiers.append(witness_key)
    try:
        opened = open_note(note, verifiers)
    except NoteError as err:
        r.steps.append(("note", False, f"the note does not verify: {err}"))
        return None
    if opened.verified_by(verifiers[0]) is None:
        r.steps.append(("note", False, f"not signed by the robot's key under {body.origin}"))
        return None
    r.steps.append(("note", True, f"signed by the robot's key under {body.origin}"))
    cosigned = field_of(bundle, "cosigned", bool)
    if cosigned != (len(opened.verified) + len(opened.unverified) > 1):
        r.steps.append(("note", False, "'cosigned' does not say what the note carries"))
        return None
    return opened


def _check_cosignature(opened: OpenedNote, witness_key: NoteVerifier, r: BundleCheck) -> None:
    """The witness's cosignature on the note, and the time it states."""
    if witness_key.sig_type != COSIGNATURE:
        raise BadBundleError("the witness key is not a cosignature key")
    sig = opened.verified_by(witness_key)
    if sig is None or sig.timestamp is None:
        r.steps.append(("cosignature", False, f"no cosignature by {witness_key.name}"))
        return
    r.witness = witness_key.name
    r.witnessed_at = iso_utc(sig.timestamp * 1_000_000_000)
    r.steps.append(
        ("cosignature", True, f"by {witness_key.name}: logged no later than {r.witnessed_at}")
    )
