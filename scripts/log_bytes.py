"""Bytes per body-step of an MCAP log, in format 1 (/contacts one row per point) and format 2
(per manifold), with each chunk compression, and the compressor's CPU time a step.

    .venv/bin/python scripts/log_bytes.py scenes/default.yaml scenes/pile.yaml [--reps 5]

The run is simulated once; its records are then written in this process by the recorder's MCAP
writer (`recorder.mcap_writer.McapLogWriter`, 256 KiB chunks, the recorder's flush rule) once
per layout and compression, format 1's /contacts from `encode_contacts_v1`, so the two layouts
differ in that message alone. The compressor's time is the writing time with compression less
the time without, best of ``--reps`` (the machine may be busy: the spread is printed).
Figures go to docs/log-format.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from isaac.engine.simulation import Simulation  # noqa: E402
from isaac.scene import load_scene  # noqa: E402
from recorder.mcap_writer import (  # noqa: E402
    McapLogWriter,
    encode_bodies,
    encode_contacts,
    encode_contacts_v1,
)
from recorder.stats import compute_stats  # noqa: E402


def _records(path: str):
    scene = load_scene(path)
    sim = Simulation(scene)
    records = [sim.record()]
    for batch in sim.batches(size=64):
        records += [batch.record(s) for s in range(batch.steps)]
    gravity = tuple(float(g) for g in scene.world.gravity)
    # encoded once: the writing timed below is the MCAP writer's and the compressor's alone
    encoded = []
    for r in records:
        stats = compute_stats(sim.model, gravity, r)
        encoded.append(
            (r.step, r.time, r.exists, encode_bodies(r), encode_contacts(r),
             encode_contacts_v1(r), stats)
        )  # fmt: skip
    return scene, sim, encoded


def _write(out: str, scene, sim, encoded, fmt: int, compression: str) -> float:
    """Write the log; returns the seconds the writing took."""
    w = McapLogWriter(out, sim.model, scene, "scene", compression=compression)
    t0 = time.perf_counter()
    for step, t, exists, bodies, v2, v1, stats in encoded:
        w.write_messages(step, t, exists, bodies, v2 if fmt == 2 else v1, stats)
    w.close()
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    for path in args.scenes:
        scene, sim, encoded = _records(path)
        steps = len(encoded)
        body_steps = sim.n_bodies * steps
        print(f"\n{path}: {sim.n_bodies} bodies, {steps} steps (0..{steps - 1})")
        with tempfile.TemporaryDirectory() as tmp:
            for fmt in (1, 2):
                times = {}
                for compression in ("none", "lz4", "zstd"):
                    out = os.path.join(tmp, f"f{fmt}_{compression}.mcap")
                    times[compression] = [
                        _write(out, scene, sim, encoded, fmt, compression) for _ in range(args.reps)
                    ]
                    size = os.path.getsize(out)
                    if compression == "none":
                        base = size
                    extra = ""
                    if compression != "none":
                        best = min(times[compression]) - min(times["none"])
                        spread = (max(times[compression]) - min(times[compression])) / steps
                        extra = (
                            f", compressor {1e3 * best / steps:.3f} ms/step "
                            f"(spread of the reps {1e3 * spread:.3f} ms/step)"
                        )
                    print(
                        f"  format {fmt} {compression:4s}: {size / 1e6:8.2f} MB, "
                        f"{size / body_steps:7.1f} B/body-step, {size / base:.2f} of none{extra}"
                    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
