"""The report's figure of the scene at the decision: the robot and the entities it perceived."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from trace_audit.incident.data import ReportData
from trace_audit.incident.drawing import (
    BROKEN,
    MAX_ENTITIES,
    figure_style,
    new_figure,
    to_svg,
    wrap_label,
)
from trace_audit.incident.window import EntityView

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["scene_figure"]


# --- the scene at t ----------------------------------------------------------------------

_CLASS_MARKERS = {"person": "o", "forklift": "s", "vehicle": "s", "pallet": "D", "corridor": ">"}


def scene_figure(data: ReportData) -> str:
    """Top-down plot of the robot and the entities it perceived at t; entities whose
    evidence failed are drawn hollow and red, those whose evidence is in a recording that
    could not be read hollow and amber (unknown), each entity's logged distance as a line."""
    placed = [e for e in data.entities[:MAX_ENTITIES] if e.x is not None and e.y is not None]
    with figure_style():
        fig = new_figure(7.5, 4.4)
        ax = fig.add_subplot()
        ax.set_aspect("equal", adjustable="box")
        robot = data.robot
        if robot is not None:
            _draw_robot(ax, robot.x, robot.y, robot.heading_rad)
        taken: list[tuple[float, float]] = []
        for number, entity in enumerate(placed):
            x, y = float(entity.x or 0.0), float(entity.y or 0.0)
            state = entity.evidence_state
            colour = _STATE_COLOURS[state]
            if robot is not None and entity.distance and entity.cls != "corridor":
                ax.plot([robot.x, x], [robot.y, y], ":", color=colour, lw=1)
            ax.plot(
                [x],
                [y],
                _CLASS_MARKERS.get(entity.cls, "^"),
                ms=11,
                ls="none",
                mfc=colour if state == "resolved" else "none",
                mec=colour,
                mew=1.6,
                # the SVG group names the entity and its evidence state, so a test (or a
                # reader of the page's source) can hold the scene to the tables below it
                gid=f"entity-{_gid_safe(entity.id)}-{state}" if number < MAX_ENTITIES else None,
            )
            # Entities close together get their labels on alternate sides, each with a
            # leader line, so a label is never read as another entity's.
            near = sum(1 for px, py in taken if abs(x - px) < 1.5 and abs(y - py) < 1.0)
            taken.append((x, y))
            offset = _LABEL_OFFSETS[near % len(_LABEL_OFFSETS)]
            ax.annotate(
                _entity_label(entity),
                (x, y),
                xytext=offset,
                textcoords="offset points",
                fontsize=8,
                color=colour,
                va="center",
                ha="left" if offset[0] > 0 else "right",
                arrowprops={"arrowstyle": "-", "color": colour, "lw": 0.6, "shrinkB": 6},
            )
        frames = sorted({e.frame for e in placed}) or ["map"]
        ax.set_xlabel(f"x (m, {', '.join(frames)} frame)")
        ax.set_ylabel("y (m)")
        ax.grid(True, lw=0.4, alpha=0.5)
        if not placed and robot is None:
            ax.text(0.5, 0.5, "no pose logged", ha="center", transform=ax.transAxes)
        else:
            points = [(float(e.x or 0.0), float(e.y or 0.0)) for e in placed]
            if robot is not None:
                points.append((robot.x, robot.y))
            _frame(ax, points)
        return to_svg(fig, "scene", "The robot and the entities it perceived at the decision")


_ENTITY = "#1f4e79"
_UNKNOWN = "#b7791f"
_STATE_COLOURS = {"resolved": _ENTITY, "broken": BROKEN, "unresolved": _UNKNOWN}
"""Evidence that resolves, that fails (a finding), and in a recording not read (unknown)."""


def _gid_safe(text: str) -> str:
    """An entity id as it may stand in an SVG id: anything but letters, digits, ``_.-``
    replaced by ``_``."""
    return "".join(c if c.isalnum() or c in "_.-" else "_" for c in text)


_MIN_SPAN_M = 4.0
"""The scene shows at least this many metres each way, so a lone entity is not a dot in a
blown-up grid of centimetres."""


def _frame(ax: Axes, points: list[tuple[float, float]]) -> None:
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    cx, cy = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    half = max(max(xs) - min(xs), max(ys) - min(ys), _MIN_SPAN_M) * 0.65
    ax.set_xlim(cx - half * 1.6, cx + half * 1.6)  # the plot is wider than tall
    ax.set_ylim(cy - half, cy + half)


_LABEL_OFFSETS = ((28, 26), (28, -30), (-28, 26), (-28, -30))


def _entity_label(entity: EntityView) -> str:
    conf = f" {entity.confidence:.2f}" if entity.confidence is not None else ""
    lines = [f"{entity.id}: {entity.cls}{conf}"]
    if entity.distance and entity.cls != "corridor":
        lines.append(f"{entity.distance} from the robot")
    sensors = sorted({e.sensor for e in entity.evidence if e.resolved})
    state = entity.evidence_state
    if state == "resolved":
        lines.append("seen by " + ", ".join(sensors))
    elif state == "unresolved":
        lines.append("evidence not checked (recording not read)")
    else:
        lines.append("evidence FAILED")
    return "\n".join(wrap_label(line, 34, 1) for line in lines)


def _draw_robot(ax: Axes, x: float, y: float, heading: float) -> None:
    """The robot as a dark disc with an arrow along its heading."""

    ax.plot([x], [y], "o", ms=14, color="#444444", zorder=3)
    ax.annotate(
        "",
        (x + 0.9 * math.cos(heading), y + 0.9 * math.sin(heading)),
        (x, y),
        arrowprops={"arrowstyle": "-|>", "color": "#444444", "lw": 1.6},
        zorder=3,
    )
    ax.annotate(
        "robot",
        (x, y),
        xytext=(0, -16),
        textcoords="offset points",
        ha="center",
        va="top",
        fontsize=8,
        fontweight="bold",
        color="#444444",
    )
