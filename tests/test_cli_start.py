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
    assert proc.stdout.strip().splitlines()[-1] == "['isaac.app.cli', 'isaac.app.run']"
