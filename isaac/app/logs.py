"""The recorder's sub-commands: ``isaac inspect``, ``isaac view``, ``isaac recover``.

A damaged log (a chunk whose CRC fails, a missing or repeated step, a summary that disagrees with
the data: `recorder.integrity`) is read up to the damage; ``inspect`` prints a ``damaged:`` line
naming the first damaged or missing step (or byte), ``recover`` says what it could not salvage.
A path that is not a regular file, or a log whose header or messages are malformed, is a
one-line error (exit status 2).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from isaac.errors import LogError


def register(subparsers) -> None:
    p = subparsers.add_parser("inspect", help="summarise an MCAP log (or list one step's contacts)")
    p.add_argument("log", help="LOG.mcap (a .partial file from a killed run works too)")
    p.add_argument("--step", type=int, metavar="K", help="print every contact of step K")
    p.set_defaults(func=cmd_inspect)

    v = subparsers.add_parser("view", help="open a recording in the Rerun viewer")
    v.add_argument("log", help="LOG.rrd, or LOG.mcap (converted on the fly)")
    v.add_argument("--web", action="store_true", help="serve the web viewer on localhost instead")
    v.add_argument("--port", type=int, default=None, help="web viewer port (with --web)")
    v.add_argument("--dry-run", action="store_true", help=argparse.SUPPRESS)
    v.set_defaults(func=cmd_view)

    r = subparsers.add_parser("recover", help="rewrite an unfinished log as a clean, indexed MCAP")
    r.add_argument("log", help="LOG.mcap.partial (or any damaged ISAAC log)")
    r.add_argument("out", help="OUT.mcap")
    r.set_defaults(func=cmd_recover)


def _g(x: float) -> str:
    return f"{x:.6g}"


def cmd_inspect(args: argparse.Namespace) -> int:
    try:
        return _inspect(args)
    except BrokenPipeError:
        # output piped into `head` and the like: stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0


def _inspect(args: argparse.Namespace) -> int:
    from recorder.reader import LogReader

    log = LogReader(args.log)
    if args.step is not None:
        return _print_step(log, args.step)
    meta = log.metadata
    s = log.summary()
    world = log.world
    n = len(world.names)
    concrete = int(world.concrete.sum())
    w = log.settings
    print(f"log      {args.log}")
    print(
        f"scene    {meta.get('scene_name', '?')} (sha256 {meta.get('scene_sha256', '?')[:16]}...)"
    )
    print(
        f"versions isaac {meta.get('engine_version')}, Python {meta.get('python_version')}, "
        f"numpy {meta.get('numpy_version')}, numba {meta.get('numba_version')}"
    )
    print(f"machine  {meta.get('platform')} ({meta.get('cpu')})")
    print(
        f"settings fidelity {w.get('fidelity')}, dt {w.get('dt')} s, gravity {w.get('gravity')}, "
        f"integrator {w.get('integrator')}, solver {w.get('solver')}"
    )
    changes = max(s.world_changes - 1, 0)
    print(f"bodies   {n} ({concrete} concrete); bodies entered or left at {changes} step(s)")
    claimed = log.claimed_steps
    of = f" of the {claimed} the log claims" if claimed is not None and claimed != s.steps else ""
    if s.steps:
        print(
            f"steps    {s.steps}{of} (step {s.first_step} to {s.last_step}, "
            f"t = {_g(s.first_step * log.dt)} to {_g(s.last_step * log.dt)} s)"
        )
    else:
        print(f"steps    0{of}")
    depth = f"{_g(s.max_depth)} m (step {s.max_depth_step})" if s.contacts else "-"
    impulse = f"{_g(s.max_impulse)} N s (step {s.max_impulse_step})" if s.contacts else "-"
    print(f"contacts {s.contacts} in all; max depth {depth}; largest impulse {impulse}")
    if s.energy_start is not None:
        print(
            f"energy   start {_g(s.energy_start)} J, end {_g(s.energy_end)} J (kinetic + potential)"
        )
    end = log.end
    damage = log.damage
    if damage is not None:
        print(f"damaged: from {damage.at()}: {damage}")
    last = s.last_step if s.steps else "none"
    recover_hint = f"`isaac recover {args.log} OUT.mcap` writes a clean copy"
    if damage is not None and log.closed_cleanly:
        state = f"closed, but damaged (above); readable up to step {last}; {recover_hint}"
    elif log.closed_cleanly and end is not None:
        if end.get("complete") == "true":
            state = "closed cleanly; run complete"
        else:
            state = f"closed cleanly; run stopped at step {end.get('stopped_at') or '?'}" + (
                f": {end['reason']}" if end.get("reason") else ""
            )
    else:
        state = f"NOT closed (unfinished or damaged); readable up to step {last}; {recover_hint}"
    print(f"file     {state}")
    return 0


_COLUMNS = (
    "row",
    "sub",
    "a",
    "b",
    "slot",
    "feature",
    "point_x",
    "point_y",
    "normal_x",
    "normal_y",
    "depth",
    "push_a_x",
    "push_a_y",
    "push_b_x",
    "push_b_y",
    "impulse",
    "tangent_imp",
    "e",
)


def _print_step(log, k: int) -> int:
    logged = log.step(k)
    r, c = logged.record, logged.record.contacts
    names = logged.world.names
    print(f"step {k}, t = {_g(r.time)} s: {len(c)} contact(s)")
    if logged.stats is not None:
        st = logged.stats
        print(
            f"  kinetic {_g(st['kinetic_energy'])} J, potential {_g(st['potential_energy'])} J, "
            f"state hash {st['state_hash'][:16]}..."
        )
    if not len(c):
        return 0
    rows = []
    for i in range(len(c)):
        a, b = int(c.a[i]), int(c.b[i])
        rows.append(
            (
                str(i),
                str(int(c.substep[i])),
                f"{a}:{names[a]}",
                f"{b}:{names[b]}",
                str(int(c.slot[i])),
                str(int(c.feature[i])),
                _g(c.point[i, 0]),
                _g(c.point[i, 1]),
                _g(c.normal[i, 0]),
                _g(c.normal[i, 1]),
                _g(c.depth[i]),
                _g(c.push_a[i, 0]),
                _g(c.push_a[i, 1]),
                _g(c.push_b[i, 0]),
                _g(c.push_b[i, 1]),
                _g(c.impulse[i]),
                _g(c.tangent_impulse[i]),
                _g(c.restitution[i]),
            )
        )
    widths = [max(len(h), *(len(row[j]) for row in rows)) for j, h in enumerate(_COLUMNS)]
    print("  ".join(h.rjust(wd) for h, wd in zip(_COLUMNS, widths)))
    for row in rows:
        print("  ".join(x.rjust(wd) for x, wd in zip(row, widths)))
    print("units: m (point, depth, push), N s (impulse, tangent_imp); normal from a to b")
    return 0


def cmd_recover(args: argparse.Namespace) -> int:
    from recorder.reader import recover

    if os.path.abspath(args.log) == os.path.abspath(args.out):
        raise LogError("the output must be a different file from the input")
    done = recover(args.log, args.out)
    kept, last, lost = done.kept, done.last, done.lost
    print(
        f"recovered {kept} step(s)"
        + ("" if last is None else f" (up to step {last})")
        + f" into {args.out}"
    )
    if lost:
        print(f"could not salvage: {lost}")
    return 0


def _rerun_executable() -> str:
    here = Path(sys.executable).parent / "rerun"
    if here.exists():
        return str(here)
    found = shutil.which("rerun")
    if found is None:
        raise LogError("the Rerun viewer (`rerun`, from rerun-sdk) is not installed")
    return found


def cmd_view(args: argparse.Namespace) -> int:
    from recorder.mcap_records import check_regular

    path = args.log
    if not os.path.exists(path):
        raise LogError(f"{path}: no such file")
    check_regular(path)  # a FIFO or a device would never end
    tmpdir = None
    if path.endswith(".mcap") or path.endswith(".mcap.partial"):
        from recorder.rerun_writer import mcap_to_rrd

        tmpdir = tempfile.mkdtemp(prefix="isaac-view-")
        rrd = os.path.join(tmpdir, Path(path).name.split(".mcap")[0] + ".rrd")
        mcap_to_rrd(path, rrd)
        path = rrd
    command = [_rerun_executable()]
    if args.web:
        command += ["--serve-web", "--bind", "127.0.0.1"]
        if args.port:
            command += ["--web-viewer-port", str(args.port)]
    command.append(path)
    if args.dry_run:
        print(" ".join(command))
        return 0
    try:
        return subprocess.call(command)
    finally:
        if tmpdir is not None:
            shutil.rmtree(tmpdir, ignore_errors=True)
