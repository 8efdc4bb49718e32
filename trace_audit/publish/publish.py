"""``trace-audit publish``: each robot's tree as C2SP tlog-tiles, for any tlog client.

Under ``OUT/<robot id>/``: ``checkpoint`` (the note of the robot's newest signed profile
1.2 checkpoint, byte for byte as the log carries it: publish signs nothing), hash tiles
``tile/<L>/<N>[.p/<W>]`` and entry bundles ``tile/entries/<N>[.p/<W>]`` whose entries are
the robot's seals as stored (the leaves of its tree, ``chain_tree.iter_seal_data``).

The tree is published up to the newest signed checkpoint's size, never beyond: seals no
checkpoint vouches for yet wait for the next run. Every signed checkpoint's root is checked
against the seals as they stream by; the partial hash tiles of each one's size are written
(the spec: a log serves the partial tiles of every size it made a checkpoint of, so a note an
auditor already holds, from a proof bundle or a witness, can be checked against the tiles);
the partial entry bundle only for the newest. A second run writes only what is new: full
tiles are immutable, compared when present, never rewritten; nothing is ever deleted but
this run's own uncommitted files (and what a killed run left beside a name, ``files``). An
unsigned robot is refused (exit 2): a public tlog's checkpoint carries the log's signature,
and tiles nobody signed prove nothing. Given the robot's public key(s), the note served
must verify under one of them, or under a key the robot's chain announced from it (key
rotation, ``key_chain``); the note served is the root's witness-cosigned one when the
witness store holds it (``served``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from trace_audit.key_chain import announcing_checkpoints
from trace_audit.publish.files import PublishedFolder, TileConflictError, make_top
from trace_audit.publish.served import served_note, signature_problem
from trace_audit.publish.tiler import TileBuilder
from trace_audit.witness.push import robot_checkpoints
from trace_runtime.boundary import folder_lock, read_side_file
from trace_runtime.errors import InputError, NoteError, UsageError
from trace_runtime.reading.chain_tree import iter_seal_data
from trace_runtime.reading.logset import Log, open_log
from trace_runtime.records import Checkpoint
from trace_runtime.tlog.checkpoints import check_note
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.signed_note import MAX_NOTE_BYTES, parse_checkpoint
from trace_runtime.tlog.signed_note import Checkpoint as NoteBody

__all__ = ["Progress", "PublishReport", "RobotPublish", "publish_root"]

Progress = Callable[[str, int, int], None]
"""``progress(robot, seals published, seals to publish)``, called at each checkpoint size."""


@dataclass(slots=True)
class RobotPublish:
    """What one robot's published folder became."""

    robot_id: str
    folder: str = ""
    origin: str = ""
    tree_size: int | None = None
    """The published checkpoint's tree size (None: nothing published this run)."""
    root: str = ""
    previous_size: int | None = None
    """The size the folder's checkpoint stated before this run (None: a new folder)."""
    checkpoints: int = 0
    """Signed checkpoints of the log whose trees the tiles hold (partial tiles included)."""
    written: int = 0
    kept: int = 0
    """Tiles and bundles already published, compared byte for byte, left as they were."""
    removed: int = 0
    """Files a killed earlier run left beside their names, removed."""
    cosigned_by: list[str] = field(default_factory=list)
    """The witnesses whose cosignature lines the served ``checkpoint`` carries (from the
    root's witness store; not verified by publish)."""
    announced_keys: list[str] = field(default_factory=list)
    """The verifier keys the robot's chain announced (key rotation) from the key given, that
    the note served was checked with the last of (as ``verify``'s ``announced_keys``)."""
    problems: list[str] = field(default_factory=list)


@dataclass(slots=True)
class PublishReport:
    root: str
    out: str
    key_ids: list[str] = field(default_factory=list)
    """The keys each served note was checked with (empty: signatures not checked here)."""
    robots: list[RobotPublish] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(not r.problems for r in self.robots)


class _MismatchError(InputError):
    """The seals do not make the tree a signed statement says (turned into a problem of the
    robot, exit 1, by ``_publish_robot``)."""


def publish_root(
    root: str | Path,
    out: str | Path,
    *,
    robots: Sequence[str] = (),
    keys: Sequence[PublicKey] = (),
    progress: Progress | None = None,
) -> PublishReport:
    """Publish every robot's (or ``robots``') tree under ``out`` (see the module doc); with
    ``keys``, a robot whose newest note none of them signed publishes nothing."""
    log = open_log(root)
    chosen = list(robots) or log.robots
    unknown = [r for r in chosen if r not in log.robots]
    if unknown:
        raise UsageError(f"no robot {', '.join(unknown)} in {root} (it holds {_names(log)})")
    signed = {robot: robot_checkpoints(log, robot) for robot in chosen}
    unsigned = [robot for robot, checkpoints in signed.items() if not checkpoints]
    if unsigned:
        raise UsageError(
            f"robot {', '.join(unsigned)} has no signed checkpoint note, so nothing would "
            "vouch for its tiles: log with a checkpoint key (LoggerConfig.checkpoint_key), "
            "or name the other robots with --robot"
        )
    out = Path(out)
    report = PublishReport(str(root), str(out), [key.key_id for key in keys])
    make_top(out)
    with folder_lock(
        out / ".publish.lock", held=f"another publish is writing to {out}", remove=True
    ):
        for robot in chosen:
            checkpoints = signed[robot]
            result = _checked(robot, checkpoints, keys, log)
            if not result.problems:
                _publish_robot(log, result, checkpoints, out, progress)
            report.robots.append(result)
    return report


