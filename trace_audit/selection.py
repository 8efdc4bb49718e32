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
- The window (``start``, ``end``) is read by ``log_time.resolve_time`` in the selected log's
  clock, so ``+5`` counts from the selected robots' first record.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from trace_audit.log_time import LogClock, TimeArg, resolve_time
from trace_runtime.cycles import Cycle
from trace_runtime.errors import TimeOutOfRangeError, UsageError
from trace_runtime.logset import Log

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
) -> list[Answer]:
    """``ask`` of each robot's log (``each_robot``), in order of name.

    A robot whose question raises ``skip`` (it has nothing to say: no cycle in the window,
    never takes the action) is left out; when every robot is, the first one's error is
    raised, so a question that no robot can answer fails as it would on one robot."""
    answers: list[Answer] = []
    first_error: Exception | None = None
    for robot in each_robot(log):
        try:
            answers.append(ask(robot))
        except skip as err:
            first_error = first_error or err
    if not answers and first_error is not None:
        raise first_error
    return answers


def robot_at(log: Log, t_ns: int) -> Log:
    """The log of the one robot with a decision in force at ``t_ns``.

    ``log`` itself when it holds one robot; ``TimeOutOfRangeError`` when no robot has a
    decision then; ``SeveralRobotsError`` naming them when more than one has."""
    if len(log.robots) == 1:
        return log
    having: list[Log] = []
    for robot in each_robot(log):
        try:
            robot.cycle_at(t_ns)
        except TimeOutOfRangeError:
            continue
        having.append(robot)
    if not having:
        raise TimeOutOfRangeError(t_ns, log.start_ns, log.end_ns)
    if len(having) > 1:
        when = LogClock.of(log).show(t_ns)
        raise SeveralRobotsError([r.first_robot for r in having], f"a decision in force at {when}")
    return having[0]


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
