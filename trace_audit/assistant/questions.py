"""Each tool's question, asked of the library exactly as its ``trace-audit`` command asks it
with ``--json``: the same functions, the same arguments, the same JSON. Runs in the
server's worker process (``worker``), which a call's timeout may kill.

Every question takes plain arguments (paths already confined to the roots) and returns
plain JSON data; ``ask`` wraps one so that what crosses back to the server is plain data
too: the answer cut to its bound (``bound``), or the error's one line.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from trace_audit.assistant.bound import bound
from trace_audit.jsonout import to_jsonable
from trace_runtime.errors import InputError, TraceError, UsageError

__all__ = ["QUESTIONS", "ask"]


def _robots(args: dict[str, Any]) -> list[str]:
    return list(args.get("robot") or ())


def _holdings(args: dict[str, Any]) -> Any:
    """``info --quick --json`` of each root (what a root holds, without scanning seals)."""
    from trace_audit.cli.info import info_each_robot
    from trace_audit.cli.output import per_robot_value

    held: list[dict[str, Any]] = []
    for root in args["roots"]:
        try:
            path, answers = info_each_robot(Path(root), False, ())
        except TraceError as err:  # a root with no log yet, or one unreadable: say which
            held.append({"root": root, "info": None, "error": str(err)})
            continue
        held.append({"root": root, "info": to_jsonable(per_robot_value(path, answers))})
    return held


def _why(args: dict[str, Any]) -> Any:
    from trace_audit.cli.output import per_robot_value
    from trace_audit.cli.why import why_each_robot

    path, answers = why_each_robot(Path(args["log"]), args["action"], args.get("t"), _robots(args))
    return to_jsonable(per_robot_value(path, answers))


def _timeline(args: dict[str, Any]) -> Any:
    from trace_audit.cli.output import per_robot_value
    from trace_audit.cli.timeline import timeline_each_robot

    path, answers = timeline_each_robot(
        Path(args["log"]),
        args.get("start"),
        args.get("end"),
        bool(args.get("every")),
        _robots(args),
    )
    return to_jsonable(per_robot_value(path, answers))


def _explain(args: dict[str, Any]) -> Any:
    from trace_audit.explanation import explain

    return to_jsonable(
        explain(Path(args["log"]), t=args.get("t"), cycle=args.get("cycle"), robots=_robots(args))
    )


def _metrics(args: dict[str, Any]) -> Any:
    """``metrics LOG --json`` with the CLI's defaults (``--failures`` lists up to 10,000)."""
    from trace_audit.cli.metrics import window_ns
    from trace_audit.cli.metrics_doc import metrics_json
    from trace_audit.metrics import MetricsConfig, compute_metrics

    logs, robots = [Path(args["log"])], _robots(args)
    config = MetricsConfig(
        by=args.get("by"),
        start_ns=window_ns(args.get("start"), logs, robots, None),
        end_ns=window_ns(args.get("end"), logs, robots, None),
        max_listed=10_000 if args.get("failures") else 0,
    )
    report = compute_metrics(logs, config, robots=robots or None)
    return metrics_json(report, bool(args.get("failures")))


def _verify(args: dict[str, Any]) -> Any:
    """``verify --json``; with the server's keys ``verify --key K [--witness local
    --witness-key V]`` (the witness: the log root's own store, nothing fetched)."""
    from trace_audit.verify import verify_log, verify_witnessed
    from trace_runtime.tlog.keys import load_public_key

    log, robots = Path(args["log"]), _robots(args)
    key = load_public_key(Path(args["key"])) if args.get("key") else None
    witness_key = args.get("witness_key")
    if witness_key:
        report = verify_witnessed(log, "local", key=key, witness_key=witness_key, robots=robots)
        return to_jsonable(report)
    return to_jsonable(verify_log(log, key=key, robots=robots))


def _check(args: dict[str, Any]) -> Any:
    from trace_audit.cli.check import check_json
    from trace_audit.rules import check_rules, read_rules

    rules = read_rules(Path(args["rules"]))  # before the log, as the CLI: a bad rule reads none
    result = check_rules(
        Path(args["log"]),
        rules,
        robots=tuple(_robots(args)),
        start=args.get("start"),
        end=args.get("end"),
        rules_file=str(args["rules"]),
        engine="auto",
    )
    return check_json(result)


def _find(args: dict[str, Any]) -> Any:
    from trace_audit.fleet.find import find_decisions

    return find_decisions(
        Path(args["index"]),
        action=args.get("action"),
        near=args.get("near"),
        within_m=args.get("within"),
        where=args.get("where"),
        robots=_robots(args),
        limit=int(args.get("limit") or 1000),
    ).records()


def _query(args: dict[str, Any]) -> Any:
    from trace_audit.fleet.query import run_query

    return run_query(Path(args["index"]), args["sql"], limit=args.get("limit")).records()


def _prove(args: dict[str, Any]) -> Any:
    from trace_audit.proof import make_bundle

    robot = args.get("robot")
    return dict(make_bundle(Path(args["log"]), int(args["cycle"]), robot=robot))


QUESTIONS: dict[str, Callable[[dict[str, Any]], Any]] = {
    "robots": _holdings,
    "why": _why,
    "explain": _explain,
    "timeline": _timeline,
    "metrics": _metrics,
    "verify": _verify,
    "check": _check,
    "find": _find,
    "query": _query,
    "prove": _prove,
}
"""Each tool's question, by the tool's (and the command's) name."""


def ask(name: str, args: dict[str, Any], limit: int) -> tuple[str, Any, Any]:
    """``("ok", data, cuts)`` with the data cut to ``limit`` bytes of JSON, or
    ``("usage" | "input" | "error", message, None)`` for the library's error: its one line,
    as plain text (an exception object may not survive the trip back to the server)."""
    try:
        data = QUESTIONS[name](args)
    except UsageError as err:
        return "usage", str(err), None
    except InputError as err:
        return "input", str(err), None
    except TraceError as err:
        return "error", str(err), None
    data, cuts = bound(data, limit, name)
    return "ok", data, cuts
