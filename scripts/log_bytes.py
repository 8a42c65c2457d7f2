"""Bytes per body-step of an MCAP log, in format 1 (/contacts one row per point) and format 2
(per manifold), with each chunk compression, and the compressor's CPU time a step.

    .venv/bin/python scripts/log_bytes.py scenes/default.yaml scenes/pile.yaml [--reps 5]

The run is simulated once; its records are then written in this process by the recorder's MCAP
writer (`recorder.mcap_writer.McapLogWriter`, 256 KiB chunks, the recorder's flush rule) once
per layout and compression, format 1's /contacts from `encode_contacts_v1`, so the two layouts
differ in that message alone. The compressor's time is the CPU time (``time.process_time``)
spent in the MCAP writer's (`recorder.mcap_file`) calls of ``lz4.frame.compress`` and
``zstandard.compress``, per step, best and worst of ``--reps`` writes (the machine may be busy).
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

_SPENT = [0.0]  # CPU seconds in the compressor since the last reset


def _timed(compress):
    def wrapped(data, *args, **kwargs):
        t0 = time.process_time()
        try:
            return compress(data, *args, **kwargs)
        finally:
            _SPENT[0] += time.process_time() - t0

    return wrapped


def _time_the_compressors() -> None:
    # recorder.mcap_file looks the codec up when a log is opened: wrapped here, it is timed
    import lz4.frame
    import zstandard

    lz4.frame.compress = _timed(lz4.frame.compress)
    zstandard.compress = _timed(zstandard.compress)


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
    """Write the log; returns the compressor's CPU seconds."""
    w = McapLogWriter(out, sim.model, scene, "scene", compression=compression)
    _SPENT[0] = 0.0
    for step, t, exists, bodies, v2, v1, stats in encoded:
        w.write_messages(step, t, exists, bodies, v2 if fmt == 2 else v1, stats)
    w.close()
    return _SPENT[0]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    _time_the_compressors()
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
                        spent = times[compression]
                        extra = (
                            f", compressor {1e3 * min(spent) / steps:.3f} ms/step "
                            f"(worst of {args.reps} {1e3 * max(spent) / steps:.3f})"
                        )
                    print(
                        f"  format {fmt} {compression:4s}: {size / 1e6:8.2f} MB, "
                        f"{size / body_steps:7.1f} B/body-step, {size / base:.2f} of none{extra}"
                    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
