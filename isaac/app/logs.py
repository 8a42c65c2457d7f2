"""The recorder's sub-commands: ``isaac inspect``, ``isaac view``, ``isaac recover``.

A damaged log (a chunk whose CRC fails, a missing or repeated step, a summary that disagrees with
the data: `recorder.integrity`) is read up to the damage; ``inspect`` prints a ``damaged:`` line
naming the first damaged or missing step (or byte), ``recover`` says what it could not salvage.
A path that is not a regular file, or a log whose header or messages are malformed, is a
one-line error (exit status 2).
"""

from __future__ import annotations

import argparse
import csv
import difflib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from isaac.app.options import integer, ip_address, port, url_host
from isaac.errors import LogError


def register(subparsers) -> None:
    p = subparsers.add_parser("inspect", help="summarise an MCAP log (or list one step's contacts)")
    p.add_argument("log", help="LOG.mcap (a .partial file from a killed run works too)")
    p.add_argument(
        "--step", type=integer(minimum=0), metavar="K", help="print every contact of step K"
    )
    p.add_argument(
        "--body", metavar="NAME", help="with --step: only the contacts of this body (a or b)"
    )
    p.add_argument(
        "--format",
        choices=("table", "csv", "json"),
        default="table",
        help="with --step: an aligned table (default), CSV (a header row, then one row a "
        "contact) or JSON (the step's record, stats and contact rows)",
    )
    p.set_defaults(func=cmd_inspect)

    v = subparsers.add_parser("view", help="open a recording in the Rerun viewer")
    v.add_argument(
        "log",
        help="LOG.rrd, or LOG.mcap (converted once; the copy LOG.mcap.rrd is reused while "
        "the log is unchanged)",
    )
    v.add_argument(
        "--web",
        action="store_true",
        help="serve the web viewer and print its URL (the default without a display)",
    )
    v.add_argument(
        "--bind",
        type=ip_address,
        default="127.0.0.1",
        metavar="ADDR",
        help="IP address the viewer's servers listen on (default 127.0.0.1: this machine only; "
        "localhost is 127.0.0.1)",
    )
    v.add_argument(
        "--port", type=port, help="web viewer HTTP port, 1-65535 (default or 0: a free one)"
    )
    v.add_argument(
        "--grpc-port",
        type=port,
        help="the viewer's gRPC server port, 1-65535 (default or 0: a free one)",
    )
    v.add_argument(
        "--fresh", action="store_true", help="convert a .mcap again, even if its copy is current"
    )
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
        return _print_step(log, args.step, body=args.body, form=args.format)
    if args.body is not None or args.format != "table":
        raise LogError("--body and --format go with --step K")
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
        f"versions isaac {meta.get('engine_version')}, "
        f"physics {meta.get('physics_version') or '1 (not recorded)'}, "
        f"Python {meta.get('python_version')}, "
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
    joints = log.world.joints if s.steps else ()
    if joints:
        kinds = {}
        for j in joints:
            kinds[j["type"]] = kinds.get(j["type"], 0) + 1
        mix = ", ".join(f"{count} {kind}" for kind, count in kinds.items())
        worst = (
            f"; largest error {_g(s.max_joint_error)} m "
            f"({joints[s.max_joint_error_joint]['name']!r}, step {s.max_joint_error_step})"
            if s.max_joint_error_step is not None
            else ""
        )
        print(f"joints   {len(joints)} ({mix}){worst}")
    if s.energy_start is not None:
        print(
            f"energy   start {_g(s.energy_start)} J, end {_g(s.energy_end)} J (kinetic + potential)"
        )
    if s.energy_check is not None:
        print(f"         {s.energy_check.summary()}")
        if s.energy_check.flagged:
            print(f"isaac inspect: warning: {s.energy_check.warning()}", file=sys.stderr)
    end = log.end
    damage = log.damage
    if damage is not None:
        print(f"damaged: from {damage.at()}: {damage}")
    last = s.last_step if s.steps else "none"
    recover_hint = f"`isaac recover {args.log} OUT.mcap` writes a clean copy"
    # "stopped at step K": K is the last step whose state is in the log, as `isaac run` and
    # `isaac recover` say it
    stopped_at = f"stopped at step {last}, the last step in the log" if s.steps else "no step"
    if damage is not None and log.closed_cleanly:
        state = f"closed, but damaged (above); readable up to step {last}; {recover_hint}"
    elif log.closed_cleanly and end is not None:
        if end.get("complete") == "true":
            state = "closed cleanly; run complete"
        else:
            reason = end.get("reason") or "the run did not complete"
            state = f"closed cleanly; {_run_did(reason)}; {stopped_at}"
    else:
        state = f"NOT closed (unfinished or damaged); {stopped_at}; {recover_hint}"
    print(f"file     {state}")
    return 0


