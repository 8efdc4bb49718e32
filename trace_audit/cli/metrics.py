"""trace-audit commands: metrics (registered on the shared app)."""

from __future__ import annotations
