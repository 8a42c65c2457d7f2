"""`isaac tradeoff SCENE.yaml`: what each fidelity setting buys (error) and costs (time).

Outline:

1. grid       the settings to compare: presets x dt values by default (`--grid KEY=V1,V2 ...` for
              any other axes); every point is the scene with those world settings.
2. reference  the `accurate` preset at a small dt (default: the scene's dt / 8), or the closed
              form for scenes it knows how to solve (`--reference analytic`: a lone body in free
              flight, a body dropped flat on level concrete ground, a 1D head-on hit).
3. measure    each point once with per-step checks (samples, penetration, tunneling), then
              `repeats` timed runs without them; cost is the median of the timed runs, measured
              after a warm-up step has compiled (or loaded) the kernels.
4. compare    at common times (multiples of the coarsest dt), so runs of different dt are
              compared where they all have a state: position RMS over bodies and sample times,
              energy drift and error, centre-of-mass error, momentum error, max penetration,
              tunneling through concrete bodies.
5. report     a table on stdout, a CSV and a PNG of error against cost with the Pareto front.

Cost is given per step (ms/step, steps/s) and per simulated second (ms/sim-s, the fair axis when
dt differs: halving dt doubles the steps). For chaotic scenes (a pile) the position RMS is
dominated by chaos, not by accuracy: two equally good runs diverge body by body. The columns
that stay meaningful there are energy, penetration, the centre of mass (settled height) and
tunneling (docs/tradeoff.md).

Modules, in the outline's order: `grid` (1), `analytic` (2, the closed forms), `trajectory` (3:
running and timing one point), `metrics` (4), `measure` (the whole measurement), `report` (5:
table, CSV, plot; matplotlib is imported only when a plot is written), `command` (the CLI).
Part of the app: it may import the engine and the scene contract; the engine never imports it.
"""

from __future__ import annotations

from isaac.app.tradeoff.analytic import analytic_model, analytic_trajectory
from isaac.app.tradeoff.command import cmd_tradeoff, register
from isaac.app.tradeoff.grid import GridPoint, TradeoffError, parse_dt, parse_grid
from isaac.app.tradeoff.measure import TradeoffResult, measure
from isaac.app.tradeoff.report import format_table, plot, write_csv
from isaac.app.tradeoff.trajectory import Trajectory, sample_times, simulate

__all__ = [
    "GridPoint",
    "TradeoffError",
    "TradeoffResult",
    "Trajectory",
    "analytic_model",
    "analytic_trajectory",
    "cmd_tradeoff",
    "format_table",
    "measure",
    "parse_dt",
    "parse_grid",
    "plot",
    "register",
    "sample_times",
    "simulate",
    "write_csv",
]
