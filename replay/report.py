"""The result of a replay or a diff: a report, never an exception.

`Report` holds what was compared and every divergence found (bounded); `format_text` renders the
one-line verdict (and the divergence details) for the terminal, `to_json` the same for machines.

The verdict (`Report.verdict`, docs/replay.md):
- ``identical`` (exit 0): every step the log claims was there, whole and intact, and was
  compared (at least one step), and no difference was found;
- ``diverged`` (exit 1): a compared step differs;
- ``damaged`` (exit 1): no difference in the steps compared, but the log is damaged (a chunk
  whose CRC fails, a missing chunk, step or message, a summary that disagrees with the data):
  ``damage`` names the first damaged or missing step (or byte);
- ``incomplete`` (exit 1): no difference and no damage, but the log was never closed (a
  ``.partial``): without its summary it cannot prove that nothing is missing after its last step;
- ``partial`` (exit 0, only when asked with ``--partial``): a damaged or incomplete log whose
  complete steps up to the damage were all identical; the verdict says how many steps were
  checked out of how many the log claims.

A `Divergence` names one place where the two sides differ at one step:
- channel: ``/world``, ``/bodies``, ``/contacts``, ``/stats``, or ``simulation`` (the replay
  itself stopped with an error at a step the log holds);
- kind: ``value`` (a field differs), ``count`` (a different number of bodies or contact rows),
  ``missing`` (a message is on one side only), ``error`` (the re-simulation failed);
- where: the body (index and name) or the contact row (row index, bodies a and b, sub-step, slot);
- field: e.g. ``position.y`` or ``impulse``; logged / replayed: the two values (for a diff: the
  first and the second log); ulps: their distance in units in the last place (float64 fields).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

# --all lists at most this many differing steps; counting goes on past it
DEFAULT_MAX_REPORTED = 100


@dataclass
class Divergence:
    """One difference at one step (see the module docstring)."""

    step: int
    channel: str
    kind: str
    field: str = ""
    logged: object = None
    replayed: object = None
    ulps: int | None = None
    body: int | None = None
    body_name: str | None = None
    contact: dict | None = None
    differing_values: int = 1
    max_ulps: int | None = None
    detail: str = ""
    joint: dict | None = None  # /joints and /world's joints: index, name (and component)

    def where(self) -> str:
        if self.joint is not None:
            j = self.joint
            part = f", {j['component']}" if j.get("component") else ""
            return f"joint {j.get('name')!r} (index {j['index']}{part})"
        if self.body is not None:
            return f"body {self.body_name!r} (index {self.body})"
        if self.contact is not None:
            c = self.contact
            pair = f"{c.get('a_name', c.get('a'))!r}-{c.get('b_name', c.get('b'))!r}"
            manifold = f"manifold {c['manifold']}, " if c.get("manifold") is not None else ""
            return (
                f"contact row {c['row']} ({manifold}{pair}, sub-step {c.get('substep')}, "
                f"slot {c.get('slot')})"
            )
        return ""


@dataclass
class Report:
    """What a replay (``isaac replay``) or a diff (``isaac diff``) found.

    mode: "replay" or "diff". logs: the file(s) read. first_step/last_step: the steps compared
    (None if none). tolerance: None for the bitwise check, else X (see docs/replay.md).
    divergences: the differences found, the first one first, at most ``max_reported`` steps
    (``differing_steps`` counts them all). complete: every step asked for (all the log claims,
    or the ``--to-step`` window) was read whole and intact. damage: the first damaged or missing
    step or byte, one line ("" if none; ``damage_step``, ``damage_offset``). claimed_steps: how
    many steps the log claims (its ``isaac.end``; for a log never closed, the steps its readable
    chunks hold), None if unknown. partial: ``--partial`` was given. truncated: not complete
    (kept for older readers), the reason in ``truncated_detail``. notes: version/platform
    differences and other remarks. elapsed_s and steps_per_s: wall time of the comparison loop
    and its rate (steps/s).
    """

    mode: str
    logs: list
    steps_compared: int = 0
    first_step: int | None = None
    last_step: int | None = None
    tolerance: float | None = None
    divergences: list = field(default_factory=list)
    differing_steps: int = 0
    within_tolerance_steps: int = 0
    max_ulps_seen: int | None = None
    complete: bool = True
    damage: str = ""
    damage_step: int | None = None
    damage_offset: int | None = None
    claimed_steps: int | None = None
    partial: bool = False
    truncated: bool = False
    truncated_detail: str = ""
    stopped_early: bool = False
    notes: list = field(default_factory=list)
    # what differs between the two logs' settings (a diff), printed before the divergences
    settings_differ: list = field(default_factory=list)
    elapsed_s: float = 0.0
    steps_per_s: float = 0.0
    max_reported: int = DEFAULT_MAX_REPORTED

    @property
    def diverged(self) -> bool:
        return self.differing_steps > 0 or bool(self.divergences)

    @property
    def identical(self) -> bool:
        """Every step claimed was present, intact and compared, and none differs."""
        return not self.diverged and self.complete and self.steps_compared > 0

    @property
    def verdict(self) -> str:
        """``identical``, ``diverged``, ``damaged``, ``incomplete`` or ``partial`` (above)."""
        if self.diverged:
            return "diverged"
        if self.identical:
            return "identical"
        if self.partial and self.steps_compared > 0:
            return "partial"
        return "damaged" if self.damage else "incomplete"

    @property
    def exit_status(self) -> int:
        return 0 if self.verdict in ("identical", "partial") else 1

    def divergent_steps(self) -> list[int]:
        return sorted({d.step for d in self.divergences})

    def add(self, found: list[Divergence]) -> None:
        """Record the divergences of one step (the step counts even past ``max_reported``)."""
        if not found:
            return
        self.differing_steps += 1
        if self.differing_steps <= self.max_reported:
            self.divergences.extend(found)


def _num(x) -> str:
    if isinstance(x, float):
        return repr(x)
    return str(x)


def _describe(d: Divergence, labels: tuple[str, str] = ("logged", "replayed")) -> str:
    logged, replayed = labels
    where = d.where()
    head = f"step {d.step}, {d.channel}" + (f", {where}" if where else "")
    if d.kind == "value":
        ulps = f", {d.ulps} ULP" if d.ulps is not None else ""
        more = ""
        if d.differing_values > 1:
            more = f" ({d.differing_values} values differ at this step on this channel"
            more += f", up to {d.max_ulps} ULP)" if d.max_ulps is not None else ")"
        return (
            f"{head}, {d.field}: {logged} {_num(d.logged)}, {replayed} {_num(d.replayed)}"
            f"{ulps}{more}"
        )
    if d.kind == "count":
        return f"{head}: {d.field} count differs: {logged} {d.logged}, {replayed} {d.replayed}" + (
            f"; {d.detail}" if d.detail else ""
        )
    if d.kind == "missing":
        return f"{head}: {d.detail}"
    return f"{head}: {d.detail}"


def _labels(report: Report) -> tuple[str, str]:
    if report.mode == "diff":
        return "A", "B"
    return "logged", "replayed"


def format_text(report: Report, *, all_steps: bool = False) -> str:
    """The verdict line, then (when they differ) the divergences of the first differing step, or
    of every listed step with ``all_steps``, then the notes."""
    lines: list[str] = []
    span = (
        "no steps"
        if report.first_step is None
        else f"steps {report.first_step}..{report.last_step}"
    )
    rate = f"{report.steps_per_s:.1f} steps/s" if report.steps_per_s else "rate n/a"
    timing = f"{report.elapsed_s:.2f} s, {rate}"
    what = (
        "identical" if report.tolerance is None else f"equal within tolerance {report.tolerance:g}"
    )
    verb = "replayed" if report.mode == "replay" else "compared"
    verdict = report.verdict
    if verdict == "identical":
        extra = ""
        if report.tolerance is not None and report.within_tolerance_steps:
            extra = f"; {report.within_tolerance_steps} of them not bit-identical" + (
                f", up to {report.max_ulps_seen} ULP" if report.max_ulps_seen else ""
            )
        lines.append(f"{what}: {verb} {report.steps_compared} steps ({span}) in {timing}{extra}")
    elif verdict == "diverged":
        first = report.divergences[0] if report.divergences else None
        at = f" at step {first.step}" if first else ""
        lines.append(
            f"DIVERGED{at}: {report.differing_steps} of {report.steps_compared} steps "
            f"differ ({span}, {timing})"
        )
        shown = (
            report.divergences
            if all_steps
            else [d for d in report.divergences if first is not None and d.step == first.step]
        )
        if report.settings_differ:
            lines.append("  settings differ (A, B): " + "; ".join(report.settings_differ))
        labels = _labels(report)
        for d in shown:
            lines.append("  " + _describe(d, labels))
        if all_steps and report.differing_steps > report.max_reported:
            lines.append(
                f"  ... {report.differing_steps - report.max_reported} more differing "
                f"steps not listed (--max-reported)"
            )
        if not all_steps and report.differing_steps > 1:
            lines.append("  (--all lists every differing step)")
    else:
        checked = "checked" if report.mode == "replay" else "compared"
        of = "" if report.claimed_steps is None else f" of {report.claimed_steps:,}"
        up_to = f", {what} up to step {report.last_step:,}" if report.last_step is not None else ""
        counted = f"{report.steps_compared:,}{of} steps {checked}{up_to}"
        if verdict == "partial":
            lines.append(f"partial: {counted} ({timing})")
        else:
            if report.damage_step is not None:
                where = f" at step {report.damage_step:,}"
            elif report.damage_offset is not None:
                where = f" at byte {report.damage_offset:,}"
            else:
                where = ""
            head = "DAMAGED" if verdict == "damaged" else "INCOMPLETE"
            lines.append(f"{head}{where}: {counted}; the log cannot be checked whole ({timing})")
    if report.damage:
        lines.append(f"  damaged: {report.damage}")
    if report.truncated:
        lines.append(f"  note: {report.truncated_detail}")
    for note in report.notes:
        lines.append(f"  note: {note}")
    return "\n".join(lines)


def _jsonable(value):
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)  # JSON has no NaN / inf
    return value


def to_json(report: Report) -> str:
    """The report as JSON (floats exact via repr round-trip; NaN / inf as strings)."""
    data = {
        "mode": report.mode,
        "logs": report.logs,
        "verdict": report.verdict,
        "identical": report.identical,
        "exit_status": report.exit_status,
        "steps_compared": report.steps_compared,
        "first_step": report.first_step,
        "last_step": report.last_step,
        "tolerance": report.tolerance,
        "differing_steps": report.differing_steps,
        "within_tolerance_steps": report.within_tolerance_steps,
        "max_ulps_seen": report.max_ulps_seen,
        "complete": report.complete,
        "damage": report.damage,
        "damage_step": report.damage_step,
        "damage_offset": report.damage_offset,
        "claimed_steps": report.claimed_steps,
        "partial": report.partial,
        "truncated": report.truncated,
        "truncated_detail": report.truncated_detail,
        "stopped_early": report.stopped_early,
        "notes": report.notes,
        "settings_differ": report.settings_differ,
        "elapsed_s": report.elapsed_s,
        "steps_per_s": report.steps_per_s,
        "divergences": [
            {k: _jsonable(v) for k, v in asdict(d).items()} for d in report.divergences
        ],
    }
    return json.dumps(data, indent=2, allow_nan=False)
