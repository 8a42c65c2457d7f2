"""The replay sub-commands: ``isaac replay LOG.mcap`` and ``isaac diff A.mcap B.mcap``.

Exit status (docs/replay.md): 0 identical (or equal within ``--tolerance``): every step the log
claims was there, intact, and compared; with ``--partial`` also a damaged or unfinished log
whose readable steps were all identical. 1 diverged, or the log is damaged or was never closed
(the report names the first divergence, or the first damaged or missing step). 2 an unusable
file (not a regular file, not an ISAAC MCAP log, a corrupt header, an invalid embedded scene, a
malformed message, no complete step to compare), as a one-line error.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from isaac.app.options import integer, number
from isaac.errors import LogError
from replay.report import DEFAULT_MAX_REPORTED, Report, format_text, to_json


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--from-step",
        type=integer(minimum=0),
        metavar="K",
        default=None,
        help="start from the state logged at step K (every logged step is a keyframe)",
    )
    p.add_argument(
        "--to-step", type=integer(minimum=0), metavar="M", default=None, help="stop after step M"
    )
    p.add_argument(
        "--tolerance",
        type=number(minimum=0.0),
        metavar="X",
        default=None,
        help="compare floats within |a - b| <= X * (1 + |a|) instead of bit for bit "
        "(for logs made with other versions or on other machines)",
    )
    p.add_argument(
        "--all",
        action="store_true",
        dest="all_steps",
        help="go on after a divergence and list every differing step",
    )
    p.add_argument(
        "--max-reported",
        type=integer(minimum=1),
        default=DEFAULT_MAX_REPORTED,
        metavar="N",
        help=f"with --all, list at most N differing steps (default {DEFAULT_MAX_REPORTED})",
    )
    p.add_argument(
        "--partial",
        action="store_true",
        help="accept a damaged or unfinished (.partial) log checked up to its last complete "
        "step before the damage: verdict 'partial: N of M steps checked', exit 0 when those "
        "are identical (without it such a log fails, exit 1)",
    )
    p.add_argument(
        "--json",
        metavar="OUT.json",
        default=None,
        help="also write the report as JSON to this file ('-' for stdout)",
    )


def register(subparsers) -> None:
    r = subparsers.add_parser(
        "replay",
        help="re-simulate a log from its embedded scene and check it bit for bit",
        description="Re-simulate LOG.mcap from the scene, settings and versions embedded in it "
        "and compare every logged /bodies, /contacts and /stats message with the "
        "re-simulated one. Exit 0 identical (every step the log claims present, intact and "
        "compared), 1 diverged, damaged or incomplete, 2 unusable file.",
    )
    r.add_argument(
        "log",
        help="LOG.mcap (a damaged, cut or .partial log fails unless --partial is given)",
    )
    _common(r)
    r.set_defaults(func=cmd_replay)

    d = subparsers.add_parser(
        "diff",
        help="compare two logs of the same scene step by step",
        description="Compare A.mcap and B.mcap message by message (e.g. before and after a code "
        "change). Exit 0 identical (both logs whole), 1 different, damaged or incomplete, "
        "2 unusable file.",
    )
    d.add_argument("a", help="A.mcap")
    d.add_argument("b", help="B.mcap")
    d.add_argument(
        "--force", action="store_true", help="compare logs of different scenes all the same"
    )
    _common(d)
    d.set_defaults(func=cmd_diff)


def _finish(report: Report, args: argparse.Namespace) -> int:
    text = format_text(report, all_steps=args.all_steps)
    if args.json == "-":
        print(to_json(report))
        print(text, file=sys.stderr)
    else:
        print(text)
        if args.json:
            try:
                Path(args.json).write_text(to_json(report) + "\n", encoding="utf-8")
            except OSError as exc:
                raise LogError(f"cannot write {args.json}: {exc.strerror or exc}") from None
    return report.exit_status


def cmd_replay(args: argparse.Namespace) -> int:
    from replay.compare import replay_log

    report = replay_log(
        args.log,
        from_step=args.from_step,
        to_step=args.to_step,
        tolerance=args.tolerance,
        all_steps=args.all_steps,
        max_reported=args.max_reported,
        partial=args.partial,
    )
    return _finish(report, args)


def cmd_diff(args: argparse.Namespace) -> int:
    from replay.compare import diff_logs

    report = diff_logs(
        args.a,
        args.b,
        from_step=args.from_step,
        to_step=args.to_step,
        tolerance=args.tolerance,
        all_steps=args.all_steps,
        max_reported=args.max_reported,
        partial=args.partial,
        force=args.force,
    )
    return _finish(report, args)
