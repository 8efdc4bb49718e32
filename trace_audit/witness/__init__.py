"""A C2SP tlog-witness for TRACE logs, and the investigator's side of it.

- ``state``: the latest cosigned checkpoint per origin, in SQLite (synchronous FULL).
- ``server``: ``POST /add-checkpoint`` (c2sp.org/tlog-witness) and ``GET /checkpoint/<origin>``
  (this project's extension: the latest cosigned note), on the stdlib's HTTP server.
- ``push``: submitting a log root's checkpoints afterwards (a robot that was offline).
- ``vkey``: the C2SP verifier key of a public key file (``witness vkey``).
- ``compare``: the witnessed state of a robot (from a witness, a note file or the root's own
  ``witness/`` store) against its log, for ``verify --witness``.

See docs/integrity.md (the witness) and docs/witness.md (running one for a fleet).
"""
