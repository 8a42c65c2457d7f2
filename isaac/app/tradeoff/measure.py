"""The whole measurement: every grid point against the reference, its cost and the Pareto front."""

from __future__ import annotations

import math
import statistics
import sys
from dataclasses import dataclass, replace

from isaac.app.tradeoff.analytic import analytic_model, analytic_trajectory
from isaac.app.tradeoff.grid import REFERENCE_DT_DIVISOR, GridPoint, TradeoffError
from isaac.app.tradeoff.metrics import _series, compare
from isaac.app.tradeoff.trajectory import (
    MIN_TIMED_SECONDS,
    sample_times,
    simulate,
    time_runs,
    warm_up,
)
from isaac.scene import Scene, checks
from isaac.scene.limits import MAX_STEPS

COLUMNS = (
    "setting",
    "dt",
    "ms_per_step",
    "steps_per_s",
    "ms_per_sim_s",
    "rms_error_m",
    "max_error_m",
    "energy_drift",
    "energy_error",
    "com_error_m",
    "momentum_error_mps",
    "max_penetration_m",
    "max_joint_error_m",
    "tunneled",
    "diverged",
    "pareto",
)


@dataclass
class TradeoffResult:
    """Rows (dicts keyed by COLUMNS) for the grid points, plus the reference row."""

    scene: str
    reference: str  # "analytic (drop)" or "accurate, dt=..."
    duration: float
    sample_dt: float
    rows: list[dict]
    reference_row: dict
    joints: bool = False  # the scene has joints (the table shows their largest error)


def _pareto(points: list[tuple[float, float]]) -> list[bool]:
    """Which (cost, error) points no other point beats in both (lower is better)."""
    marks = []
    for i, (c, e) in enumerate(points):
        if not (math.isfinite(c) and math.isfinite(e)):
            marks.append(False)
            continue
        dominated = any(
            j != i
            and math.isfinite(c2)
            and math.isfinite(e2)
            and c2 <= c
            and e2 <= e
            and (c2 < c or e2 < e)
            for j, (c2, e2) in enumerate(points)
        )
        marks.append(not dominated)
    return marks


