"""The `isaac` command line.

Each package registers its own sub-commands (`register(subparsers)`), so the engine's commands
(`run`, `check`) live here and the recorder's and replay's live with them. Every `IsaacError` is
turned into one line on stderr and its exit status; no traceback reaches the user.
"""

from __future__ import annotations

import sys


def _interrupted_at_start(kind, value, tb, _previous=sys.excepthook) -> None:
    """sys.excepthook while this module and `main` run: Ctrl-C before `main` catches it (in the
    first few hundred ms of a command: its imports) says one line and exits with status 130, as
    `main` does, instead of printing the interrupted import's traceback."""
    if not issubclass(kind, KeyboardInterrupt):
        _previous(kind, value, tb)
        return
    import os

    try:
        print("isaac: interrupted", file=sys.stderr, flush=True)
    finally:
        os._exit(130)  # not Python's own exit: a second traceback could come from its clean-up


def _is_the_command() -> bool:
    """Whether this process is the `isaac` command (its console script, or `python -m isaac`),
    not a program that imports this module (whose Ctrl-C is its own)."""
    argv0 = (getattr(sys, "argv", None) or [""])[0].replace("\\", "/")
    return argv0.rsplit("/", 1)[-1] == "isaac" or argv0.endswith("isaac/__main__.py")


# first, before the other imports: the console script imports this module, then calls `main`
if _is_the_command():
    sys.excepthook = _interrupted_at_start

import argparse  # noqa: E402 - after the hook, which covers these imports
import importlib  # noqa: E402
import os  # noqa: E402

from isaac.errors import IsaacError  # noqa: E402

# Modules that add sub-commands; a module that is not there (yet) is skipped.
COMMAND_MODULES = (
    "isaac.app.run",
    "isaac.app.logs",
    "isaac.app.verify",
    "isaac.app.tradeoff",
    "isaac.app.sweep",
)
# the module of each sub-command (tests/test_cli_start.py checks it against COMMAND_MODULES):
# a command line naming one imports that module alone (importing the others is start-up time)
COMMANDS = {
    "run": "isaac.app.run",
    "check": "isaac.app.run",
    "inspect": "isaac.app.logs",
    "view": "isaac.app.logs",
    "recover": "isaac.app.logs",
    "replay": "isaac.app.verify",
    "diff": "isaac.app.verify",
    "tradeoff": "isaac.app.tradeoff",
    "sweep": "isaac.app.sweep",
}


class Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage errors (an unknown option, a missing argument, a value an
    option's type refuses: isaac.app.options) are one line, ``isaac run: error: argument
    --steps: ...; see `isaac run --help```, exit status 2, instead of the usage text and then
    the error. Its sub-command parsers are of this class too (argparse makes them so)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}; see `{self.prog} --help`\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every sub-command, or of ``command``'s module alone when it is one of
    COMMANDS (what `main` builds for a command line that starts with it)."""
    parser = Parser(prog="isaac", description="ISAAC: recorded, replayable 2D rigid-body physics.")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    modules = (COMMANDS[command],) if command in COMMANDS else COMMAND_MODULES
    for name in modules:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line `argv` (default: this process's) and return its exit status. As
    the `isaac` command itself (argv None), a finished command ends the process at once
    (`_end_now`)."""
    words = sys.argv[1:] if argv is None else argv
    command = words[0] if words and not words[0].startswith("-") else None
    try:
        status = _main(argv, words)
    except KeyboardInterrupt:
        # Ctrl-C while the sub-command's modules were imported or its arguments parsed
        print(f"isaac{' ' + command if command else ''}: interrupted", file=sys.stderr)
        status = 130
    if argv is None and _is_the_command():
        _end_now(status)
    return status


def _end_now(status: int) -> None:
    """End the `isaac` process now, with `status`, without the interpreter's teardown.

    Why: once a command has closed its files, Python's teardown (freeing numba's and LLVM's
    objects and every module) is a noticeable part of a short `isaac run`, more with its
    recordings (docs/speed.md, the start-up). What a normal exit does that matters still
    happens: the `atexit` handlers run (numba's, dask's, multiprocessing's, the compile
    helpers' reaping) and the standard streams are flushed.
    Every file a command writes is closed before it returns. Returns (and the normal exit
    follows) when a non-daemon thread is still alive, which a normal exit would wait for, or
    when this Python has no `atexit._run_exitfuncs`.
    """
    import atexit
    import threading

    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)
    main_thread = threading.main_thread()
    waiting = [t for t in threading.enumerate() if t is not main_thread and not t.daemon]
    if run_exit_handlers is None or waiting:
        return
    try:
        run_exit_handlers()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe (`| head`) or a closed stream
                pass
        os._exit(status)


def _main(argv: list[str] | None, words: list[str]) -> int:
    from isaac.tuning import one_blas_thread, reuse_large_buffers

    reuse_large_buffers()
    one_blas_thread()  # before numpy is imported, by this command or the processes it starts
    parser = build_parser(words[0] if words else None)
    args = parser.parse_args(argv)
    # whether the command is this process's only job (the `isaac` command itself, not a call
    # from a program): it may then tune the process (`isaac run`'s collector, see run.py)
    args.owns_process = argv is None and _is_the_command()
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
