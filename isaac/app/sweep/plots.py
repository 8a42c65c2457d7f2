"""The sweep's PNG plots: a histogram of each metric, and each metric against each swept
parameter (matplotlib, the `plot` extra, imported only here)."""

from __future__ import annotations

import os
import re

PLOTS_DIR = "plots"
# one column per metric (the others are in the table): a 40-run sweep of 4 parameters gives
# up to 30 plots rather than 75
PLOTTED = (
    "final_com_x",
    "final_com_y",
    "max_depth",
    "energy_drift",
    "contacts",
    "tunneled",
)
LABELS = {
    "final_com_x": "final_com_x (m): centre of mass of the moving bodies at the end",
    "final_com_y": "final_com_y (m): centre of mass of the moving bodies at the end",
    "max_depth": "max_depth (m): deepest contact penetration",
    "energy_drift": "energy_drift: (E_end - E_0) / |E_0|",
    "contacts": "contacts: contact points over all steps",
    "tunneled": "tunneled: bodies that passed through concrete",
}


# the unit of a swept value by the scene key it names or is a component of
# (docs/scene-format.md); none for the dimensionless ones (restitution, friction) and counts
PARAM_UNITS = {
    "gravity": "m/s²",
    "dt": "s",
    "slop": "m",
    "restitution_threshold": "m/s",
    "position": "m",
    "angle": "rad",
    "velocity": "m/s",
    "angular_velocity": "rad/s",
    "density": "kg/m²",
    "enters_at": "s",
    "leaves_at": "s",
    "box": "m",
    "base": "m",
    "spacing": "m",
    "radius": "m",
    "width": "m",
    "height": "m",
    "thickness": "m",
}


def param_label(key: str) -> str:
    """A swept key path with its unit: `bodies.box.velocity.x (m/s)`. The body's name and the
    generator's index and kind are not keys (a body may be called `velocity`)."""
    segments = key.split(".")
    skip = {"bodies": 2, "generators": 3, "world": 1}.get(segments[0], 0)
    for segment in reversed(segments[skip:]):
        if segment in PARAM_UNITS:
            return f"{key} ({PARAM_UNITS[segment]})"
    return key


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", name).strip("_") or "column"


def _numeric(values) -> list:
    return [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]


def plot_all(table, sweep, out_dir: str) -> list[str] | None:
    """Write OUT/plots/*.png for the runs with status ok; the paths written, or None when
    matplotlib is not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    from isaac.app.sweep.metrics import columns

    rows = [r for r in table.to_pylist() if r["status"] == "ok"]
    folder = os.path.join(out_dir, PLOTS_DIR)
    os.makedirs(folder, exist_ok=True)
    metric_names = [f.name for f in columns(sweep.metrics, sweep.final_bodies) if f.name in PLOTTED]
    params = [a.key for a in sweep.axes]
    written = []
    title = f"{os.path.basename(sweep.path)}: {len(rows)} ok runs of {sweep.n_runs}"
    for metric in metric_names:
        values = _numeric([r[metric] for r in rows])
        if len(set(values)) < 2:
            continue  # a constant (or empty) column: the summary says its value
        fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
        ax.hist(values, bins=min(50, max(5, int(len(values) ** 0.5))), color="tab:blue")
        ax.set_xlabel(LABELS.get(metric, metric))
        ax.set_ylabel("runs")
        ax.yaxis.get_major_locator().set_params(integer=True)  # counts: no 1.5 runs
        ax.set_title(title, fontsize=9)
        fig.tight_layout()
        path = os.path.join(folder, f"hist-{_safe(metric)}.png")
        fig.savefig(path)
        plt.close(fig)
        written.append(path)
        for param in params:
            pairs = [
                (r[param], r[metric])
                for r in rows
                if r[metric] is not None and not isinstance(r[metric], (bool, str))
            ]
            if not pairs:
                continue
            xs = [p for p, _ in pairs]
            ys = [m for _, m in pairs]
            fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
            if _numeric(xs) == xs:
                ax.scatter(xs, ys, s=8, alpha=0.6, color="tab:blue")
            else:  # categories (names, lists): one column of points each, in sorted order
                cats = sorted({str(x) for x in xs})
                where = {c: i for i, c in enumerate(cats)}
                ax.scatter([where[str(x)] for x in xs], ys, s=8, alpha=0.6, color="tab:blue")
                ax.set_xticks(range(len(cats)), cats, rotation=30, fontsize=8)
            ax.set_xlabel(param_label(param))
            ax.set_ylabel(LABELS.get(metric, metric).split(":")[0])
            ax.set_title(title, fontsize=9)
            fig.tight_layout()
            path = os.path.join(folder, f"{_safe(metric)}-vs-{_safe(param)}.png")
            fig.savefig(path)
            plt.close(fig)
            written.append(path)
    return written
