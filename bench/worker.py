"""One (scene, engine) run in its own process: build, warm up, time, measure quality, print JSON.

Run as `python -m bench.worker --scene pile-500 --engine pymunk`; the suite (`python -m bench`)
starts one such process per repetition so memory (RSS) and compile caches of one engine never
leak into another's figures.

Order inside the process:
1. import the engine and run a tiny two-body scene for a few steps (loads ISAAC's compiled
   kernels, or compiles them on a first run; the peers do the same for symmetry);
2. build the benchmark scene description (not counted as engine memory);
3. baseline RSS, build the engine's world, take `warmup_steps` steps, RSS again:
   memory per body = (RSS after warm-up - baseline) / n;
4. time `timed_steps` steps with one perf_counter block (ms/step = block / steps);
5. the quality figure from the final poses (bench.quality, the same code for every engine).

An engine that runs a whole scene in its own compiled process (bench.peers.OWN_PROCESS: Box2D
v3) takes steps 3 and 4 there, on its own clocks and RSS readings, with the same warm-up and
timed steps; step 5 is the same code on the final states it wrote.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time

import numpy as np

from bench import quality
from bench.geometry import LocalPolygons
from bench.peers import OWN_PROCESS, make_engine
from bench.scenes import BenchScene, build
from isaac.scene.checks import mass_properties


def rss_bytes() -> int:
    """Current resident set size (bytes), from /proc (falls back to the peak on other systems)."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
        return pages * resource.getpagesize()
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def warm_engine(engine_name: str) -> None:
    """A few steps of the head-on scene: compiles or loads whatever the engine compiles (an
    engine that runs in a process of its own has nothing to load in this one)."""
    tiny = build("head-on")
    engine = make_engine(engine_name, tiny.scene)
    if engine_name in OWN_PROCESS:
        return
    for _ in range(5):
        engine.step()
    engine.poses()


def measure_quality(bench: BenchScene, polys: LocalPolygons, start: tuple, engine) -> dict:
    pos, ang = engine.poses()
    q: dict = {}
    if bench.kind == "pyramid":
        q.update(
            quality.pyramid_quality(
                start[0],
                pos,
                start[1],
                ang,
                ~polys.concrete,
                bench.info["top"],
                tolerance=bench.info["tolerance_m"],
                angle_tolerance=bench.info["angle_tolerance_rad"],
            )
        )
        q.update(quality.overlap_stats(polys, pos, ang))
    elif bench.kind == "pile":
        q.update(quality.overlap_stats(polys, pos, ang))
    elif bench.kind == "head_on":
        vel, omega = engine.velocities()
        q["exchange_error_mps"] = quality.exchange_error(start[2], vel)
        q["final_velocities_x"] = [float(vel[0, 0]), float(vel[1, 0])]
        q["max_spin_radps"] = float(np.abs(omega).max())
    elif bench.kind == "mass_ratio":
        heavy, light = bench.info["heavy"], bench.info["light"]
        q["heavy_drop_m"] = float(start[0][heavy, 1] - pos[heavy, 1])
        q["light_drop_m"] = float(start[0][light, 1] - pos[light, 1])
        q["holds"] = bool(abs(q["heavy_drop_m"]) < 0.1)
        q.update(quality.overlap_stats(polys, pos, ang))
    elif bench.kind == "tunneling":
        bullets = [k for k, b in enumerate(bench.scene.bodies) if b.name.startswith("bullet")]
        wall_x = bench.info["wall_x"]
        passed = int(np.sum(pos[bullets, 0] > wall_x))
        q["passed_through"] = passed
        q["stopped"] = len(bullets) - passed
        q["lanes"] = len(bullets)
    elif bench.kind == "drop":
        q["final_height_m"] = float(pos[:, 1].max())
        q.update(quality.overlap_stats(polys, pos, ang))
    elif bench.kind == "off_centre":
        # no gravity: the bodies' total linear momentum is conserved (kg m/s)
        vel, _ = engine.velocities()
        mass = mass_properties(bench.scene.bodies).mass
        q["momentum_error_kgmps"] = float(
            np.hypot(*((mass[:, None] * (vel - start[2])).sum(axis=0)))
        )
    finite = bool(np.all(np.isfinite(pos)) and np.all(np.isfinite(ang)))
    q["finite"] = finite
    return q


def _steps(engine, steps: int) -> None:
    """`steps` steps: one call per step, or the engine's own block of steps (ISAAC's run and
    advance modes)."""
    block = getattr(engine, "block", None)
    if block is not None:
        block(steps)
        return
    for _ in range(steps):
        engine.step()


def _time_in_process(engine_name: str, bench: BenchScene) -> tuple[object, tuple, dict]:
    """(engine, start (positions, angles, velocities), timing figures) in this process."""
    n = bench.n_bodies
    rss0 = rss_bytes()
    t0 = time.perf_counter()
    engine = make_engine(engine_name, bench.scene)
    build_s = time.perf_counter() - t0
    start = (*engine.poses(), engine.velocities()[0])
    rss_built = rss_bytes()
    _steps(engine, bench.warmup_steps)
    rss_warm = rss_bytes()

    t0 = time.perf_counter()
    _steps(engine, bench.timed_steps)
    elapsed = time.perf_counter() - t0
    timing = dict(
        ms_per_step=1000.0 * elapsed / bench.timed_steps,
        build_s=build_s,
        memory_per_body_bytes=(rss_warm - rss0) / n,
        memory_built_per_body_bytes=(rss_built - rss0) / n,
        peak_rss_bytes=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
    )
    return engine, start, timing


def _time_in_its_process(engine_name: str, bench: BenchScene) -> tuple[object, tuple, dict]:
    """The same for an engine that runs the scene in its own process (OWN_PROCESS)."""
    n = bench.n_bodies
    engine = make_engine(engine_name, bench.scene)
    own = engine.run_scene(bench.warmup_steps, bench.timed_steps)
    rss0 = own["rss_before_build_bytes"]
    timing = dict(
        ms_per_step=own["ms_per_step"],
        cpu_ms_per_step=own["cpu_ms_per_step"],
        build_s=own["build_s"],
        memory_per_body_bytes=(own["rss_warm_bytes"] - rss0) / n,
        memory_built_per_body_bytes=(own["rss_built_bytes"] - rss0) / n,
        peak_rss_bytes=own["peak_rss_bytes"],
        engine_version=engine.version,
    )
    return engine, engine.start(), timing


def run(scene_name: str, engine_name: str) -> dict:
    warm_engine(engine_name)
    bench = build(scene_name)
    polys = LocalPolygons.from_scene(bench.scene)
    timed = _time_in_its_process if engine_name in OWN_PROCESS else _time_in_process
    engine, start, timing = timed(engine_name, bench)
    return dict(
        scene=scene_name,
        engine=engine.name,
        settings=engine.settings,
        n_bodies=bench.n_bodies,
        n_dynamic=bench.n_dynamic,
        dt=bench.scene.world.dt,
        warmup_steps=bench.warmup_steps,
        timed_steps=bench.timed_steps,
        **timing,
        scene_source=bench.scene.source,
        quality=measure_quality(bench, polys, start, engine),
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.worker")
    parser.add_argument("--scene", required=True)
    parser.add_argument("--engine", required=True)
    args = parser.parse_args(argv)
    result = run(args.scene, args.engine)
    sys.stdout.write(json.dumps(result) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
