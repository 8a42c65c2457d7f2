"""`isaac tradeoff SCENE.yaml`: the command line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from isaac.app.options import integer, number
from isaac.app.tradeoff.grid import parse_grid
from isaac.app.tradeoff.measure import measure
from isaac.app.tradeoff.report import format_table, plot, write_csv
from isaac.app.tradeoff.trajectory import MIN_TIMED_SECONDS
from isaac.scene import load_scene

# bounds of the options whose larger values would run for days: the timed rounds and the
# seconds timed per point in a round
MAX_REPEATS = 1000
MAX_MIN_TIME = 3600.0  # s


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "tradeoff",
        help="measure error against cost of fidelity settings on a scene",
        description="Run SCENE under a grid of settings (default: the presets x the scene's dt "
        "times 2, 1 and 1/2), each against a reference, and report cost (ms/step, "
        "median of repeats) and error. Writes a CSV and a PNG (error vs cost, "
        "Pareto front marked).",
    )
    p.add_argument("scene", help="scene YAML file")
    p.add_argument(
        "--grid",
        action="append",
        metavar="KEY=V1,V2",
        help="a grid axis (repeatable; or several joined by ';'): preset=..., "
        "dt=1/60,1/120 (or x2 for twice the scene's dt), or any world setting "
        "(iterations=4,10, ccd=off,speculative, ...)",
    )
    p.add_argument(
        "--reference",
        choices=("accurate", "analytic"),
        default=None,
        help="accurate: the accurate preset at a small dt (default, unless the scene "
        "declares `analytic:`); analytic: the closed form (free flight, a flat "
        "drop on level ground, a 1D head-on hit)",
    )
    p.add_argument(
        "--reference-dt",
        type=number(minimum=0.0, above=True, maximum=1.0),
        default=None,
        metavar="S",
        help="dt of the accurate reference, in (0, 1] s (default: the scene's dt / 8)",
    )
    p.add_argument(
        "--duration",
        type=number(minimum=0.0, above=True),
        default=None,
        metavar="S",
        help="simulated seconds (default: the scene's steps x dt); at most 100000000 steps of "
        "the finest dt run",
    )
    p.add_argument(
        "--repeats",
        type=integer(minimum=1, maximum=MAX_REPEATS),
        default=3,
        help=f"timed runs per setting (median; default 3, at most {MAX_REPEATS})",
    )
    p.add_argument(
        "--min-time",
        type=number(minimum=0.0, maximum=MAX_MIN_TIME),
        default=MIN_TIMED_SECONDS,
        metavar="S",
        help="repeat short runs until this many seconds were timed "
        f"(default {MIN_TIMED_SECONDS}, at most {MAX_MIN_TIME:g})",
    )
    p.add_argument("--csv", metavar="OUT.csv", help="CSV path (default: SCENE_tradeoff.csv here)")
    p.add_argument("--png", metavar="OUT.png", help="plot path (default: SCENE_tradeoff.png)")
    p.add_argument("--no-plot", action="store_true", help="do not write the plot")
    p.add_argument(
        "--second",
        default=None,
        choices=("max_penetration_m", "energy_error", "com_error_m", "max_joint_error_m"),
        help="error shown in the plot's second panel (default: max_joint_error_m for a scene "
        "with joints, else max_penetration_m)",
    )
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_tradeoff)


def cmd_tradeoff(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    grid = parse_grid(args.grid, scene.world.dt, joints=bool(scene.joints))
    reference = args.reference or ("analytic" if scene.analytic else "accurate")
    result = measure(
        scene,
        grid,
        reference=reference,
        reference_dt=args.reference_dt,
        duration=args.duration,
        repeats=args.repeats,
        min_seconds=args.min_time,
        progress=not args.quiet and sys.stderr.isatty(),
    )
    stem = Path(args.scene).stem
    csv_path = Path(args.csv or f"{stem}_tradeoff.csv")
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    write_csv(result, csv_path)
    print(
        f"scene {result.scene!r}: {result.duration:.6g} s simulated, compared every "
        f"{result.sample_dt:.6g} s; reference: {result.reference}; cost: median of "
        f"{args.repeats} rounds of timed runs (at least {args.min_time} s each point) after "
        f"a warm-up step"
    )
    print(format_table(result, markdown=args.markdown))
    print(f"wrote {csv_path}")
    if not args.no_plot:
        png_path = Path(args.png or f"{stem}_tradeoff.png")
        png_path.parent.mkdir(parents=True, exist_ok=True)
        second = args.second or ("max_joint_error_m" if result.joints else "max_penetration_m")
        plot(result, png_path, second=second)
        print(f"wrote {png_path}")
    diverged = [r for r in result.rows if r["diverged"]]
    for r in diverged:
        print(f"note: {r['setting']} dt={r['dt']:.6g} stopped: {r['diverged']}", file=sys.stderr)
    return 0
