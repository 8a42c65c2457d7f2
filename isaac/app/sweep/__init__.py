"""`isaac sweep`: one scene run many times (a grid and random draws of its parameters), the runs
fanned out over Dask distributed, every run recorded and measured, one results table.

Outline (docs/sweep-format.md is the sweep file's contract):

- `spec`     the sweep file read and checked; each run's parameters (grid points, random draws
             from (seed, sample, key) alone) and its scene, checked by the scene loader.
- `keys`     key paths (``bodies.box.restitution``) put into the scene's YAML node tree, and the
             edited tree written back as YAML the scene loader reads (its own messages).
- `worker`   what a Dask worker does with a chunk of runs: simulate, measure, record, keep the
             row on disk (a rescheduled chunk keeps the runs already done).
- `metrics`  the measured columns (final_state, max_depth, energy_drift, contacts, tunneled).
- `table`    runs.parquet (pyarrow): columns, rows, and what a resumed sweep keeps.
- `plots`    PNG histograms and metric-against-parameter plots (matplotlib, the `plot` extra).
- `cluster`  the Dask cluster: an existing one by address, or a local one on 127.0.0.1.
- `verify`   `isaac sweep verify DIR`: every log replayed on the cluster, a verdict table.
- `command`  the command line and `run`, the Python API.

Part of the app: may import the engine, the scene contract, `recorder`, dask and pyarrow; the
engine and the recorder never import it.
"""

from __future__ import annotations

from isaac.app.sweep.command import SweepResult, execute, register, run
from isaac.app.sweep.spec import Sweep, SweepError, load_sweep

__all__ = ["Sweep", "SweepError", "SweepResult", "execute", "load_sweep", "register", "run"]
