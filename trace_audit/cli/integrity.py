"""trace-audit commands: integrity (registered on the shared app)."""

from __future__ import annotations
