"""Fault injection at the paper's rates, and the ground-truth sidecar that records it.

Faults act on the real pipeline: a sensor that is down produces no reading; a corrupted
evidence link loses (or misdirects) an entity's refs; an edge write failure leaves a belief
edge on a factor's chain out of the record; a rationale written into a smaller buffer is
truncated; counterfactual probing given a cut budget produces nothing; an audit write
timeout makes the log's file stream raise ``OSError`` so the logger drops the cycle.

The truth sidecar (JSON lines) is for tests that check the metrics found exactly what was
injected. Metrics must never read it.
"""

from __future__ import annotations

import errno
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import IO, Any, BinaryIO, cast

import numpy as np
import orjson

from trace_runtime.logger.config import default_opener


@dataclass(frozen=True, slots=True)
class FaultRates:
    """Per-cycle (evidence: per-entity) probabilities of each injected fault."""

    lidar_unavailable: float = 0.02
    camera_unavailable: float = 0.12
    evidence_corruption: float = 0.03
    edge_write_failure: float = 0.02
    rationale_truncation: float = 0.02
    counterfactual_timeout: float = 0.025
    audit_write_timeout: float = 0.01

    @classmethod
    def off(cls) -> FaultRates:
        """No faults at all (sensors always up)."""
        return cls(**{f.name: 0.0 for f in fields(cls)})

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class CycleFaults:
    """The faults drawn for one cycle (per-entity corruption is drawn later, per entity)."""

    lidar_down: bool = False
    camera_down: bool = False
    edge_failure: bool = False
    truncate: bool = False
    cf_timeout: bool = False
    write_timeout: bool = False


class FaultInjector:
    """Draws faults from its own random stream, so the world's randomness is unaffected."""

    def __init__(self, rates: FaultRates, rng: np.random.Generator) -> None:
        self.rates = rates
        self.rng = rng

    def draw_cycle(self) -> CycleFaults:
        # As Python floats: the same doubles, compared without a numpy scalar each (~1 us).
        u = self.rng.random(6).tolist()
        r = self.rates
        return CycleFaults(
            lidar_down=u[0] < r.lidar_unavailable,
            camera_down=u[1] < r.camera_unavailable,
            edge_failure=u[2] < r.edge_write_failure,
            truncate=u[3] < r.rationale_truncation,
            cf_timeout=u[4] < r.counterfactual_timeout,
            write_timeout=u[5] < r.audit_write_timeout,
        )

    def corrupt_entity(self) -> str | None:
        """None, or how this entity's evidence link is corrupted: ``null`` or ``dangling``."""
        u = self.rng.random(2).tolist()
        if u[0] >= self.rates.evidence_corruption:
            return None
        return "null" if u[1] < 0.5 else "dangling"

    def pick(self, n: int) -> int:
        return int(self.rng.integers(0, n))


class FailingStream:
    """A file stream that raises ``ETIMEDOUT`` on write while ``failing`` is set.

    Handed to the logger through ``LoggerConfig.opener``; everything else is delegated to
    the real file, so the logger's roll-back (seek + truncate) works on the real bytes.
    """

    def __init__(self, inner: BinaryIO) -> None:
        self._inner = inner
        self.failing = False

    def write(self, data: bytes) -> int:
        if self.failing:
            raise OSError(errno.ETIMEDOUT, "simulated audit write timeout")
        return self._inner.write(data)

    def flush(self) -> None:
        self._inner.flush()

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._inner.seek(offset, whence)

    def tell(self) -> int:
        return self._inner.tell()

    def truncate(self, size: int | None = None) -> int:
        return self._inner.truncate(size)

    def fileno(self) -> int:
        return self._inner.fileno()

    def close(self) -> None:
        self._inner.close()

    @property
    def closed(self) -> bool:
        return self._inner.closed


class FailingOpener:
    """``LoggerConfig.opener`` that wraps every segment file in a ``FailingStream``."""

    def __init__(self) -> None:
        self.streams: list[FailingStream] = []
        self._failing = False

    def __call__(self, path: Path) -> BinaryIO:
        stream = FailingStream(default_opener(path))  # never over an existing log
        stream.failing = self._failing
        self.streams.append(stream)
        return cast(BinaryIO, stream)

    def set_failing(self, failing: bool) -> None:
        self._failing = failing
        for s in self.streams:
            s.failing = failing


DEFAULT_ROBOT_ID = "amr-01"
"""The simulated robot's id unless told otherwise (``trace-sim run --robot-id``)."""


def truth_path_for(out: Path, robot_id: str = DEFAULT_ROBOT_ID) -> Path:
    """Where the truth sidecar of a log goes: ``X.mcap.truth.jsonl``, or in a log root
    ``ROOT/truth/sim-truth.jsonl`` for the default robot and ``sim-truth-<robot>.jsonl`` for
    another, so several simulated robots sharing a root keep their truth apart."""
    if out.suffix == ".mcap":
        return out.with_name(out.name + ".truth.jsonl")
    name = "sim-truth" if robot_id == DEFAULT_ROBOT_ID else f"sim-truth-{robot_id}"
    return out / "truth" / f"{name}.jsonl"


class TruthLog:
    """Appends one JSON line per injected fault: cycle, t_ns, scenario, kind, detail.

    ``keep=True`` adds to what the file holds: a run into an existing log root continues the
    robot's chain there (a restart), and the earlier run's truth must stay beside it."""

    def __init__(self, path: Path, *, keep: bool = False) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._f: IO[bytes] = open(path, "ab" if keep else "wb")  # noqa: SIM115 - closed in close()
        self.counts: dict[str, int] = {}

    def write(
        self, cycle: int, t_ns: int, scenario: str, kind: str, detail: dict[str, Any]
    ) -> None:
        line = {"cycle": cycle, "t_ns": t_ns, "scenario": scenario, "kind": kind, "detail": detail}
        self._f.write(orjson.dumps(line) + b"\n")
        self.counts[kind] = self.counts.get(kind, 0) + 1

    def close(self) -> None:
        self._f.close()


def read_truth(path: Path) -> list[dict[str, Any]]:
    """Read a truth sidecar back (tests only; metrics must not)."""
    with open(path, "rb") as f:
        return [orjson.loads(line) for line in f if line.strip()]
