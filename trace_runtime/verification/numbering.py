"""Along links that hold, a gap in cycle numbers must be what the seal declares dropped:
declared drops are a note, an undeclared gap or a number that goes back is a finding."""

from __future__ import annotations

from trace_runtime.gaps import CycleRange
from trace_runtime.verification.scan import SealScan
from trace_runtime.verification.sink import SegmentReporter

__all__ = ["Numbering"]


class Numbering:
    """Checks the cycle numbers of one segment's scan against the drops its seals declare."""

    __slots__ = ("entry_cycle", "report", "scan")

    def __init__(self, report: SegmentReporter, scan: SealScan, entry_cycle: int | None) -> None:
        self.report = report
        self.scan = scan
        self.entry_cycle = entry_cycle

    def check(self, positions: range | list[int]) -> None:
        """Linked cycles: a numbering gap must be what the seal declares dropped."""
        scan = self.scan
        for i in positions:
            before = self.entry_cycle if i == 0 else scan.num[i - 1]
            if before is None:
                # The first cycle the log holds (earlier segments retired or lost): nothing
                # to number against, but the drops its seal declares are still drops.
                self.declared(i, None)
                continue
            self.gap(before, scan.t[i - 1] if i > 0 else None, i)

    def declared(self, i: int, before_t: int | None) -> int:
        """Note the drops the seal at position ``i`` declares; return their count."""
        scan = self.scan
        declared, number = scan.dropped[i], scan.num[i]
        if declared:
            self.report.sink.declared += declared
            self.report.note(
                "declared_gap",
                f"{declared} cycle(s) dropped by the logger before cycle {number} "
                "(declared by its seal)",
                CycleRange(number - declared, number - 1, before_t, scan.t[i]),
            )
        return declared

    def gap(self, before: int, before_t: int | None, i: int) -> None:
        """The cycle at position ``i`` against the cycle ``before`` it in the chain."""
        scan = self.scan
        gap = scan.num[i] - before - 1
        declared = self.declared(i, before_t)
        number, t = scan.num[i], scan.t[i]
        if gap > declared:
            scan.bad_positions.add(i)
            self.report.finding(
                "undeclared_gap",
                f"cycles {before + 1}..{number - 1 - declared} are missing although "
                "the chain is intact and the logger declared no drop",
                CycleRange(before + 1, number - 1 - declared, before_t, t),
            )
        elif gap < 0:
            scan.bad_positions.add(i)
            self.report.finding(
                "reordered",
                f"cycle {number} follows cycle {before} in the chain",
                CycleRange(number, before, t, t),
            )