def measure(
    scene: Scene,
    grid: list[GridPoint],
    *,
    reference: str = "accurate",
    reference_dt: float | None = None,
    duration: float | None = None,
    repeats: int = 3,
    min_seconds: float = MIN_TIMED_SECONDS,
    progress: bool = False,
) -> TradeoffResult:
    """Run every grid point against the reference and measure cost and error.

    reference: "accurate" (the `accurate` preset at `reference_dt`, default the smaller of the
        scene's dt / 8 and the smallest grid dt / 4) or "analytic" (`analytic_trajectory`).
    duration: simulated seconds (default: the scene's steps * dt).
    repeats: rounds of timed runs over the whole grid; a point's cost is the median of its timed
        runs. Short runs are repeated until `min_seconds` were timed (timer noise).
    """
    from isaac.engine.world import build_model

    if repeats < 1:
        raise TradeoffError(f"--repeats must be >= 1, got {repeats}")
    if not grid:
        raise TradeoffError("the grid is empty")
    w = scene.world
    duration = w.steps * w.dt if duration is None else float(duration)
    if not duration > 0.0:
        raise TradeoffError(f"--duration must be > 0, got {duration}")
    # the reference's dt: the accurate preset's, given or made from the scene's and the grid's
    ref_dt = reference_dt or min(w.dt / REFERENCE_DT_DIVISOR, min(p.dt for p in grid) / 4)
    finest = min(p.dt for p in grid)
    if reference == "accurate":
        finest = min(finest, ref_dt)
    if duration / finest > MAX_STEPS:  # a scene's own bound on world.steps
        raise TradeoffError(
            f"--duration {duration:g} s is {duration / finest:.3g} steps of the finest dt run "
            f"({finest:g} s), more than the {MAX_STEPS} a run may take"
        )
    sample_dt = max(p.dt for p in grid)
    times = sample_times(duration, sample_dt)
    if times.shape[0] < 2:
        raise TradeoffError(
            f"the run ({duration} s) is shorter than the coarsest dt "
            f"({sample_dt} s): nothing to compare"
        )
    duration = float(times[-1])
    model = build_model(scene)
    for point in grid:  # refused before anything runs: a setting that cannot solve the scene
        refusal = checks.joint_solver_problem(point.world(w, duration).solver, scene.joints)
        if refusal is not None:
            raise TradeoffError(f"--grid {point.label}: {refusal}")
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=1 + len(grid) * (1 + repeats),
            unit="run",
            desc=scene.name,
            leave=False,
            file=sys.stderr,
        )
    try:
        if reference == "analytic":
            kind = analytic_model(scene)
            ref = analytic_trajectory(scene, times)
            ref_label = f"analytic ({kind})"
            ref_row = dict(setting="analytic", dt=0.0)
            ref_cost = math.nan
        elif reference == "accurate":
            ref_point = GridPoint("accurate (reference)", ref_dt, (("preset", "accurate"),))
            ref_scene = replace(scene, world=ref_point.world(w, duration))
            if bar:
                bar.set_postfix_str(f"reference dt={ref_dt:.3g}")
            warm_up(ref_scene)
            ref = simulate(ref_scene, times)
            if ref.error is not None:
                raise TradeoffError(f"the reference run failed: {ref.error}")
            ref_cost = statistics.median(time_runs(ref_scene, 1, min_seconds))
            ref_label = f"accurate, dt={ref_dt:.6g} s"
            ref_row = dict(
                setting=ref_point.label,
                dt=ref_dt,
                max_penetration_m=ref.max_depth,
                max_joint_error_m=ref.max_joint_error,
                tunneled=len(ref.tunneled),
            )
        else:
            raise TradeoffError(f"--reference must be accurate or analytic, got {reference!r}")
        if bar:
            bar.update(1)
        ref_series = _series(scene, model, ref)
        ref_row.update(compare(scene, model, ref, ref, ref_series), diverged="")
        if math.isfinite(ref_cost):
            steps = math.ceil(duration / ref_row["dt"] - 1e-9)
            ref_row.update(_cost(ref_cost, steps, ref_row["dt"]))
        # measure: one untimed run per point with the per-step checks
        rows, timed = [], []
        for point in grid:
            if bar:
                bar.set_postfix_str(f"{point.label} dt={point.dt:.3g}")
            run_scene = replace(scene, world=point.world(w, duration))
            warm_up(run_scene)
            run = simulate(run_scene, times)
            row = dict(setting=point.label, dt=point.dt)
            row.update(compare(scene, model, run, ref, ref_series))
            row.update(
                max_penetration_m=run.max_depth,
                max_joint_error_m=run.max_joint_error,
                tunneled=len(run.tunneled),
                diverged=run.error or "",
                ms_per_step=math.nan,
                steps_per_s=math.nan,
                ms_per_sim_s=math.nan,
            )
            rows.append(row)
            timed.append((row, run_scene, []) if run.error is None else None)
            if bar:
                bar.update(1)
        # time: `repeats` rounds over the whole grid, so a burst of load from elsewhere on the
        # machine falls on every setting alike instead of on one
        for _ in range(repeats):
            for entry in timed:
                if entry is None:
                    continue
                row, run_scene, costs = entry
                if bar:
                    bar.set_postfix_str(f"timing {row['setting']} dt={row['dt']:.3g}")
                costs.extend(time_runs(run_scene, 1, min_seconds / repeats))
                if bar:
                    bar.update(1)
        for entry in timed:
            if entry is not None:
                row, run_scene, costs = entry
                row.update(_cost(statistics.median(costs), run_scene.world.steps, row["dt"]))
    finally:
        if bar:
            bar.close()
    marks = _pareto([(r["ms_per_sim_s"], r["rms_error_m"]) for r in rows])
    for row, mark in zip(rows, marks):
        row["pareto"] = "*" if mark else ""
    ref_row.setdefault("pareto", "")
    return TradeoffResult(
        scene=scene.name,
        reference=ref_label,
        duration=duration,
        sample_dt=sample_dt,
        rows=rows,
        reference_row=ref_row,
        joints=bool(scene.joints),
    )


def _cost(seconds: float, steps: int, dt: float) -> dict[str, float]:
    ms_per_step = 1e3 * seconds / steps
    return dict(
        ms_per_step=ms_per_step, steps_per_s=1e3 / ms_per_step, ms_per_sim_s=ms_per_step / dt
    )
