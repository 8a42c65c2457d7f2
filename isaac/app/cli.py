"""The `isaac` command line.

Each package registers its own sub-commands (`register(subparsers)`), so the engine's commands
(`run`, `check`) live here and the recorder's and replay's live with them. Every `IsaacError` is
turned into one line on stderr and its exit status; no traceback reaches the user.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from isaac.errors import IsaacError

# Modules that add sub-commands; a module that is not there (yet) is skipped.
COMMAND_MODULES = (
    "isaac.app.run",
    "isaac.app.logs",
    "isaac.app.verify",
    "isaac.app.tradeoff",
    "isaac.app.sweep",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="isaac", description="ISAAC: recorded, replayable 2D rigid-body physics."
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    from isaac.tuning import reuse_large_buffers

    reuse_large_buffers()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        status = args.func(args)
    except IsaacError as exc:
        print(f"isaac {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print(f"isaac {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # output piped into `head` and the like, which stopped reading: stop quietly (and keep
        # Python's own flush at exit from raising again)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return int(status or 0)


if __name__ == "__main__":
    sys.exit(main())
