"""The sample logs the investigator's tests use, shared with the verification tests."""

from tests.trace_audit.conftest import crashed_log, sample_log

__all__ = ["crashed_log", "sample_log"]
