"""Starting a writer process before the engine is imported, so that its start-up overlaps ours.

Why: a writer process spends most of a short run starting. The Rerun one imports rerun-sdk
(0.37 s here, `python -X importtime`) and builds its recording stream and blueprint (0.1 s);
started once the simulation was built, as `Recorder` used to, a 600-step run was over before
the child was ready, and the whole process waited for it. Started from `isaac run` as soon as
the outputs are claimed, the child imports its libraries while this process imports numpy and
numba and loads the kernels; the two take the two CPUs of a small machine side by side.

This module is light on purpose (standard library only, no numpy, no engine): importing it must
not delay the start it exists to hasten. The child is `python -m recorder.writer_process`, which
imports its writer's libraries at once and only then waits for its configuration (the ring's
size and the scene's tables, which need the engine) on the command pipe; the protocol is in
`recorder.writer_process`.

`start_sender_child` starts the Rerun sender the same way (`recorder.rerun_send`: it imports
rerun-sdk only, and is fed drawn batches through a pipe, with no ring), for ``--offload auto``
and ``thread``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

KINDS = ("mcap", "rerun")
# the Rerun sender (`recorder.rerun_send`): fed drawn batches through a pipe, not a ring
SENDER = "rerun-send"
# the sender's command pipe, enlarged where Linux allows it (F_SETPIPE_SZ): a batch of the
# default scene's drawing is about 0.3 MB, and the pipe's 64 KiB made the parent's writing
# thread wait for the child at every batch
SENDER_PIPE_BYTES = 1 << 20


class WriterChild:
    """A started writer process that has not been given its configuration yet.

    kind: one of KINDS, or SENDER (ring_fd is then -1: it has no ring).
    cmd_fd: the parent's end of the command pipe; reply_fd: the parent's end of the reply pipe.
    ring_fd: the shared memory the frames go through, created empty: the parent sizes it
    (``os.ftruncate``) and maps it once it knows the scene, then tells the child its size in the
    configuration. stderr: the child's standard error (a temporary file, already unlinked).

    (A plain class, not a dataclass: `dataclasses` imports `inspect`, 13-16 ms before the
    Rerun sender could start, on a short recorded run's critical path.)
    """

    __slots__ = ("kind", "proc", "cmd_fd", "reply_fd", "ring_fd", "stderr")

    def __init__(
        self,
        kind: str,
        proc: subprocess.Popen,
        cmd_fd: int,
        reply_fd: int,
        ring_fd: int,
        stderr: object,
    ) -> None:
        self.kind, self.proc, self.stderr = kind, proc, stderr
        self.cmd_fd, self.reply_fd, self.ring_fd = cmd_fd, reply_fd, ring_fd

    def discard(self) -> None:
        """Stop a child that will never be configured: closing the command pipe before the
        configuration makes it exit at once (status 0, no file written)."""
        for fd in (self.cmd_fd, self.reply_fd, self.ring_fd):
            if fd < 0:
                continue
            try:
                os.close(fd)
            except OSError:
                pass
        reap(self.proc, 10)
        self.stderr.close()

    def prepare(self, partial_path: str, recording_id: str, joints: bool, moving: int) -> None:
        """Tell the Rerun sender (kind SENDER) what the scene alone says of the recording
        (`recorder.rerun_send.RerunSender`'s arguments): it makes the stream, its layout and
        static entities as soon as rerun-sdk is imported, while this process still builds the
        model (0.1 s it no longer waits for), and the ``open`` that agrees only adds the
        scales. The command waits in the pipe (`SENDER_PIPE_BYTES`) if the child is still
        importing; the framing is `recorder.rerun_send`'s (length, then a pickle)."""
        import pickle

        args = dict(partial_path=partial_path, recording_id=recording_id, joints=joints)
        body = pickle.dumps(("prepare", (dict(args, moving=moving),)), pickle.HIGHEST_PROTOCOL)
        view = memoryview(len(body).to_bytes(8, "little") + body)
        while view:
            view = view[os.write(self.cmd_fd, view) :]


def _shared_memory() -> int:
    """A file descriptor of (for now, zero bytes of) memory the child can map."""
    if hasattr(os, "memfd_create"):
        return os.memfd_create("isaac-recorder", 0)
    f = tempfile.TemporaryFile()  # pragma: no cover - non-Linux
    fd = os.dup(f.fileno())  # pragma: no cover
    f.close()  # pragma: no cover
    return fd  # pragma: no cover


def _start_python(
    module: str, args: list, pass_fds: tuple[int, ...], child_ends: tuple[int, ...], parent_ends
) -> tuple[subprocess.Popen, object]:
    """``python -m module args...`` with this checkout on its path, ``pass_fds`` passed,
    standard error to an unlinked temporary file, in a process group of its own (Ctrl-C
    reaches the run loop, which closes the files). ``child_ends`` (the child's pipe ends) are
    closed here once it has them; on failure the parent's ends ``parent_ends`` are closed too.
    Returns (the process, its standard error)."""
    stderr = tempfile.TemporaryFile()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    # no BLAS thread pool: a writer never calls BLAS, and the pool's start (its threads spin
    # a while) costs 0.05-0.1 s of CPU beside the run it overlaps (`isaac.tuning`)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", module, *map(str, args)],
            pass_fds=pass_fds,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            env=env,
            process_group=0,
        )
    except BaseException:
        for fd in parent_ends:
            os.close(fd)
        stderr.close()
        raise
    finally:
        for fd in child_ends:
            os.close(fd)
    return proc, stderr


def reap(proc: subprocess.Popen, timeout: float) -> None:
    """Wait for a child that was told to stop; kill it after ``timeout`` s (a stuck child)."""
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:  # pragma: no cover - a stuck child
        proc.kill()
        proc.wait()


def start_writer_child(kind: str, keep_fd: int | None = None) -> WriterChild:
    """Start the writer process of ``kind`` ("mcap" or "rerun"); it begins importing what it
    writes with at once. keep_fd: a descriptor the child keeps open, unused, until it exits
    (the output's lock, `recorder.outputs.OutputClaim.fd`)."""
    if kind not in KINDS:
        raise ValueError(f"writer kind must be one of {KINDS}, got {kind!r}")
    ring_fd = _shared_memory()
    cmd_r, cmd_w = os.pipe()
    rep_r, rep_w = os.pipe()
    keep = () if keep_fd is None else (keep_fd,)
    proc, stderr = _start_python(
        "recorder.writer_process",
        [kind, cmd_r, rep_w, ring_fd],
        pass_fds=(cmd_r, rep_w, ring_fd) + keep,
        child_ends=(cmd_r, rep_w),
        parent_ends=(cmd_w, rep_r, ring_fd),
    )
    return WriterChild(kind, proc, cmd_w, rep_r, ring_fd, stderr)


def start_sender_child(keep_fd: int | None = None) -> WriterChild:
    """Start the Rerun sender process (`recorder.rerun_send`, run as ``python -m``): it imports
    rerun-sdk at once, then reads its command pipe. keep_fd: as for `start_writer_child` (the
    ``.rrd`` output's lock, held until it exits). It needs nothing of the scene to start, so
    `isaac run` starts it before it reads the scene; `WriterChild.prepare` then tells it what
    the scene alone says of the recording."""
    cmd_r, cmd_w = os.pipe()
    rep_r, rep_w = os.pipe()
    try:
        import fcntl

        fcntl.fcntl(cmd_w, getattr(fcntl, "F_SETPIPE_SZ", 1031), SENDER_PIPE_BYTES)
    except (ImportError, OSError):  # pragma: no cover - not Linux, or over pipe-max-size
        pass
    proc, stderr = _start_python(
        "recorder.rerun_send",
        [cmd_r, rep_w],
        pass_fds=(cmd_r, rep_w) + (() if keep_fd is None else (keep_fd,)),
        child_ends=(cmd_r, rep_w),
        parent_ends=(cmd_w, rep_r),
    )
    return WriterChild(SENDER, proc, cmd_w, rep_r, -1, stderr)
