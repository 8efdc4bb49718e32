"""``python -m trace_audit.cli``: the same as the ``trace-audit`` command."""

from trace_audit.cli import main

if __name__ == "__main__":
    main()
