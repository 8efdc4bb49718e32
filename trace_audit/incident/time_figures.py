"""The report's figures over the window: each factor's value, and the execution's deviation,
over the bands of the command in force."""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_audit.causal.lenient import as_float
from trace_audit.incident.data import ReportData
from trace_audit.incident.drawing import (
    BROKEN,
    MARKED,
    MAX_FACTORS,
    as_seconds,
    command_bands,
    command_colour,
    command_legend,
    figure_style,
    new_figure,
    time_axis_label,
    to_svg,
    wrap_label,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["execution_figure", "factor_line", "factors_figure"]


# --- factors over time --------------------------------------------------------------------


def factors_figure(data: ReportData) -> str:
    """Each factor of the decision over the window, its thresholds, the commands as bands."""
    names = list(data.factor_units)
    numeric = [n for n in names if any(n in s.factors for s in data.samples)][:MAX_FACTORS]
    with figure_style():
        rows = max(1, len(numeric))
        fig = new_figure(7.5, 1.2 + 1.7 * rows)
        axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
        for ax, name in zip(axes, numeric, strict=False):
            _factor_axis(ax, data, name)
        if not numeric:
            axes[0].text(
                0.5, 0.5, "no numeric factor logged", ha="center", transform=axes[0].transAxes
            )
            command_bands(axes[0], data)
        axes[-1].set_xlabel(time_axis_label(data))
        command_legend(fig, data)
        return to_svg(fig, "factors", "The decision's factors over the window")


def factor_line(data: ReportData, name: str) -> tuple[list[float], list[float]]:
    """The points of factor ``name`` over the window, NaN where the line must break: a
    cycle whose action does not name the factor, and wherever the factor is read from
    another entity (``ped_1.distance`` then ``ped_2.distance``) or the scenario changes,
    so that two people, or two situations, are never joined as if one approached."""
    xs: list[float] = []
    ys: list[float] = []
    before: tuple[str | None, str | None] | None = None
    for s in data.samples:
        x = as_seconds(data, s.t_ns)
        value = s.factors.get(name)
        whose = (s.factor_nodes.get(name), s.scenario)
        if value is not None and before is not None and whose != before:
            xs.append(x)
            ys.append(float("nan"))
        xs.append(x)
        ys.append(float("nan") if value is None else value)
        before = whose if value is not None else None
    return xs, ys


def _factor_axis(ax: Axes, data: ReportData, name: str) -> None:
    unit = data.factor_units.get(name)
    xs, ys = factor_line(data, name)
    command_bands(ax, data)
    ax.plot(xs, ys, ".", ms=2.5, color="#333333")
    ax.plot(xs, ys, "-", lw=0.8, color="#333333", alpha=0.5)
    for cf in data.decision.counterfactuals:
        threshold = as_float(cf.threshold)
        if cf.name != name or threshold is None:
            continue
        ax.axhline(threshold, color=command_colour(cf.would_select), ls="--", lw=1)
        ax.annotate(
            cf.text,
            (1.0, threshold),
            xycoords=("axes fraction", "data"),
            xytext=(-4, 3),
            textcoords="offset points",
            ha="right",
            va="bottom",
            fontsize=8,
            color=command_colour(cf.would_select),
            bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1},
        )
    now = next((f for f in data.decision.factors if f.label == name), None)
    value = as_float(now.value) if now is not None else None
    if now is not None and value is not None:
        ax.plot([as_seconds(data, data.explanation.t_ns)], [value], "o", color=MARKED, ms=5)
        ax.annotate(
            now.shown,
            (as_seconds(data, data.explanation.t_ns), value),
            xytext=(6, 6),
            textcoords="offset points",
            fontsize=8,
            fontweight="bold",
            va="bottom",
            bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1},
        )
    ax.set_ylabel(f"{name} ({unit})" if unit else name)
    ax.set_xlim(as_seconds(data, data.start_ns), as_seconds(data, data.end_ns))


# --- execution ---------------------------------------------------------------------------


def execution_figure(data: ReportData) -> str:
    """Intended vs actual per execution channel, and the deviation with failed checks."""
    channels = list(dict.fromkeys(c for s in data.samples for c in s.channels))
    with figure_style():
        rows = len(channels) + 1
        fig = new_figure(7.5, 1.2 + 1.45 * rows)
        axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
        for ax, channel in zip(axes, channels, strict=False):
            _channel_axis(ax, data, channel)
        _deviation_axis(axes[-1], data)
        axes[-1].set_xlabel(time_axis_label(data))
        from matplotlib.lines import Line2D

        lines = [
            Line2D([], [], color="#1f4e79", ls="--", lw=1.2, label="intended"),
            Line2D([], [], color="#333333", lw=1.0, label="actual"),
        ]
        if any(s.failed_checks for s in data.samples):
            lines.append(Line2D([], [], color=BROKEN, marker="x", ls="none", label="check failed"))
        command_legend(fig, data, lines)
        return to_svg(fig, "execution", "Intended and actual motion over the window")


def _channel_axis(ax: Axes, data: ReportData, channel: str) -> None:
    command_bands(ax, data)
    xs = [as_seconds(data, s.t_ns) for s in data.samples if channel in s.channels]
    pairs = [s.channels[channel] for s in data.samples if channel in s.channels]
    ax.plot(xs, [_nan(p[0]) for p in pairs], "--", lw=1.2, color="#1f4e79")
    ax.plot(xs, [_nan(p[1]) for p in pairs], "-", lw=1.0, color="#333333")
    ax.set_ylabel(wrap_label(channel, 16, 2))
    ax.set_xlim(as_seconds(data, data.start_ns), as_seconds(data, data.end_ns))


def _deviation_axis(ax: Axes, data: ReportData) -> None:
    command_bands(ax, data)
    xs = [as_seconds(data, s.t_ns) for s in data.samples]
    ax.plot(xs, [_nan(s.deviation) for s in data.samples], "-", lw=1.0, color="#333333")
    failed = [s for s in data.samples if s.failed_checks]
    if failed:
        ax.plot(
            [as_seconds(data, s.t_ns) for s in failed],
            [_nan(s.deviation) for s in failed],
            "x",
            ms=4,
            color=BROKEN,
        )
    ax.set_ylabel("deviation")
    ax.set_xlim(as_seconds(data, data.start_ns), as_seconds(data, data.end_ns))


def _nan(value: float | None) -> float:
    return float("nan") if value is None else value
