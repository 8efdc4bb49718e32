"""Explains broken links inside a segment: which cycles were removed, added or moved.

``pred[i]`` is the position of the cycle whose seal digest cycle ``i``'s seal names. In an
intact segment it is ``i - 1`` everywhere. Reading the exceptions: cycles a link skips over
and that no later cycle continues from were inserted; of the rest, those outside the longest
run in increasing cycle number (seals bind the numbers) were moved; a predecessor nowhere in
the log is a removed cycle (when numbers are missing) or an altered seal (when they are not).
"""

from __future__ import annotations

import bisect

from trace_runtime.gaps import CycleRange
from trace_runtime.verification.numbering import Numbering
from trace_runtime.verification.report import describe_numbers
from trace_runtime.verification.scan import SealScan, digest_prefix
from trace_runtime.verification.sink import SegmentReporter

__all__ = ["ChainOrder"]


class ChainOrder:
    """Classifies the broken links of one segment's scan into findings."""

    ENTRY = -1
    NONE = -2

    def __init__(
        self,
        report: SegmentReporter,
        scan: SealScan,
        numbering: Numbering,
        *,
        entry: str | None,
        first_cycle: int,
    ) -> None:
        self.report = report
        self.scan = scan
        self.numbering = numbering
        self.entry_cycle = numbering.entry_cycle
        self.first_cycle = first_cycle
        """The first cycle the segment's metadata names."""
        n = len(scan.num)
        self.n = n
        where: dict[int, int] = {}
        self.duplicates: list[tuple[int, int]] = []
        for i in range(n):
            if scan.dig[i] in where:
                self.duplicates.append((where[scan.dig[i]], i))
            else:
                where[scan.dig[i]] = i
        entry_prefix = digest_prefix(entry) if entry is not None else None
        self.pred: list[int] = []
        for i in range(n):
            if i > 0 and scan.link_ok[i] == 1:
                self.pred.append(i - 1)
            elif (i == 0 and scan.link_ok[i]) or (
                entry_prefix is not None and scan.prev[i] == entry_prefix
            ):
                self.pred.append(self.ENTRY)
            else:
                self.pred.append(where.get(scan.prev[i], self.NONE))
        self.succ: list[list[int]] = [[] for _ in range(n)]
        for i, p in enumerate(self.pred):
            if p >= 0:
                self.succ[p].append(i)

    def _descendants(self, start: int) -> set[int]:
        """Positions reached by following links forward from ``start`` (itself included)."""
        seen: set[int] = set()
        stack = [start]
        while stack:
            node = stack.pop()
            if node not in seen:
                seen.add(node)
                stack.extend(self.succ[node])
        return seen

    def _ancestors(self, start: int) -> set[int]:
        """Positions reached by following links back from ``start``."""
        seen: set[int] = set()
        node = self.pred[start]
        while node >= 0 and node not in seen:
            seen.add(node)
            node = self.pred[node]
        return seen

    def classify(self) -> None:
        """Report every broken link: copies, inserted runs, moved runs, removed or altered
        seals, then the numbering along the links that hold."""
        inserted = self._duplicates()
        self._skipped_over(inserted)
        # Order: seals bind cycle numbers, so the longest run of the remaining cycles in
        # increasing number stayed in place and every other one was moved.
        scan = self.scan
        rest = [i for i in range(self.n) if i not in inserted]
        kept = _longest_increasing([scan.num[i] for i in rest])
        moved = {rest[j] for j in range(len(rest)) if j not in kept}
        self._report_moved(rest, moved)
        scan.bad_positions.update(inserted | moved)
        explained = inserted | moved
        self._unlinked(explained)
        self._numbering(explained)

    def _duplicates(self) -> set[int]:
        """A second copy of an existing cycle: the copy is the one the chain does not use."""
        scan, pred = self.scan, self.pred
        inserted: set[int] = set()
        for original, copy in self.duplicates:
            extra = copy if pred[copy] != copy - 1 or not self.succ[copy] else original
            inserted.add(extra)
            self.report.finding(
                "inserted",
                f"cycle {scan.num[extra]} appears twice; the copy is not part of the chain",
                CycleRange(scan.num[extra], scan.num[extra], scan.t[extra], scan.t[extra]),
            )
        return inserted

    def _skipped_over(self, inserted: set[int]) -> None:
        """A link that skips cycles: those no later cycle continues from were inserted (added
        to ``inserted``).

        ``next_open`` jumps over positions already found inserted, so many links that skip
        back to one place (a flood of seals naming the start) cost linear time, not n^2.
        """
        scan, pred = self.scan, self.pred
        jump = list(range(self.n + 1))
        for k in inserted:
            jump[k] = k + 1

        def next_open(k: int) -> int:
            root = k
            while jump[root] != root:
                root = jump[root]
            while jump[k] != root:
                jump[k], k = root, jump[k]
            return root

        for i in range(self.n):
            p = pred[i]
            if scan.link_ok[i] or not (0 <= p < i - 1 or (p == self.ENTRY and i > 0)):
                continue
            skipped: list[int] = []
            k = next_open(max(p, -1) + 1)
            while k < i:
                if k not in inserted:
                    skipped.append(k)
                k = next_open(k + 1)
            if not skipped:
                continue
            # Skipped cycles that continue the chain, before or after ``i``, were moved.
            chain = self._descendants(i) | self._ancestors(i)
            dead = [k for k in skipped if k not in chain]
            inserted.update(dead)
            for k in dead:
                jump[k] = k + 1
            self._report_inserted(p, dead)

    def _report_inserted(self, p: int, dead: list[int]) -> None:
        scan = self.scan
        after = f"after cycle {scan.num[p]}" if p >= 0 else "at the start of the segment"
        for run in _runs(dead):
            numbers = sorted({scan.num[k] for k in run})
            self.report.finding(
                "inserted",
                f"{len(run)} cycle(s) not in the chain {after} "
                f"(numbered {describe_numbers(numbers)})",
                CycleRange(numbers[0], numbers[-1], scan.t[run[0]], scan.t[run[-1]]),
            )

    def _unlinked(self, explained: set[int]) -> None:
        """A seal named by nobody, or naming a seal that is nowhere: removed or altered."""
        scan, pred = self.scan, self.pred
        for i in range(self.n):
            if scan.link_ok[i] or i in explained:
                continue
            if pred[i] >= 0 or pred[i] == self.ENTRY:
                # Linked (to the entry, or a prefix match the full digest disagreed with).
                if pred[i] == i - 1 or (pred[i] == self.ENTRY and i == 0):
                    self._unknown_link(i)
                continue
            q = i - 1
            while q >= 0 and q in explained:
                q -= 1
            self._no_predecessor(i, q, explained)

    def _numbering(self, explained: set[int]) -> None:
        """Numbering gaps along the links that hold."""
        scan = self.scan
        for i in range(self.n):
            if scan.link_ok[i] != 1 or i in explained or (i > 0 and i - 1 in explained):
                continue
            if i > 0:
                self.numbering.gap(scan.num[i - 1], scan.t[i - 1], i)
            elif self.entry_cycle is not None:
                self.numbering.gap(self.entry_cycle, None, i)
            else:
                self.numbering.declared(i, None)

    def _report_moved(self, rest: list[int], moved: set[int]) -> None:
        """One finding per run of moved cycles, located between the cycles around it."""
        scan = self.scan
        j = 0
        while j < len(rest):
            if rest[j] not in moved:
                j += 1
                continue
            k = j
            while k + 1 < len(rest) and rest[k + 1] in moved:
                k += 1
            run = [rest[x] for x in range(j, k + 1)]
            before = rest[j - 1] if j > 0 else None
            after = rest[k + 1] if k + 1 < len(rest) else None
            around = [i for i in (before, after) if i is not None]
            numbers = [scan.num[i] for i in run]
            span = [scan.num[i] for i in run + around]
            times = [scan.t[i] for i in run + around]
            if before is not None and after is not None:
                where = f"between cycles {scan.num[before]} and {scan.num[after]}"
            elif before is not None:
                where = f"after cycle {scan.num[before]}, at the end"
            elif after is not None:
                where = f"before cycle {scan.num[after]}, at the start"
            else:
                where = "alone"
            what = (
                f"cycle {numbers[0]} is"
                if len(run) == 1
                else (f"cycles {describe_numbers(sorted(numbers))} are")
            )
            self.report.finding(
                "reordered",
                f"{what} out of chain order (found {where})",
                CycleRange(min(span), max(span), min(times), max(times)),
            )
            j = k + 1

    def _unknown_link(self, i: int) -> None:
        scan = self.scan
        self.report.finding(
            "modified",
            f"cycle {scan.num[i]}: its seal does not link to the previous seal",
            CycleRange(scan.num[i], scan.num[i], scan.t[i], scan.t[i]),
        )
        scan.bad_positions.add(i)

    def _no_predecessor(self, i: int, q: int, explained: set[int]) -> None:
        """Cycle ``i`` names a previous seal that is nowhere in the log.

        Cycles are missing when numbers are; otherwise a seal was altered. Which one the next
        cycle tells: if it no longer names cycle ``i`` either, ``i``'s own seal changed (its
        ``prev`` and so its digest); if it still links to ``i``, the seal before ``i`` changed.
        """
        report, scan = self.report, self.scan
        number, t = scan.num[i], scan.t[i]
        declared = scan.dropped[i]
        if q < 0:
            before, before_t = self.entry_cycle, None
            if before is None:
                if scan.link_ok[i] == 2:
                    return  # the first segment present: nothing to link to
                # Only the segment's metadata says where the chain entered, and which cycle
                # came first.
                before = self.first_cycle - 1
        else:
            before, before_t = scan.num[q], scan.t[q]
        scan.bad_positions.add(i)
        if number - before - 1 > declared:
            first, last = before + 1, number - 1
            if any(a <= first and last <= b for a, b, _ in scan.damaged):
                return  # lost in a damaged chunk: reported as damage, not as a removal
            report.finding(
                "missing",
                f"cycles {first}..{last} are missing ({last - first + 1} cycle(s) removed: "
                f"cycle {number} names a previous seal that is not in the log)",
                CycleRange(first, last, before_t, t),
            )
            return
        self._altered(i, q, before, before_t, explained)

    def _altered(
        self, i: int, q: int, before: int, before_t: int | None, explained: set[int]
    ) -> None:
        """No cycle is missing before cycle ``i``: say which seal was altered."""
        report, scan = self.report, self.scan
        number, t = scan.num[i], scan.t[i]
        nxt = i + 1 if i + 1 < self.n else None
        if nxt is not None and self.pred[nxt] == self.NONE and not scan.link_ok[nxt]:
            explained.add(nxt)
            report.finding(
                "modified",
                f"cycle {number}: its seal was altered (it names a previous seal that is not "
                f"in the log, and cycle {scan.num[nxt]} no longer names it)",
                CycleRange(number, number, t, t),
            )
        elif nxt is not None and q >= 0:
            scan.bad_positions.add(q)
            report.finding(
                "modified",
                f"cycle {before}: its seal was altered or replaced "
                f"(cycle {number} names a different previous seal)",
                CycleRange(before, before, before_t, before_t),
            )
        elif q >= 0:
            report.finding(
                "modified",
                f"the seal of cycle {before} or of cycle {number} was altered (cycle {number} "
                "names a previous seal that is not in the log)",
                CycleRange(before, number, before_t, t),
            )
        else:
            where = (
                f"the previous segment's chain (which ends at cycle {before})"
                if self.entry_cycle is not None
                else "the chain recorded in the segment's trace.session metadata"
            )
            report.finding(
                "modified",
                f"cycle {number} does not continue {where}: a seal was altered",
                CycleRange(before if self.entry_cycle is not None else number, number, None, t),
            )


def _longest_increasing(values: list[int]) -> set[int]:
    """Indexes of one longest strictly increasing subsequence of ``values`` (O(n log n))."""
    tails: list[int] = []  # smallest tail value of an increasing run of each length
    tail_at: list[int] = []  # index of that tail
    parent = [-1] * len(values)
    for i, value in enumerate(values):
        j = bisect.bisect_left(tails, value)
        if j == len(tails):
            tails.append(value)
            tail_at.append(i)
        else:
            tails[j], tail_at[j] = value, i
        parent[i] = tail_at[j - 1] if j > 0 else -1
    kept: set[int] = set()
    k = tail_at[-1] if tail_at else -1
    while k != -1:
        kept.add(k)
        k = parent[k]
    return kept


def _runs(positions: list[int]) -> list[list[int]]:
    runs: list[list[int]] = []
    for p in positions:
        if runs and p == runs[-1][-1] + 1:
            runs[-1].append(p)
        else:
            runs.append([p])
    return runs
