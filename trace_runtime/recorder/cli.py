"""``trace-recorder``: the recorder service as a program, part of a robot's install.

argparse, not typer: typer and rich belong to the investigator's extra, and the recorder
runs on robots that do not carry it. The program parses, builds one ``Recorder``, serves in
the foreground until SIGTERM or SIGINT, then closes every robot's logger (its queue written,
its segment finished) and exits 0. Errors are one line on stderr with the exit codes of
``trace_runtime.errors``: 2 usage (an option, a key file), 3 unreadable input, 4 cannot
write (the root, the socket).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from types import FrameType
from typing import NoReturn

from trace_runtime.errors import (
    EXIT_CANNOT_WRITE,
    EXIT_OK,
    EXIT_UNREADABLE,
    EXIT_USAGE,
    InputError,
    StorageError,
    UsageError,
)

__all__ = ["main"]

_DESCRIPTION = """\
Take decision cycles from robots in any language over a local socket and write them,
sealed and signed, through the TRACE logger: one chain per robot id under one log root.
The wire protocol is schemas/PROFILE.md section 13; docs/logger.md has a systemd unit."""

_EPILOG = """\
exit codes: 0 stopped by SIGTERM or SIGINT (every logger closed), 2 usage (an
option, a key file that cannot be read), 4 cannot write (the root, the socket)"""


class _Parser(argparse.ArgumentParser):
    """argparse with its usage errors as one line on stderr (exit 2), as every program of
    the project reports bad input; ``--help`` shows the usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see --help)\n")


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="trace-recorder",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    serve = commands.add_parser(
        "serve",
        help="run the recorder in the foreground",
        description="Run the recorder in the foreground until SIGTERM or SIGINT.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    serve.add_argument("--root", required=True, metavar="DIR", help="the log root to write")
    serve.add_argument(
        "--socket",
        required=True,
        metavar="PATH",
        help="the Unix socket to listen on (created with mode 0660: owner and group only)",
    )
    serve.add_argument(
        "--tcp",
        metavar="HOST:PORT",
        help="also listen on a loopback TCP address, e.g. 127.0.0.1:7400 (port 0: any free)",
    )
    serve.add_argument(
        "--key",
        metavar="KEY",
        help="sign every robot's checkpoints with this Ed25519 key (trace-audit keygen): a "
        "key file or a pkcs11: URI of a key in a token",
    )
    serve.add_argument(
        "--next-key",
        metavar="KEY",
        help="rotate every robot to this key (profile 1.5): --key announces it at the robot's "
        "next checkpoint, unless its chain already did (a restart, a reconnect): then it "
        "signs with this key alone; needs --key",
    )
    serve.add_argument(
        "--witness",
        metavar="URL",
        help="submit signed checkpoints to this C2SP witness (needs --key)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``trace-recorder``; return its exit code."""
    logging.basicConfig(stream=sys.stderr, level=logging.INFO, format="trace-recorder: %(message)s")
    args = _parser().parse_args(argv)  # exits 2 with argparse's usage line
    try:
        return _serve(args)
    except UsageError as err:
        code = EXIT_USAGE
        message = str(err)
    except InputError as err:
        code = EXIT_UNREADABLE
        message = str(err)
    except StorageError as err:
        code = EXIT_CANNOT_WRITE
        message = str(err)
    print(f"trace-recorder: {message}", file=sys.stderr)
    return code


def _serve(args: argparse.Namespace) -> int:
    # Deferred: --help and argument errors answer without loading the logger.
    from trace_runtime.logger.config import LoggerConfig
    from trace_runtime.recorder.server import Recorder, parse_tcp
    from trace_runtime.tlog.signers import open_signer

    if args.witness and not args.key:
        raise UsageError("--witness needs --key: a witness cosigns signed checkpoints only")
    tcp = parse_tcp(args.tcp) if args.tcp else None
    if args.next_key and not args.key:
        raise UsageError("--next-key needs --key: the key the robots sign with announces it")
    # A bad key is the operator's to fix before any robot connects: load it once here.
    signer = open_signer(args.key) if args.key else None
    next_signer = open_signer(args.next_key) if args.next_key else None
    if next_signer is not None and signer is not None and next_signer.key_id == signer.key_id:
        raise UsageError("--next-key is --key itself: nothing to rotate to")
    config = LoggerConfig(checkpoint_key=signer, next_key=next_signer, witness=args.witness)
    recorder = Recorder(args.root, socket_path=args.socket, tcp=tcp, config=config)

    def stop(signum: int, frame: FrameType | None) -> None:
        recorder.stop()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        where = recorder.open()
        logging.getLogger("trace_runtime.recorder").info(
            "writing %s, listening on %s", args.root, ", ".join(where)
        )
        recorder.serve()
    finally:
        recorder.close()
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