def _names(log: Log) -> str:
    return ", ".join(log.robots) or "no robot"


def _checked(
    robot: str, checkpoints: list[Checkpoint], keys: Sequence[PublicKey], log: Log
) -> RobotPublish:
    """The robot's result, with a problem when nothing may be published for it: an id that
    cannot name a folder, a note that does not state its checkpoint's tree, or a newest note
    signed neither by one of ``keys`` nor by a key the chain announced from one."""
    result = RobotPublish(robot, origin=checkpoints[-1].origin or "")
    if robot in ("", ".", "..") or any(c in robot for c in "/\\\x00") or robot.startswith("."):
        result.problems.append(f"robot id {robot!r} cannot name a folder: not published")
        return result
    for c in checkpoints:
        if check_note(c, None) != "unchecked":
            result.problems.append(f"the note of checkpoint {c.tree_size} does not state its tree")
            return result
    announcing = announcing_checkpoints(log, robot) if keys else []
    problem, result.announced_keys = signature_problem(checkpoints[-1], keys, announcing)
    if problem is not None:
        result.problems.append(f"{problem}: nothing published")
    return result


def _publish_robot(
    log: Log, result: RobotPublish, checkpoints: list[Checkpoint], out: Path,
    progress: Progress | None,
) -> None:  # fmt: skip
    """Publish one checked robot's tree into ``out/<robot>``; problems go into ``result``."""
    robot, newest = result.robot_id, checkpoints[-1]
    folder = out / robot
    result.folder = str(folder)
    make_top(folder)
    previous = _published(folder, result)
    if result.problems:
        return
    published = PublishedFolder(folder)
    try:
        _cut(
            log,
            robot,
            checkpoints=checkpoints,
            previous=previous,
            published=published,
            progress=progress,
        )
    except TileConflictError as err:
        result.problems.append(
            f"{err.path} as published differs from this log's: the log no longer holds the "
            f"history published from it, or the folder was altered; nothing replaced"
        )
    except _MismatchError as err:
        result.problems.append(f"{err}: the checkpoint is not replaced")
    finally:
        published.discard()
        published.sync()
        result.written, result.kept = published.written, published.kept
        result.removed = published.removed
    if result.problems:
        return
    served = served_note(log.root, robot, newest)
    published.replace("checkpoint", served.note.encode())
    result.written, result.kept = published.written, published.kept
    result.removed, result.cosigned_by = published.removed, list(served.witnesses)
    result.tree_size, result.root = newest.tree_size, newest.root or ""
    result.checkpoints = len(checkpoints)


def _published(folder: Path, result: RobotPublish) -> NoteBody | None:
    """The checkpoint the folder already serves, when it is one of this robot's log and no
    larger than what the log can publish now (a problem otherwise)."""
    data = read_side_file(folder / "checkpoint", limit=MAX_NOTE_BYTES)
    if data is None:
        return None
    text = data.decode(errors="replace")
    split = text.rfind("\n\n")
    try:
        body = parse_checkpoint(text[: split + 1] if split >= 0 else text)
    except NoteError as err:
        result.problems.append(f"the published checkpoint is not a checkpoint note ({err})")
        return None
    result.previous_size = body.size
    if body.origin != result.origin:
        result.problems.append(
            f"the folder serves the log {body.origin}, not this robot's {result.origin}"
        )
    return body


def _cut(
    log: Log,
    robot: str,
    *,
    checkpoints: list[Checkpoint],
    previous: NoteBody | None,
    published: PublishedFolder,
    progress: Progress | None,
) -> None:
    """Stream the robot's seals into tiles up to its newest checkpoint's size, committing
    what each matching checkpoint vouches for."""
    roots = {c.tree_size or 0: c.root for c in checkpoints}
    final = max(roots)
    if previous is not None and previous.size > final:
        raise _MismatchError(
            f"the folder serves a tree of {previous.size} seals, beyond the {final} this "
            "log's newest signed checkpoint states (the log lost its newest cycles?)"
        )
    builder = TileBuilder()
    for entry in iter_seal_data(log, robot):
        for tile in builder.append(entry):
            published.stage(tile)
        size = builder.size
        if previous is not None and size == previous.size and builder.root() != previous.root:
            raise _MismatchError(
                f"the published checkpoint of {size} states another root than the seals"
            )
        if size not in roots:
            continue
        if builder.root().hex() != roots[size]:
            raise _MismatchError(
                f"the signed checkpoint of {size} states another root than the seals"
            )
        published.commit()  # a signed root vouches for every tile staged so far
        for tile in builder.partial_tiles():
            published.stage(tile)
        bundle = builder.partial_bundle() if size == final else None
        if bundle is not None:
            published.stage(bundle)
        published.commit()
        if progress is not None:
            progress(robot, size, final)
        if size == final:
            return
    raise _MismatchError(f"the log holds {builder.size} seals, its checkpoint a tree of {final}")
