"""The logger's own cost per cycle: a fixed-size histogram the writer fills, and the
``trace.timing`` metadata record it ends each segment with (schemas/PROFILE.md §2.2).

What is measured is the control thread's time inside the logger for one cycle: the
``sensor()`` calls, the four layer calls (validating and encoding plain dicts) and
``commit()`` up to the hand-over to the writer. The writer thread's work (sealing,
compression, the write) is not on the control thread and is not counted. The Python logger
times one cycle in eight (``cycle_builder.COST_SAMPLE_EVERY``), so timing costs the other seven
nothing; ``cycles`` in the record counts the cycles timed, ``sample_every`` says which.

The histogram is log-linear: exact below 16 ns, then eight buckets per power of two, so a
percentile read from it is within 1/16 (6.25 %) of the true value, whatever the range.
Histograms of several segments merge by adding counts, so ``trace-audit metrics`` reports
one p50 / p99 over a whole fleet without keeping the samples. Memory is bounded by the
number of buckets (at most 8 per bit of a 64-bit duration).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

TIMING_METADATA = "trace.timing"
"""Name of the metadata record holding a segment's commit-cost statistics."""

_SUB_BITS = 3  # 2**3 = 8 buckets per power of two
_EXACT_BELOW = 1 << (_SUB_BITS + 1)
_MAX_TEXT = 64 * 1024  # a hostile histogram text is refused, not parsed into a huge dict
_MAX_BUCKET = ((64 - _SUB_BITS - 1) << _SUB_BITS) + (1 << (_SUB_BITS + 1)) - 1
"""The bucket of the largest 64-bit duration; a bigger index in a file is refused (its bounds
would be a shift by that many bits)."""


def bucket_of(value_ns: int) -> int:
    """The histogram bucket of a duration (ns); buckets grow with the value."""
    if value_ns < _EXACT_BELOW:
        return max(value_ns, 0)
    shift = value_ns.bit_length() - _SUB_BITS - 1
    return (shift << _SUB_BITS) + (value_ns >> shift)


def bucket_bounds(bucket: int) -> tuple[int, int]:
    """[low, high) of the durations (ns) that fall into ``bucket``."""
    if bucket < _EXACT_BELOW:
        return bucket, bucket + 1
    shift = (bucket >> _SUB_BITS) - 1
    mantissa = (bucket & ((1 << _SUB_BITS) - 1)) | (1 << _SUB_BITS)
    return mantissa << shift, (mantissa + 1) << shift


@dataclass(slots=True)
class CostHistogram:
    """Per-cycle costs in ns: exact count, sum, min and max; percentiles to bucket width."""

    counts: dict[int, int] = field(default_factory=dict)
    cycles: int = 0
    total_ns: int = 0
    min_ns: int | None = None
    max_ns: int | None = None

    def add(self, value_ns: int) -> None:
        """Count one cycle's cost (the writer thread calls this, once per cycle written)."""
        b = bucket_of(value_ns)
        self.counts[b] = self.counts.get(b, 0) + 1
        self.cycles += 1
        self.total_ns += value_ns
        if self.min_ns is None or value_ns < self.min_ns:
            self.min_ns = value_ns
        if self.max_ns is None or value_ns > self.max_ns:
            self.max_ns = value_ns

    def merge(self, other: CostHistogram) -> None:
        """Add ``other``'s cycles into this histogram."""
        for b, n in other.counts.items():
            self.counts[b] = self.counts.get(b, 0) + n
        self.cycles += other.cycles
        self.total_ns += other.total_ns
        for value in (other.min_ns, other.max_ns):
            if value is not None:
                self.min_ns = value if self.min_ns is None else min(self.min_ns, value)
                self.max_ns = value if self.max_ns is None else max(self.max_ns, value)

    @property
    def mean_ns(self) -> float | None:
        return self.total_ns / self.cycles if self.cycles else None

    def percentile_ns(self, q: float) -> int | None:
        """The ``q`` quantile (0..1): the middle of the bucket holding that rank, clamped to
        the exact min and max."""
        if not self.cycles or not self.counts:
            return None
        rank = min(self.cycles - 1, int(q * self.cycles))
        seen = 0
        for b in sorted(self.counts):
            seen += self.counts[b]
            if seen > rank:
                low, high = bucket_bounds(b)
                middle = (low + high - 1) // 2
                assert self.min_ns is not None and self.max_ns is not None
                return min(max(middle, self.min_ns), self.max_ns)
        return self.max_ns

    def to_metadata(self, sample_every: int = 1) -> dict[str, str]:
        """The ``trace.timing`` record (MCAP metadata: strings only); ``sample_every``: one
        cycle in that many was timed."""
        out = {
            "cycles": str(self.cycles),
            "sample_every": str(sample_every),
            "what": "control-thread ns per cycle in the logger",
        }
        if self.cycles:
            out.update(
                commit_mean_ns=f"{self.total_ns / self.cycles:.1f}",
                commit_p50_ns=str(self.percentile_ns(0.5)),
                commit_p99_ns=str(self.percentile_ns(0.99)),
                commit_min_ns=str(self.min_ns),
                commit_max_ns=str(self.max_ns),
                commit_histogram=" ".join(f"{b}:{n}" for b, n in sorted(self.counts.items())),
            )
        return out

    @classmethod
    def from_metadata(cls, data: Mapping[str, str]) -> CostHistogram | None:
        """Read a ``trace.timing`` record; None when it holds no histogram (a record from
        another writer may give only ``commit_mean_ns`` and ``cycles``). Raises
        ``ValueError`` when a field is malformed."""
        text = data.get("commit_histogram")
        if text is None:
            return None
        if len(text) > _MAX_TEXT:
            raise ValueError("commit_histogram is too long")
        out = cls()
        for item in text.split():
            key, _, count = item.partition(":")
            b, n = int(key), int(count)
            if not 0 <= b <= _MAX_BUCKET or n <= 0 or b in out.counts:
                raise ValueError(f"bad commit_histogram entry {item!r}")
            out.counts[b] = n
        out.cycles = sum(out.counts.values())
        if out.cycles != int(data.get("cycles", out.cycles)):
            raise ValueError("commit_histogram does not add up to cycles")
        mean = float(data.get("commit_mean_ns", "0"))
        out.total_ns = round(mean * out.cycles)
        low, high = _bounds(out.counts)
        out.min_ns = int(data.get("commit_min_ns", low))
        out.max_ns = int(data.get("commit_max_ns", high))
        return out


def _bounds(counts: Iterable[int]) -> tuple[int, int]:
    buckets = sorted(counts)
    return bucket_bounds(buckets[0])[0], bucket_bounds(buckets[-1])[1] - 1
