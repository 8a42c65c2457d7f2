"""A run's output files: checked before anything is written, claimed for the run, and never
replacing an earlier run's data.

Every output ``PATH`` is written as ``PATH.partial`` and renamed on close (`recorder.recording`).
Before a run opens it, `claim` makes sure that

- ``PATH`` is not a directory, a FIFO or a device (a rename would replace it; the FIFO's reader
  would get nothing) and ``PATH.partial`` is a regular file or absent (opening a FIFO hangs);
- no other run is writing ``PATH.partial`` now (the lock below), and
- ``PATH.partial`` holds no steps of an earlier run: that is the salvageable part of a run that
  was killed (``isaac recover`` turns it into a clean log), so it is replaced only on request
  (``replace_partial``; ``isaac run --force``). An empty file or a log of no steps is replaced.

`check_distinct` refuses an output that is another output or an input (the scene file), however
spelled: the same real path, or, for files that exist, the same inode.

The lock: ``fcntl.flock(LOCK_EX)`` on the ``.partial`` file itself, held for the whole run.
Why flock and not ``O_CREAT | O_EXCL``: a run killed with SIGKILL leaves its ``.partial``
behind, and that file is the one worth keeping, so "the file exists" cannot mean "a run is
writing it". An flock dies with the last process holding it, so a crashed run never blocks the
next one; and it is held by every process that writes the file: the recorder hands the locked
descriptor to its writer processes (`recorder.writer_process`), so the lock lasts while a writer
finishes the file after the run itself died, and a new run cannot truncate it under the writer.
After taking the lock, the path is checked to still name the locked file (a run that finished
meanwhile renamed it away), else the claim starts again. flock is advisory: it guards against
other ISAAC runs, not against other programs.
"""

from __future__ import annotations

import fcntl
import os
import stat

from isaac.errors import LogError

FORCE_HINT = "pass replace_partial=True to replace it"  # the Python API's word for --force

_KINDS = {
    stat.S_IFDIR: "a directory",
    stat.S_IFIFO: "a FIFO",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
}


def _kind_of(mode: int) -> str:
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")


class OutputClaim:
    """One output claimed for a run: ``partial_path`` is open as ``fd`` and locked (flock).

    kind: "mcap" or "rrd". ``created``: the claim created ``partial_path`` (an empty file), so
    `release` may remove it again when nothing was written.
    """

    def __init__(self, path: str, kind: str, fd: int, created: bool) -> None:
        self.path = path
        self.partial_path = path + ".partial"
        self.kind = kind
        self.fd: int | None = fd
        self.created = created

    def release(self, *, discard: bool = False) -> None:
        """Drop the lock. ``discard``: also remove ``partial_path`` if this claim created it
        and it is still empty (a run that failed before writing anything leaves no file)."""
        if self.fd is None:
            return
        try:
            if discard and self.created:
                try:
                    now, mine = os.stat(self.partial_path), os.fstat(self.fd)
                    if _same_inode(now, mine) and mine.st_size == 0:
                        os.unlink(self.partial_path)
                except OSError:
                    pass
        finally:
            os.close(self.fd)
            self.fd = None


def _same_inode(a: os.stat_result, b: os.stat_result) -> bool:
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def claim(
    path: str, kind: str, *, replace_partial: bool = False, force_hint: str = FORCE_HINT
) -> OutputClaim:
    """Claim output ``path`` (kind "mcap" or "rrd") for a run; LogError, in one line naming the
    file, when it cannot be written or must not be replaced (see the module docstring).

    force_hint: how the caller's user asks to replace an earlier run's ``.partial`` (the end of
        the refusal's message).
    """
    path = str(path)
    partial = path + ".partial"
    try:
        st = os.stat(path)
    except FileNotFoundError:
        pass  # absent, or a dangling symlink (the rename replaces the link)
    except OSError as exc:
        raise LogError(f"cannot write {path}: {exc.strerror}") from exc
    else:
        if not stat.S_ISREG(st.st_mode):
            raise LogError(f"cannot write {path}: it is {_kind_of(st.st_mode)}, not a file")
    while True:
        fd, created = _open_partial(partial)
        try:
            mine = os.fstat(fd)
            if not stat.S_ISREG(mine.st_mode):
                what = _kind_of(mine.st_mode)
                raise LogError(f"cannot write {partial}: it is {what}, not a file")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise LogError(
                    f"{partial} is being written by another run now (or by a writer process "
                    f"finishing it): wait for it to end or record to another file"
                ) from None
            except OSError as exc:
                raise LogError(f"cannot lock {partial}: {exc.strerror}") from exc
            try:
                now = os.stat(partial)
            except FileNotFoundError:
                now = None
            if now is None or not _same_inode(now, mine):
                os.close(fd)  # renamed or replaced by the run that held it: claim again
                continue
            if not replace_partial and mine.st_size > 0:
                _refuse_earlier_run(path, kind, force_hint)
        except BaseException:
            os.close(fd)
            raise
        return OutputClaim(path, kind, fd, created)


