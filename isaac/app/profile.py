"""Per-stage timings for `isaac run --profile`.

Wraps the stage kernels that `isaac.engine.step` calls with timers (wall time, perf_counter), so the
step runs unchanged and pays nothing when profiling is off. Timings include the call overhead of
each kernel, which is part of what a step costs.
"""

from __future__ import annotations

import time

from isaac.engine import step as step_module

STAGES = {
    "transform": "geometry",
    "speculative_reach": "broad phase",
    "find_pairs": "broad phase",
    "collide_pairs": "narrow phase",
    "match_previous": "narrow phase",
    "push_out": "push-out",
    "add_gravity": "integration",
    "solve_contacts": "impulses",
    "advance_positions": "integration",
}


class Profiler:
    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._originals: dict[str, object] = {}

    def _wrap(self, name: str, stage: str):
        original = getattr(step_module, name)
        self._originals[name] = original
        seconds = self.seconds
        seconds.setdefault(stage, 0.0)

        def timed(*args):
            t0 = time.perf_counter()
            result = original(*args)
            seconds[stage] += time.perf_counter() - t0
            return result

        setattr(step_module, name, timed)

    def restore(self) -> None:
        for name, original in self._originals.items():
            setattr(step_module, name, original)
        self._originals.clear()

    def report(self, steps: int) -> str:
        total = sum(self.seconds.values())
        lines = [f"  per-stage time over {steps} steps (ms/step, share of kernel time):"]
        for stage, sec in sorted(self.seconds.items(), key=lambda kv: -kv[1]):
            share = sec / total if total else 0.0
            lines.append(f"    {stage:<13} {1e3 * sec / max(steps, 1):9.4f}  {100 * share:5.1f}%")
        return "\n".join(lines)


def enable_profiling() -> Profiler:
    profiler = Profiler()
    for name, stage in STAGES.items():
        profiler._wrap(name, stage)
    return profiler
