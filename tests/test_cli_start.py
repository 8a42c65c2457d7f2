"""The command line's start-up: a command line naming a sub-command imports that sub-command's
module alone (isaac.app.cli.COMMANDS), and the map agrees with what the modules register."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
from pathlib import Path

from isaac.app.cli import COMMAND_MODULES, COMMANDS, build_parser

ROOT = Path(__file__).resolve().parents[1]


def _choices(parser: argparse.ArgumentParser) -> list[str]:
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return list(sub.choices)


def test_the_command_map_names_the_module_that_registers_each_command():
    registered = {}
    for name in COMMAND_MODULES:
        parser = argparse.ArgumentParser()
        sub = parser.add_subparsers(dest="command")
        importlib.import_module(name).register(sub)
        registered.update({command: name for command in _choices(parser)})
    assert registered == COMMANDS
    assert _choices(build_parser()) == list(COMMANDS)  # without a command: every one
    assert _choices(build_parser("check")) == ["run", "check"]


def test_a_command_imports_its_own_module_alone():
    code = (
        "import sys; from isaac.app.cli import main; "
        "status = main(['check', 'scenes/bounce.yaml']); "
        "print(sorted(m for m in sys.modules if m.startswith('isaac.app.')))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert (
        proc.stdout.strip().splitlines()[-1]
        == "['isaac.app.cli', 'isaac.app.options', 'isaac.app.run']"
    )


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def test_ctrl_c_while_the_command_imports_its_modules_says_one_line_and_exits_130():
    # as the console script does: argv[0] is `isaac`; the signal comes right after the command
    # line's module is imported, before `main` runs (its handler raises at the next line)
    proc = _python(
        "import os, signal, sys, time; sys.argv[0] = '/usr/bin/isaac'; "
        "from isaac.app.cli import main; os.kill(os.getpid(), signal.SIGINT); time.sleep(30)"
    )
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr == "isaac: interrupted\n"


def test_ctrl_c_while_main_imports_the_sub_command_says_one_line_and_exits_130():
    proc = _python(
        "import os, signal, sys, time; sys.argv[0] = '/usr/bin/isaac'; "
        "import isaac.app.cli as cli\n"
        "def slow_parser(command):\n"
        "    os.kill(os.getpid(), signal.SIGINT); time.sleep(30)\n"
        "cli.build_parser = slow_parser\n"
        "sys.exit(cli.main(['check', 'scenes/bounce.yaml']))"
    )
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr == "isaac check: interrupted\n"


def test_a_program_that_imports_the_command_line_keeps_its_own_ctrl_c():
    proc = _python("import sys; import isaac.app.cli; print(sys.excepthook is sys.__excepthook__)")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "True"


def _as_the_command(args: str, before: str = "") -> subprocess.CompletedProcess:
    """`isaac ARGS` as its console script runs it (argv[0] `isaac`, `main()` on sys.argv),
    after `before` (Python lines)."""
    return _python(
        "import atexit, sys, threading, time\n"
        f"{before}\n"
        f"sys.argv = ['/usr/bin/isaac', *{args.split()!r}]\n"
        "from isaac.app.cli import main\n"
        "sys.exit(main())\n"
    )


def test_the_command_ends_at_once_with_its_status_output_and_exit_handlers():
    # isaac ends with os._exit (no interpreter teardown): its status, both streams' last
    # lines and the atexit handlers must survive it, and nothing after main() runs
    before = "atexit.register(lambda: print('handler ran', flush=True))"
    ok = _as_the_command("check scenes/bounce.yaml", before + "\nsys.exit = None")
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.rstrip().endswith("handler ran")
    assert "bounce" in ok.stdout
    bad = _as_the_command("check scenes/missing.yaml", before)
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "missing.yaml" in bad.stderr
    assert bad.stdout == "handler ran\n"


def test_the_command_waits_for_a_thread_that_is_still_running():
    # a non-daemon thread still alive at the end: the normal exit, which waits for it
    before = (
        "t = threading.Thread(target=lambda: (time.sleep(1.0), print('thread done', flush=True)))"
        "\nt.start()"
    )
    proc = _as_the_command("check scenes/bounce.yaml", before)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.rstrip().endswith("thread done")


def test_isaac_run_pauses_the_collector_only_as_the_command_and_runs_it_again():
    import gc

    from isaac.app.run import _pause_collector, _settle_collector

    called = argparse.Namespace(owns_process=False)  # a program's call: its collector is its own
    assert _pause_collector(called) is False and gc.isenabled()
    command = argparse.Namespace(owns_process=True)
    frozen = gc.get_freeze_count()
    try:
        running = _pause_collector(command)
        assert running is True and not gc.isenabled()
        kept = [object() for _ in range(10)]  # start-up's objects
        assert _settle_collector(running) is False
        assert gc.isenabled()  # collecting again for the run itself
        assert gc.get_freeze_count() >= frozen + len(kept)  # ... without start-up's objects
        assert _settle_collector(False) is False and gc.isenabled()
    finally:
        gc.unfreeze()
        gc.enable()