# one row per contact point; m and the columns up to push_b_y are its manifold's (the pair's,
# stored once per manifold in the log), the rest the point's own
_COLUMNS = (
    "row",
    "m",
    "sub",
    "a",
    "b",
    "slot",
    "feature",
    "normal_x",
    "normal_y",
    "pair_depth",
    "push_a_x",
    "push_a_y",
    "push_b_x",
    "push_b_y",
    "point_x",
    "point_y",
    "point_depth",
    "impulse",
    "tangent_imp",
    "e",
)


def _logged_step(log, k: int):
    """Step k of the log; a step it does not hold is one line naming the steps it does."""
    try:
        return log.step(k)
    except LogError as exc:
        if "is not in the log" not in str(exc):
            raise
        s = log.summary()
        held = (
            "no complete step" if s.first_step is None else (f"steps {s.first_step}..{s.last_step}")
        )
        raise LogError(f"{log.path}: step {k} is not in the log (it holds {held})") from None


def _manifolds(c):
    """Each contact row's manifold (its index among the step's manifolds, as the log stores
    them: a manifold begins at slot 0)."""
    import numpy as np

    return np.cumsum(np.asarray(c.slot) == 0) - 1


def _contact_rows(c, names, keep) -> list[tuple[str, ...]]:
    """The table's rows (`_COLUMNS`) of the contact rows ``keep``."""
    rows = []
    manifold = _manifolds(c)
    for i in keep:
        a, b = int(c.a[i]), int(c.b[i])
        rows.append(
            (
                str(i),
                str(int(manifold[i])),
                str(int(c.substep[i])),
                f"{a}:{names[a]}",
                f"{b}:{names[b]}",
                str(int(c.slot[i])),
                str(int(c.feature[i])),
                _g(c.normal[i, 0]),
                _g(c.normal[i, 1]),
                _g(c.pair_depth[i]),
                _g(c.push_a[i, 0]),
                _g(c.push_a[i, 1]),
                _g(c.push_b[i, 0]),
                _g(c.push_b[i, 1]),
                _g(c.point[i, 0]),
                _g(c.point[i, 1]),
                _g(c.depth[i]),
                _g(c.impulse[i]),
                _g(c.tangent_impulse[i]),
                _g(c.restitution[i]),
            )
        )
    return rows


