"""The logger a robot embeds: the API (``api``: ``AuditLogger``), its configuration and
statistics (``config``), a cycle built on the control thread (``cycle_builder``), the
hand-over queue (``handover``), the writer thread (``writer_thread``), sealing and rotation
(``chain_writer``), checkpoints (``checkpointer``), the witness feed (``witness_feed``), the
MCAP segment writer (``segment_writer``) and the records it builds (``mcap_out``), the
one-writer lock (``lock``) and where a restarted robot's chain continues (``resume``).

``from trace_runtime import AuditLogger, LoggerConfig`` is the public way in.
"""
