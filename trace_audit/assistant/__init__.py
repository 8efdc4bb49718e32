"""The assistant: ``trace-audit mcp``, a read-only Model Context Protocol server whose tools
are the investigator's questions and whose every answer carries its integrity
(docs/assistant.md).

``roots`` confines what a model may name, ``questions`` asks the library as the CLI's
``--json`` does (in the ``worker`` process, killed on a call's timeout), ``bound`` cuts an
answer to its size, ``integrity`` reads verify's report (kept per log while its files are
unchanged), ``answers`` types what a tool returns, ``server`` assembles an answer,
``tools`` declares the tools, ``serve`` runs them over stdio or loopback HTTP.
"""

from __future__ import annotations

__all__: list[str] = []
