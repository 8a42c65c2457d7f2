"""The result as a table, a CSV and a PNG of error against cost (matplotlib, imported only here)."""

from __future__ import annotations

import csv
import math

from isaac.app.tradeoff.measure import COLUMNS, TradeoffResult, _pareto


def _fmt(value, key: str) -> str:
    if value is None or value == "":
        return ""
    if isinstance(value, str):
        return value
    if key in ("tunneled",):
        return str(int(value))
    if isinstance(value, float) and math.isnan(value):
        return "-"
    if key == "dt":
        return f"{value:.5g}" if value else "-"
    if key == "steps_per_s":
        return f"{value:.0f}"
    return f"{value:.3g}"


def write_csv(result: TradeoffResult, path) -> None:
    """One row per grid point plus the reference row (first), columns COLUMNS."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(("scene", "reference") + COLUMNS)
        for row in [result.reference_row] + result.rows:
            values = []
            for key in COLUMNS:
                v = row.get(key, "")
                values.append(repr(v) if isinstance(v, float) else v)
            writer.writerow((result.scene, result.reference, *values))


TABLE_COLUMNS = (
    ("setting", "setting"),
    ("dt", "dt s"),
    ("ms_per_step", "ms/step"),
    ("steps_per_s", "steps/s"),
    ("ms_per_sim_s", "ms/sim-s"),
    ("rms_error_m", "RMS err m"),
    ("energy_drift", "E drift"),
    ("energy_error", "E err"),
    ("com_error_m", "COM err m"),
    ("momentum_error_mps", "P err m/s"),
    ("max_penetration_m", "max pen m"),
    ("tunneled", "tunnel"),
    ("pareto", "pareto"),
)


JOINT_COLUMN = ("max_joint_error_m", "joint err m")  # shown for a scene with joints


def format_table(result: TradeoffResult, *, markdown: bool = False) -> str:
    """The table as aligned text (or a Markdown table), reference row first; a scene with
    joints also gets the largest joint error of each run."""
    columns = list(TABLE_COLUMNS)
    if result.joints:
        columns.insert(columns.index(("tunneled", "tunnel")), JOINT_COLUMN)
    header = [title for _, title in columns]
    body = []
    for row in [result.reference_row] + result.rows:
        cells = [_fmt(row.get(key, ""), key) for key, _ in columns]
        if row.get("diverged"):
            cells[-1] = "DIVERGED"
        body.append(cells)
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(c or " " for c in cells) + " |" for cells in body]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in [header] + body) for i in range(len(header))]
    lines = ["  ".join(h.ljust(wd) for h, wd in zip(header, widths))]
    lines += ["  ".join(c.ljust(wd) for c, wd in zip(cells, widths)) for cells in body]
    return "\n".join(lines)


def plot(result: TradeoffResult, path, *, second: str = "max_penetration_m") -> None:
    """PNG: error against cost (ms per simulated second, log-log), one marker per setting and
    dt, the Pareto front joined; a second panel shows `second` (a physically meaningful error)."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = {
        "rms_error_m": "trajectory RMS error vs reference (m)",
        "max_penetration_m": "max penetration (m)",
        "energy_error": "energy error (rel.)",
        "com_error_m": "centre-of-mass error (m)",
        "max_joint_error_m": "largest joint error (m)",
    }
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.2), dpi=90)
    labels = list(dict.fromkeys(r["setting"] for r in result.rows))
    dts = sorted({r["dt"] for r in result.rows}, reverse=True)
    markers = "osD^v<>ph*"
    cmap = plt.get_cmap("viridis")
    for ax, metric in zip(axes, ("rms_error_m", second)):
        pts = []
        values = [r[metric] for r in result.rows if math.isfinite(r[metric])]
        positive = [v for v in values if v > 0.0]
        floor = min(positive) / 10.0 if positive else 1e-6
        floor_note = f"0 plotted at {floor:.2g}" if len(positive) < len(values) else ""
        for r in result.rows:
            c, e = r["ms_per_sim_s"], r[metric]
            if not (math.isfinite(c) and math.isfinite(e)):
                continue
            e_plot = max(e, floor)
            li, di = labels.index(r["setting"]), dts.index(r["dt"])
            ax.scatter(
                c,
                e_plot,
                marker=markers[li % len(markers)],
                s=55,
                color=cmap(di / max(1, len(dts) - 1) * 0.85),
                edgecolor="black",
                linewidth=0.5,
                zorder=3,
            )
            pts.append((c, e_plot))
        marks = _pareto(pts)
        front = sorted(p for p, m in zip(pts, marks) if m)
        if front:
            ax.plot(*zip(*front), "--", color="crimson", lw=1.2, zorder=2, label="Pareto front")
            ax.scatter(*zip(*front), s=140, facecolor="none", edgecolor="crimson", zorder=4)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        if floor_note:
            ax.text(0.02, 0.02, floor_note, transform=ax.transAxes, fontsize=7, color="dimgray")
        ax.set_xlabel("cost: ms of wall time per simulated second")
        ax.set_ylabel(titles.get(metric, metric))
        ax.grid(True, which="both", alpha=0.25)
    from matplotlib.lines import Line2D

    handles = [
        Line2D(
            [],
            [],
            marker=markers[i % len(markers)],
            ls="",
            color="grey",
            markeredgecolor="black",
            label=lab,
        )
        for i, lab in enumerate(labels)
    ]
    handles += [
        Line2D(
            [],
            [],
            marker="o",
            ls="",
            color=cmap(i / max(1, len(dts) - 1) * 0.85),
            label=f"dt = {_dt_text(d)}",
        )
        for i, d in enumerate(dts)
    ]
    handles.append(Line2D([], [], ls="--", color="crimson", label="Pareto front"))
    axes[1].legend(handles=handles, fontsize=7, loc="best", framealpha=0.8)
    fig.suptitle(
        f"{result.scene}: error vs cost (reference: {result.reference}; "
        f"{result.duration:.3g} s simulated)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _dt_text(dt: float) -> str:
    inverse = 1.0 / dt
    if abs(inverse - round(inverse)) < 1e-6 * inverse:
        return f"1/{round(inverse)} s"
    return f"{dt:.3g} s"