def _print_step(log, k: int, *, body: str | None = None, form: str = "table") -> int:
    logged = _logged_step(log, k)
    r, c = logged.record, logged.record.contacts
    names = logged.world.names
    keep = range(len(c))
    if body is not None:
        if body not in names:
            close = difflib.get_close_matches(body, [str(x) for x in names], n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise LogError(f"{log.path}: no body named {body!r} in the log{hint}")
        index = list(names).index(body)
        keep = [i for i in keep if int(c.a[i]) == index or int(c.b[i]) == index]
    if form == "json":
        return _print_step_json(logged, names, keep)
    rows = _contact_rows(c, names, keep)
    if form == "csv":
        out = csv.writer(sys.stdout, lineterminator="\n")
        out.writerow(_COLUMNS)
        out.writerows(rows)
        return 0
    which = "" if body is None else f" of {body!r}"
    print(f"step {k}, t = {_g(r.time)} s: {len(rows)} contact(s){which}")
    if logged.stats is not None:
        st = logged.stats
        print(
            f"  kinetic {_g(st['kinetic_energy'])} J, potential {_g(st['potential_energy'])} J, "
            f"state hash {st['state_hash'][:16]}..."
        )
    if rows:
        _print_table(_COLUMNS, rows)
        print(
            "units: m (point, depths, push), N s (impulse, tangent_imp); normal from a to b; "
            "pair_depth: the pair's MTD, point_depth: the point's own penetration"
        )
    if logged.world.joints and r.joints is not None:
        print(f"{len(logged.world.joints)} joint(s):")
        _print_table(_JOINT_COLUMNS, _joint_rows(logged.world.joints, r.joints, names))
        print(
            "units: m, world (anchors, error_m); N s, world, on b (lin_imp; a takes minus it); "
            "N m s or N s (ang_imp, motor_imp, limit_imp); rad (error_rad)"
        )
    return 0


def _print_table(columns, rows) -> None:
    widths = [max(len(h), *(len(row[j]) for row in rows)) for j, h in enumerate(columns)]
    print("  ".join(h.rjust(wd) for h, wd in zip(columns, widths)))
    for row in rows:
        print("  ".join(x.rjust(wd) for x, wd in zip(row, widths)))


_JOINT_COLUMNS = (
    "joint",
    "type",
    "a",
    "b",
    "anchor_a_x",
    "anchor_a_y",
    "anchor_b_x",
    "anchor_b_y",
    "lin_imp_x",
    "lin_imp_y",
    "ang_imp",
    "motor_imp",
    "limit_imp",
    "error_m",
    "error_rad",
)


def _joint_rows(table, j, names) -> list[tuple[str, ...]]:
    """The joints table's rows (`_JOINT_COLUMNS`): the /world joint table beside the step's
    /joints values."""
    rows = []
    for i, spec in enumerate(table):
        a, b = int(spec["a"]), int(spec["b"])
        rows.append(
            (
                str(spec["name"]),
                str(spec["type"]),
                f"{a}:{names[a]}",
                f"{b}:{names[b]}",
                _g(j.anchor_a[i, 0]),
                _g(j.anchor_a[i, 1]),
                _g(j.anchor_b[i, 0]),
                _g(j.anchor_b[i, 1]),
                _g(j.linear_impulse[i, 0]),
                _g(j.linear_impulse[i, 1]),
                _g(j.angular_impulse[i]),
                _g(j.motor_impulse[i]),
                _g(j.limit_impulse[i]),
                _g(j.error[i, 0]),
                _g(j.error[i, 1]),
            )
        )
    return rows


def _print_step_json(logged, names, keep) -> int:
    """The step as JSON: exact floats (repr round-trips float64), SI units as in the log."""
    r, c = logged.record, logged.record.contacts
    keep = list(keep)

    def rows(a):
        return a[keep].tolist()

    out = {
        "step": int(r.step),
        "time_s": float(r.time),
        "stats": logged.stats,
        "bodies": {
            "name": [str(x) for x in names],
            "position_m": r.position.tolist(),
            "angle_rad": r.angle.tolist(),
            "velocity_mps": r.velocity.tolist(),
            "angular_velocity_radps": r.angular_velocity.tolist(),
            "exists": r.exists.tolist(),
        },
        "contacts": {
            "row": keep,
            "manifold": rows(_manifolds(c)),
            "substep": rows(c.substep),
            "a": rows(c.a),
            "b": rows(c.b),
            "slot": rows(c.slot),
            "feature": rows(c.feature),
            "point_m": rows(c.point),
            "normal": rows(c.normal),
            "pair_depth_m": [None if x != x else x for x in rows(c.pair_depth)],
            "point_depth_m": rows(c.depth),
            "push_a_m": rows(c.push_a),
            "push_b_m": rows(c.push_b),
            "impulse_Ns": rows(c.impulse),
            "tangent_impulse_Ns": rows(c.tangent_impulse),
            "restitution": rows(c.restitution),
        },
    }
    if logged.world.joints and r.joints is not None:
        j = r.joints
        out["joints"] = {
            "name": [str(x["name"]) for x in logged.world.joints],
            "type": [str(x["type"]) for x in logged.world.joints],
            "a": [int(x["a"]) for x in logged.world.joints],
            "b": [int(x["b"]) for x in logged.world.joints],
            "anchor_a_m": j.anchor_a.tolist(),
            "anchor_b_m": j.anchor_b.tolist(),
            "linear_impulse_Ns": j.linear_impulse.tolist(),
            "angular_impulse": j.angular_impulse.tolist(),
            "motor_impulse": j.motor_impulse.tolist(),
            "limit_impulse": j.limit_impulse.tolist(),
            "error": j.error.tolist(),
            "impulses": j.impulses.tolist(),
        }
    json.dump(out, sys.stdout, allow_nan=False)
    sys.stdout.write("\n")
    return 0


def _run_did(reason: str) -> str:
    """What the log's end record says of its run, for `inspect`: "run interrupted by SIGINT",
    "run did not complete: step 58: body ..."."""
    if reason.startswith("interrupted"):
        return f"run {reason}"
    return f"run did not complete: {reason}"


def cmd_recover(args: argparse.Namespace) -> int:
    from recorder.reader import recover

    if os.path.abspath(args.log) == os.path.abspath(args.out):
        raise LogError("the output must be a different file from the input")
    done = recover(args.log, args.out)
    kept, last, lost = done.kept, done.last, done.lost
    print(
        f"recovered {kept} step(s) into {args.out}"
        + ("" if last is None else f": stopped at step {last}, the last step in the log")
    )
    if lost:
        print(f"could not salvage: {lost}")
    if done.restated:
        print(f"rewrote the metadata from the embedded scene: {done.restated}")
    return 0


def rerun_executable() -> str:
    """The Rerun viewer binary itself. Not the ``rerun`` script beside this Python: that is a
    Python process that runs the binary as its child, and stopping it left the viewer serving
    (seen: orphaned ``rerun --serve-web`` processes after SIGTERM)."""
    try:
        import rerun_cli

        here = Path(os.environ.get("RERUN_CLI_PATH") or Path(rerun_cli.__file__).parent / "rerun")
        if sys.platform == "darwin" and "RERUN_CLI_PATH" not in os.environ:
            bundled = here.parent / "Rerun.app" / "Contents" / "MacOS" / "Rerun"
            here = bundled if bundled.exists() else here
        if sys.platform.startswith("win"):
            here = here.with_suffix(".exe")
        if here.exists():
            return str(here)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise LogError("the Rerun viewer (`rerun`, from rerun-sdk) is not installed")
    return found


def _has_display() -> bool:
    """Whether a native window can open: on Linux an X11 or Wayland display must be named
    (without one, the native viewer dies with a raw winit error); elsewhere, a desktop."""
    if not sys.platform.startswith("linux"):
        return True
    return any(os.environ.get(k) for k in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"))


def _ports(bind: str, wanted: dict[str, int | None]) -> dict[str, int]:
    """The port of each option in ``wanted`` (``{"--grpc-port": 9877, "--port": None}``): the
    one given, checked free on ``bind`` now, or a free one (the kernel's choice) for None or 0;
    all held at once, so no two are the same. LogError (exit 2), before the viewer starts, in
    one line: an address not of this machine (``--bind``), a port in use or not allowed to
    this user, two options given one port."""
    import errno
    import socket

    given = [p for p in wanted.values() if p]
    if len(set(given)) < len(given):
        raise LogError(" and ".join(wanted) + f" must differ, got {given[0]} for both")
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    found, held = {}, []
    try:
        for option, port in wanted.items():
            s = socket.socket(family, socket.SOCK_STREAM)
            held.append(s)
            # as the viewer's own listeners do: a port left in TIME_WAIT is free
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((bind, port or 0))
            except OSError as exc:
                if port and exc.errno in (errno.EADDRINUSE, errno.EACCES):
                    raise LogError(
                        f"{option} {port}: cannot listen on {bind}: {exc.strerror}"
                    ) from None
                raise LogError(
                    f"--bind {bind}: cannot listen on it (an address of this machine, 127.0.0.1, "
                    f"0.0.0.0 or ::): {exc.strerror or exc}"
                ) from None
            found[option] = s.getsockname()[1]
    finally:
        for s in held:
            s.close()
    return found


# The watchdog of `isaac view`'s viewer, in the viewer's process group: it reads its stdin, a
# pipe whose writing end `isaac view` alone holds, until end of file, which comes when `isaac
# view` ends in any way (SIGKILL included: the kernel closes its files), and then kills its
# process group, the viewer and whatever the viewer started. Signals to the group (the
# clean-up's SIGTERM) leave it running, so that it outlives the viewer it watches.
_WATCHDOG = (
    "import os, signal\n"
    "for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):\n"
    "    signal.signal(s, signal.SIG_IGN)\n"
    "while os.read(0, 512):\n"
    "    pass\n"
    "os.killpg(0, signal.SIGKILL)\n"
)


def _start_watchdog() -> tuple[subprocess.Popen, int]:
    """(the watchdog, the pipe's writing end): the watchdog leads a new process group, which
    the viewer is then started into (`cmd_view`); closing the writing end, or this process
    ending, kills the group."""
    read_end, write_end = os.pipe()  # neither is inherited by the viewer (O_CLOEXEC)
    try:
        watchdog = subprocess.Popen(
            [sys.executable, "-I", "-S", "-c", _WATCHDOG],
            stdin=read_end,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            process_group=0,
        )
    except BaseException:
        os.close(write_end)
        raise
    finally:
        os.close(read_end)
    return watchdog, write_end


def _listening(host: str, port: int) -> bool:
    import socket

    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


class _Stopped(Exception):
    """SIGTERM or SIGHUP arrived: the viewer is stopped and the temporary files go."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _stop(signum, frame) -> None:
    raise _Stopped(signum)


def view_copy_path(log: str) -> str:
    """Where ``isaac view LOG.mcap`` keeps its Rerun copy of the log: next to it."""
    return log + ".rrd"


def _viewable(path: str, *, fresh: bool, tmpdir: str) -> str:
    """The .rrd to show for ``path``: itself, or a .mcap's Rerun copy.

    A closed log's copy (``LOG.mcap.rrd``) is kept and reused while its modification time is
    the log's own (it is set so when written; the 600-step, 66-body default log took 4-6 s
    to convert on a loaded 2-core machine, a reused copy no time). A ``.partial`` log (still
    growing, or left by a killed run), or a log in a directory this user cannot write, is
    converted into ``tmpdir``, removed when the viewer stops.
    """
    if not (path.endswith(".mcap") or path.endswith(".mcap.partial")):
        return path
    source = os.stat(path)
    copy = view_copy_path(path)
    keep = path.endswith(".mcap") and os.access(os.path.dirname(os.path.abspath(path)), os.W_OK)
    if not keep:
        copy = os.path.join(tmpdir, Path(path).name.split(".mcap")[0] + ".rrd")
    elif not fresh and os.path.exists(copy) and os.stat(copy).st_mtime_ns == source.st_mtime_ns:
        return copy
    from recorder.rerun_writer import mcap_to_rrd  # rerun and numba: only when converting

    try:
        mcap_to_rrd(path, copy)
    except BaseException:
        # a signal or an error mid-way: no half-written copy stays behind
        for leftover in (copy + ".partial", copy):
            if keep and os.path.exists(leftover):
                os.remove(leftover)
        raise
    if keep:
        os.utime(copy, ns=(source.st_atime_ns, source.st_mtime_ns))
    return copy


def cmd_view(args: argparse.Namespace) -> int:
    """Open the viewer; return when it is closed or on Ctrl-C, SIGTERM or SIGHUP, having
    stopped the viewer process started here and removed the temporary files."""
    from recorder.mcap_records import check_regular

    path = args.log
    if not os.path.exists(path):
        raise LogError(f"{path}: no such file")
    check_regular(path)  # a FIFO or a device would never end
    signals = (signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, _stop) for sig in signals}
    tmpdir = tempfile.mkdtemp(prefix="isaac-view-")
    proc = watchdog = watch_end = None
    try:
        web = args.web or not _has_display()
        bind = args.bind  # an IP address (isaac.app.options.ip_address)
        # before converting and before the viewer starts: the viewer's own refusal of an
        # address or port is a usage text, or a viewer that never listens
        ports = _ports(bind, {"--grpc-port": args.grpc_port, "--port": args.port if web else None})
        grpc_port, http_port = ports["--grpc-port"], ports["--port"]
        rrd = _viewable(path, fresh=args.fresh, tmpdir=tmpdir)
        if web and not args.web and not args.dry_run:
            print(
                "isaac view: no display (DISPLAY and WAYLAND_DISPLAY unset): serving the web "
                "viewer instead (as with --web)",
                file=sys.stderr,
            )
        command = [rerun_executable(), "--bind", bind, "--port", str(grpc_port)]
        if web:
            command += ["--serve-web", "--web-viewer-port", str(http_port)]
        command.append(rrd)
        if args.dry_run:
            print(" ".join(command))
            return 0
        # the viewer's own chatter (a first-run banner, INFO lines) goes to a file: shown only
        # if it fails
        out_path = os.path.join(tmpdir, "rerun.out")
        watchdog, watch_end = _start_watchdog()
        with open(out_path, "wb") as out:
            # in the watchdog's process group, not this one: a Ctrl-C reaches this process,
            # which stops the viewer; this process killed, the watchdog kills the group
            proc = subprocess.Popen(
                command,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                process_group=watchdog.pid,
            )
        if web:
            # every interface: the URL names this machine's loopback address of that family
            host = {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(bind, bind)
            while proc.poll() is None and not (
                _listening(host, http_port) and _listening(host, grpc_port)
            ):
                time.sleep(0.1)
            if proc.poll() is None:
                from urllib.parse import quote

                proxy = quote(f"rerun+http://{url_host(host)}:{grpc_port}/proxy", safe="")
                print(f"http://{url_host(host)}:{http_port}/?url={proxy}", flush=True)
                print("isaac view: open the URL above; Ctrl-C stops the viewer", file=sys.stderr)
        status = proc.wait()
        if status != 0:
            with open(out_path, errors="replace") as f:
                lines = [x.strip() for x in f if x.strip()]
            said = lines[-1] if lines else "no output"
            hint = "" if web else " (without a display, use --web)"
            print(
                f"isaac view: the viewer exited with status {status}: {said}{hint}", file=sys.stderr
            )
        return status
    except KeyboardInterrupt:
        return 130
    except _Stopped as stopped:
        return 128 + stopped.signum
    finally:
        # the cleanup runs to its end: a second signal now would leave the viewer or the files
        interrupt = signal.signal(signal.SIGINT, signal.SIG_IGN)
        for sig in signals:
            signal.signal(sig, signal.SIG_IGN)
        try:
            if proc is not None and proc.poll() is None:
                # the watchdog's process group: the viewer and anything it started
                os.killpg(watchdog.pid, signal.SIGTERM)
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(watchdog.pid, signal.SIGKILL)
                    proc.wait()
        finally:
            if watch_end is not None:
                os.close(watch_end)  # the watchdog kills what is left of the group, and itself
                watchdog.wait()
            shutil.rmtree(tmpdir, ignore_errors=True)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            signal.signal(signal.SIGINT, interrupt)
