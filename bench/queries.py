"""`python -m bench.queries`: a batch of ray casts into the settled pile-2000, ISAAC's
`Simulation.ray_cast_many` against pymunk's `Space.segment_query_first` loop over the same rays,
in one process, interleaved repeat by repeat.

The scene: bench.scenes' pile-2000 (2,003 bodies), settled by ISAAC (`balanced`) over the
scene's warm-up steps. pymunk gets the same polygons at ISAAC's settled poses
(bench/peers/pymunk_engine.py, radius 0), so both engines are asked about the same shapes.

The rays (seeded): origins drawn uniformly in the box from the pile's floor to 1 m above its top
and across its width, kept when outside every shape (`Simulation.closest`: pymunk reports a
hit at fraction 0 from inside a shape, ISAAC none, as Box2D); directions uniform in angle,
3 m long (segments: ISAAC's max_fraction 1, pymunk's end point origin + direction).

Time: per ray, the median over `repeats` of one `ray_cast_many` call (all the rays: its input
checks, world geometry, grid and walk) and of the Python loop of `segment_query_first` calls;
the ratio ISAAC / pymunk (issue 39's target: at most 0.5). Agreement: the share of rays where
both engines report the same body (or both none), and the largest fraction difference among
those. Run on the machine as it is: say how busy it was beside the figures.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace

import numpy as np

SCENE = "pile-2000"
RAYS = 10_000
RAY_LENGTH = 3.0  # m
SEED = 39


def settled(scene_name: str = SCENE):
    """(Simulation, BenchScene): ISAAC `balanced` after the scene's warm-up steps."""
    from bench.scenes import build, with_preset
    from isaac.engine.simulation import Simulation

    bench_scene = build(scene_name)
    sim = Simulation(with_preset(bench_scene.scene, "balanced"))
    sim.advance(bench_scene.warmup_steps)
    return sim, bench_scene


def rays(sim, count: int = RAYS, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """(origins, directions) (count, 2) m: origins in the pile's box and 1 m above it, outside
    every shape; directions RAY_LENGTH long, uniform in angle."""
    rng = np.random.default_rng(seed)
    moving = ~sim.model.concrete
    pos = sim.state.position[moving]
    lo = pos.min(axis=0) - 0.3
    hi = pos.max(axis=0) + np.array([0.3, 1.0])
    origins = []
    while len(origins) < count:
        for o in rng.uniform(lo, hi, size=(count, 2)):
            if sim.closest(o).distance > 0.0:
                origins.append(o)
                if len(origins) == count:
                    break
    turn = rng.uniform(-np.pi, np.pi, size=count)
    directions = RAY_LENGTH * np.stack([np.cos(turn), np.sin(turn)], axis=1)
    return np.array(origins), directions


def pymunk_space(sim, bench_scene):
    """pymunk's space of the scene's polygons at the simulation's current poses."""
    from bench.peers.pymunk_engine import PymunkEngine

    bodies = tuple(
        replace(b, position=tuple(sim.state.position[i]), angle=float(sim.state.angle[i]))
        for i, b in enumerate(bench_scene.scene.bodies)
    )
    engine = PymunkEngine(replace(bench_scene.scene, bodies=bodies))
    shapes = {id(next(iter(b.shapes))): i for i, b in enumerate(engine.bodies)}
    return engine.space, shapes


def pymunk_cast(space, shapes, origins, directions):
    """(body (m,), fraction (m,)): pymunk's first hit of each segment, -1 / NaN for none."""
    import pymunk

    everything = pymunk.ShapeFilter()
    query = space.segment_query_first
    body = np.full(len(origins), -1, dtype=np.int64)
    fraction = np.full(len(origins), np.nan)
    for k, ((ox, oy), (dx, dy)) in enumerate(zip(origins.tolist(), directions.tolist())):
        info = query((ox, oy), (ox + dx, oy + dy), 0.0, everything)
        if info is not None:
            body[k] = shapes[id(info.shape)]
            fraction[k] = info.alpha
    return body, fraction


def measure(repeats: int = 7, count: int = RAYS) -> dict:
    import pymunk

    sim, bench_scene = settled()
    origins, directions = rays(sim, count)
    space, shapes = pymunk_space(sim, bench_scene)
    everything = pymunk.ShapeFilter()
    query = space.segment_query_first
    ends = (origins + directions).tolist()
    starts = origins.tolist()
    sim.ray_cast_many(origins, directions)  # compile or load the kernels
    ours, theirs = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        hits = sim.ray_cast_many(origins, directions)
        ours.append(time.perf_counter() - t)
        t = time.perf_counter()
        for a, b in zip(starts, ends):
            query(a, b, 0.0, everything)
        theirs.append(time.perf_counter() - t)
    body, fraction = pymunk_cast(space, shapes, origins, directions)
    same = hits.body == body
    both = same & (body >= 0)
    us_isaac = statistics.median(ours) / count * 1e6
    us_pymunk = statistics.median(theirs) / count * 1e6
    return {
        "scene": SCENE,
        "bodies": sim.n_bodies,
        "rays": count,
        "repeats": repeats,
        "isaac_us_per_ray": us_isaac,
        "pymunk_us_per_ray": us_pymunk,
        "ratio_to_pymunk": us_isaac / us_pymunk,
        "hit_share_isaac": float(np.mean(hits.body >= 0)),
        "hit_share_pymunk": float(np.mean(body >= 0)),
        "same_body_share": float(np.mean(same)),
        "largest_fraction_difference": float(
            np.max(np.abs(hits.fraction[both] - fraction[both])) if both.any() else 0.0
        ),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.queries", description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--rays", type=int, default=RAYS)
    parser.add_argument("--json", action="store_true", help="one JSON line")
    args = parser.parse_args(argv)
    row = measure(args.repeats, args.rays)
    if args.json:
        print(json.dumps(row))
    else:
        print(
            f"{row['scene']} ({row['bodies']} bodies), {row['rays']} rays, median of "
            f"{row['repeats']}: ISAAC {row['isaac_us_per_ray']:.3g} us/ray, pymunk "
            f"{row['pymunk_us_per_ray']:.3g} us/ray, ratio {row['ratio_to_pymunk']:.3g}; "
            f"same body {100 * row['same_body_share']:.2f}% (hits: ISAAC "
            f"{100 * row['hit_share_isaac']:.1f}%, pymunk {100 * row['hit_share_pymunk']:.1f}%), "
            f"largest fraction difference {row['largest_fraction_difference']:.3g}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
