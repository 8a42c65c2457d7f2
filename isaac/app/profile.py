"""Per-stage timings for `isaac run --profile`, measured inside the compiled driver.

`Simulation(scene, profile=True)` steps through the timed driver (`isaac.engine.driver`): the
same stage kernels, in the same order, with a monotonic clock read between stages
(`isaac.engine.clock`), compiled apart from the plain driver, so a run without --profile carries
no clock read. The physics is the same bits (tests/test_profile.py). This module turns the
totals (`Simulation.stage_times`) into what the user reads.
"""

from __future__ import annotations

# what each stage covers, said once under the table
_DRIVER_NOTE = (
    "driver = its own work: each step's start kept to undo it, contacts carried to the next "
    "sub-step, the divergence check, states and rows copied into the batch"
)


def report(times: dict[str, float], steps: int, loop_ms_per_step: float | None = None) -> str:
    """The per-stage table: ms/step and share of the driver's time per stage, largest first,
    then the clock reads' own cost (the total less the stages) and the driver's total beside
    the run loop's rate (loop_ms_per_step, ms; None when too few steps to measure one).

    times: `Simulation.stage_times()` (s); steps: the steps those calls took."""
    per = max(steps, 1)
    total = times.get("total", 0.0)
    stages = {k: v for k, v in times.items() if k != "total"}
    lines = [
        f"  time per step inside the compiled driver, over {steps} steps "
        "(ms/step, share of the driver's time):"
    ]
    for stage, sec in sorted(stages.items(), key=lambda kv: -kv[1]):
        share = sec / total if total > 0 else 0.0
        lines.append(f"    {stage:<13} {1e3 * sec / per:9.4f}  {100 * share:5.1f}%")
    reads = max(total - sum(stages.values()), 0.0)
    share = reads / total if total > 0 else 0.0
    lines.append(f"    {'clock reads':<13} {1e3 * reads / per:9.4f}  {100 * share:5.1f}%")
    whole = f"  driver total {1e3 * total / per:.4f} ms/step"
    if loop_ms_per_step is not None:
        whole += (
            f"; the run's loop {loop_ms_per_step:.4f} ms/step after its first step (with Python "
            "between batches, records, files)"
        )
    lines.append(whole)
    lines.append(f"  ({_DRIVER_NOTE})")
    return "\n".join(lines)
