"""trace-audit commands: storage (registered on the shared app)."""

from __future__ import annotations
