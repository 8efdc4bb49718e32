"""The recorder: robots in any language feed their decision cycles over a local socket, and
``trace-recorder`` writes them through the same logger (schemas/PROFILE.md section 13).

``protocol`` (frames, kinds, limits, checks), ``robots`` (one logger per robot id),
``connection`` (one client's thread), ``server`` (``Recorder``: the listening sockets),
``client`` (``RemoteLogger``: ``AuditLogger``'s API over the protocol; ``remote_cycle``: the
cycle it hands the control loop, and its counters), ``cli``
(``trace-recorder``).
"""

from __future__ import annotations

from trace_runtime.recorder.client import RemoteCycle, RemoteLogger, RemoteStats
from trace_runtime.recorder.server import Recorder

__all__ = ["Recorder", "RemoteCycle", "RemoteLogger", "RemoteStats"]
