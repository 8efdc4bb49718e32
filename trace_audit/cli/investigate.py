"""trace-audit commands: investigate (registered on the shared app)."""

from __future__ import annotations