def _open_partial(partial: str) -> tuple[int, bool]:
    """``partial`` opened for writing without truncating it (created if absent), and whether it
    was created. O_NONBLOCK: opening a FIFO must not wait for a reader (it is refused)."""
    flags = os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC
    while True:
        try:
            return os.open(partial, flags | os.O_CREAT | os.O_EXCL, 0o666), True
        except FileExistsError:
            pass
        except OSError as exc:
            raise LogError(f"cannot write {partial}: {exc.strerror}") from exc
        try:
            return os.open(partial, flags), False
        except FileNotFoundError:
            continue  # removed between the two opens
        except OSError as exc:
            raise LogError(f"cannot write {partial}: {exc.strerror}") from exc


def _refuse_earlier_run(path: str, kind: str, force_hint: str) -> None:
    """LogError unless ``path``.partial holds no step of an earlier run."""
    partial = path + ".partial"
    steps = mcap_steps(partial) if kind == "mcap" else rrd_steps(partial)
    if steps == 0:
        return
    if kind == "mcap":
        if steps is None:
            raise LogError(
                f"{partial} holds data that is not a readable ISAAC log: move it away first "
                f"or {force_hint}"
            )
        # recovered under another name: a run to ``path`` would replace the recovered log
        stem, ext = os.path.splitext(path)
        raise LogError(
            f"{partial} holds {steps} steps of an earlier run: recover it first "
            f"(isaac recover {partial} {stem}.recovered{ext or '.mcap'}, then remove it) "
            f"or {force_hint}"
        )
    what = f"{steps} steps" if steps is not None else "an unfinished recording"
    raise LogError(f"{partial} holds {what} of an earlier run: move it away first or {force_hint}")


def mcap_steps(path: str) -> int | None:
    """Steps readable in the MCAP log ``path`` (complete or not), None if it is not a readable
    ISAAC log. A step counts when its ``/stats`` message is there: the last of its messages."""
    from recorder.reader import LogReader

    steps = 0
    try:
        for _ in LogReader(path).messages("/stats"):
            steps += 1
    except Exception:  # noqa: BLE001 - not a log, or damaged after the steps read so far
        return steps or None
    return steps


def rrd_steps(path: str) -> int | None:
    """Steps in the Rerun recording ``path``, None when it cannot be read (a recording cut short
    is not readable as a whole)."""
    import warnings

    try:
        from rerun.chunk import RrdReader

        steps: set[int] = set()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer": a recording that was not finished
            for chunk in RrdReader(path).stream():
                batch = chunk.to_record_batch()
                if "step" in batch.schema.names:
                    steps.update(batch.column("step").to_pylist())
        return len(steps)
    except Exception:  # noqa: BLE001 - whatever the Rerun reader raises: not readable
        return None


def check_distinct(outputs: dict[str, str], inputs: dict[str, str] | None = None) -> None:
    """LogError when two outputs (or an output's ``.partial``) are one file, or an output is an
    input: the same real path (symlinks resolved) or, when both exist, the same file.

    outputs, inputs: {label: path}, the labels as the user knows them ("--mcap", "scene file").
    """
    files = []  # (label, path, the output it belongs to or None for an input)
    for label, path in outputs.items():
        files.append((label, str(path), label))
        files.append((f"{label}'s temporary file", str(path) + ".partial", label))
    for label, path in (inputs or {}).items():
        files.append((label, str(path), None))
    for i, (label_a, a, owner_a) in enumerate(files):
        for label_b, b, owner_b in files[i + 1 :]:
            if owner_a is None and owner_b is None:
                continue  # two inputs may well be one file
            if owner_a is not None and owner_a == owner_b:
                continue  # an output and its own .partial
            if not same_file(a, b):
                continue
            if owner_a is not None and owner_b is not None:
                raise LogError(
                    f"{label_b} {b} is the same file as {label_a} {a}: each output needs a "
                    f"file of its own"
                )
            out_label, out, in_label, inp = (
                (label_b, b, label_a, a) if owner_a is None else (label_a, a, label_b, b)
            )
            raise LogError(
                f"{out_label} {out} is the {in_label} {inp}: recording there would overwrite it"
            )


def same_file(a: str, b: str) -> bool:
    """True when paths ``a`` and ``b`` name one file (resolved symlinks, or one inode)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False
