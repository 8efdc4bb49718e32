"""Which part of a log a question is about: its robots, and a window of its time.

A log root may hold many robots (``Log.robots``). Every investigating command and the
library select the same way:

- ``Selection.robots`` (``--robot``, repeatable) cuts the log to those robots
  (``Log.of_robots``); none means every robot.
- A question over time (``why``, ``timeline``, ``info``, ``metrics``) is answered per robot:
  ``each_robot`` gives one log per selected robot, in order, ``per_robot`` asks the question
  of each, and each answer names its robot (``PerRobot`` holds them for a printer).
- A question about one moment (``explain``, ``report``, ``export``) needs one decision:
  ``robot_at`` keeps the one robot with a decision in force at that time, or refuses
  (``SeveralRobotsError``) naming the robots that have one. Never a silent pick.
- A time is read in each robot's own clock (``log_time.resolve_time``): ``+5`` counts from
  that robot's first record, an ISO time is a moment only to robots on a wall clock (the
  others have no decision then), plain seconds are the same number for every robot.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from trace_audit.log_time import (
    LogClock,
    NotWallClockError,
    TimeArg,
    TimePoint,
    exact_seconds,
    resolve_time,
)
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import TimeOutOfRangeError, UsageError
from trace_runtime.reading.logset import Log

__all__ = [
    "PerRobot",
    "Selection",
    "SeveralRobotsError",
    "each_robot",
    "per_robot",
    "robot_at",
    "robot_with_cycle",
]

Answer = TypeVar("Answer")

_CycleFinder = Callable[[Log, int], Cycle]
"""Looks a cycle number up in one robot's log, raising ``UsageError`` when it is not there."""


class SeveralRobotsError(UsageError):
    """A question about one decision reached decisions of several robots (exit 2)."""

    def __init__(self, robots: Sequence[str], what: str) -> None:
        self.robots = tuple(robots)
        super().__init__(
            f"{len(self.robots)} robots have {what}: {', '.join(self.robots)}; "
            "choose one with --robot"
        )


@dataclass(frozen=True, slots=True)
class Selection:
    """Robots and a window of time: what a question is asked of."""

    robots: tuple[str, ...] = ()
    """Only these robots (empty: all of the log's)."""
    start: TimeArg = None
    end: TimeArg = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "robots", tuple(dict.fromkeys(self.robots)))  # once each

    def of(self, log: Log) -> Log:
        """``log`` cut to the selected robots (``UsageError`` naming the log's robots when one
        is not there)."""
        return log.of_robots(self.robots) if self.robots else log

    def window(self, log: Log) -> tuple[int | None, int | None]:
        """The window as ``t_ns`` in ``log``'s clock (None: open at that end)."""
        return resolve_time(self.start, log), resolve_time(self.end, log)


def each_robot(log: Log) -> list[Log]:
    """One log per robot of ``log``, robots in order of name; ``[log]`` for one robot."""
    robots = log.robots
    return [log] if len(robots) == 1 else [log.of_robots([r]) for r in robots]


@dataclass(frozen=True, slots=True)
class PerRobot(Generic[Answer]):
    """One question's answers over a log of several robots, one per robot, in order of name
    (as JSON: ``{"path": ..., "robots": [answer, ...]}``, each answer naming its robot)."""

    path: str
    robots: tuple[Answer, ...]


def per_robot(
    log: Log,
    ask: Callable[[Log], Answer],
    *,
    skip: type[Exception] | tuple[type[Exception], ...] = (),
    skipped: list[tuple[str, Exception]] | None = None,
) -> list[Answer]:
    """``ask`` of each robot's log (``each_robot``), in order of name.

    A robot whose question raises ``skip`` (it has nothing to say: no cycle in the window,
    never takes the action) is left out, and added to ``skipped`` (robot, error) when given;
    when every robot is, the first one's error is raised (on several robots, as a
    ``UsageError`` that says so and quotes the first), so a question that no robot can
    answer fails as it would on one robot."""
    answers: list[Answer] = []
    errors: list[tuple[str, Exception]] = []
    robots = each_robot(log)
    for robot in robots:
        try:
            answers.append(ask(robot))
        except skip as err:
            errors.append((robot.first_robot, err))
            if skipped is not None:
                skipped.append((robot.first_robot, err))
    if not answers and errors:
        if len(robots) == 1:
            raise errors[0][1]
        first, why = errors[0]
        raise UsageError(f"none of the {len(robots)} robots answers ({first}: {why})") from why
    return answers


def robot_at(log: Log, t: TimeArg) -> tuple[Log, int]:
    """The log of the one robot with a decision in force at ``t``, and ``t`` as its ``t_ns``.

    ``t`` is read in each robot's own clock (``log_time.resolve_time``): ``+5`` is 5 s after
    that robot's first record, and an ISO time names a moment only to robots on a wall
    clock. ``log`` itself when it holds one robot. Otherwise ``SeveralRobotsError`` names
    the robots with a decision then, and a time no robot has a decision at is a
    ``UsageError`` giving each robot's range."""
    if len(log.robots) == 1:
        t_ns = resolve_time(t, log)
        assert t_ns is not None
        return log, t_ns
    having: list[tuple[Log, int]] = []
    missed: list[Log] = []
    for robot in each_robot(log):
        try:
            t_ns = resolve_time(t, robot)
        except NotWallClockError:
            continue
        assert t_ns is not None
        try:
            robot.cycle_at(t_ns)
        except TimeOutOfRangeError:
            missed.append(robot)
            continue
        having.append((robot, t_ns))
    if len(having) == 1:
        return having[0]
    asked = _asked(t, log)
    if having:
        raise SeveralRobotsError([r.first_robot for r, _ in having], f"a decision at {asked}")
    if not missed:
        raise NotWallClockError(
            f"{asked} is a time of day, and no robot of this log keeps a wall clock: give seconds"
        )
    ranges = "; ".join(f"{r.first_robot} {_range(r)}" for r in missed)
    raise UsageError(f"no robot has a decision at {asked}: {ranges}")


def _asked(t: TimeArg, log: Log) -> str:
    """A time as the user gave it, for a message about several robots."""
    if isinstance(t, str):
        return t.strip()
    if isinstance(t, TimePoint):
        return f"+{exact_seconds(t.ns)} s" if t.relative else exact_seconds(t.ns)
    return LogClock.of(log).show(t) if isinstance(t, int) else "?"


def _range(log: Log) -> str:
    clock = LogClock.of(log)

    def shown(t_ns: int) -> str:
        return clock.iso(t_ns, digits=3) if clock.wall else f"{t_ns / 1e9:.3f} s"

    return f"{shown(log.start_ns)} .. {shown(log.end_ns)}"


def robot_with_cycle(log: Log, number: int, find: _CycleFinder) -> tuple[Log, Cycle]:
    """The log of the one robot whose chain holds cycle ``number``, and that cycle.

    ``find`` is ``explain.find_cycle`` (passed in: this floor stands below it)."""
    if len(log.robots) == 1:
        return log, find(log, number)
    found: list[tuple[Log, Cycle]] = []
    for robot in each_robot(log):
        try:
            found.append((robot, find(robot, number)))
        except UsageError:
            continue
    if len(found) == 1:
        return found[0]
    if not found:
        raise UsageError(f"cycle {number} is in none of this log's robots ({_names(log)})")
    raise SeveralRobotsError([r.first_robot for r, _ in found], f"a cycle numbered {number}")


def _names(log: Log) -> str:
    return ", ".join(log.robots)
