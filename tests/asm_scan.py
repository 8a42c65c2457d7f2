"""Scan the machine code of numba kernels for fused multiply-add and libm calls.

`scan(asm)` reads one kernel's x86-64 assembly (``dispatcher.inspect_asm(signature)``).
Run as a script (``python tests/asm_scan.py``, by tests/test_no_platform_math.py in a process
with a fresh NUMBA_CACHE_DIR: numba cannot show the code of a kernel it loaded from its cache),
it compiles the project's kernels by running small scenes through every path of the step (each
preset, both drivers and the staged step, friction, ccd on and off, bodies entering), the
replay's frame encoder and the MCAP recorder's frame packing, then writes one JSON object to
the file named by its argument: every dispatcher of isaac.engine, recorder and replay with its
compiled signatures and what the scan found in each.
"""

from __future__ import annotations

import json
import re
import sys

# x86 FMA3 and FMA4 mnemonics: vfmadd132sd, vfmsub213pd, vfnmadd231ss, vfmaddsub..., vfmaddsd
FMA = re.compile(r"^\s*(vf(?:n)?m(?:add|sub)\w*)\b", re.IGNORECASE | re.MULTILINE)
# symbols the code calls or loads for a call: `movabsq $sin, %rax` + `callq *%rax` (numba's
# way), `callq sin@PLT`, `jmp sin` (a tail call)
SYMBOL = re.compile(
    r"^\s*(?:movabs\w*\s+\$|call\w*\s+|jmp\w*\s+)\"?([A-Za-z_.$][\w.$@]*)\"?",
    re.MULTILINE,
)
# libm's transcendental and other inexact functions (exact ones, floor, fabs, fmod,
# remainder, copysign, would be harmless)
LIBM = frozenset(
    "sin cos tan asin acos atan atan2 sinh cosh tanh asinh acosh atanh sincos exp exp2 exp10 "
    "expm1 log log2 log10 log1p logb pow hypot cbrt erf erfc lgamma tgamma gamma j0 j1 jn y0 "
    "y1 yn fma".split()
)
_LIBM_NAME = re.compile(r"^(?:__)?(?:numba_)?([a-z0-9]+?)(?:f|l)?(?:_finite)?(?:@PLT)?$")


def scan(asm: str) -> dict[str, list[str]]:
    """{"fma": FMA instructions, "libm": libm functions called} found in `asm`."""
    fma = sorted(set(m.group(1).lower() for m in FMA.finditer(asm)))
    libm = set()
    for m in SYMBOL.finditer(asm):
        name = _LIBM_NAME.match(m.group(1))
        if name and (name.group(1) in LIBM or m.group(1).split("@")[0] in LIBM):
            libm.add(m.group(1).split("@")[0])
    return {"fma": fma, "libm": sorted(libm)}


def _exercise() -> None:
    """Run every path of the step once, compiling what it calls (types decide, not sizes)."""
    from dataclasses import replace

    from isaac.engine.simulation import Simulation
    from isaac.scene import load_scene, load_scene_text
    from replay.compare import StepEncoder

    stack = (
        "name: s\nworld: {{dt: 0.016666666666666666, fidelity: {preset}, friction: {friction}, "
        "ccd: {ccd}}}\nbodies:\n"
        "  - {{name: ground, shape: {{box: [6.0, 1.0]}}, position: [0.0, -0.5], concrete: true}}\n"
        "  - {{name: box, shape: {{box: [1.0, 1.0]}}, position: [0.0, 0.5]}}\n"
        "  - {{name: p, shape: {{regular: {{sides: 5, radius: 0.5}}}}, position: [0.1, 1.6], "
        "angle: 0.3, enters_at: 0.02}}\n"
    )
    scenes = [load_scene("scenes/head_on.yaml"), load_scene("scenes/spawn.yaml")]
    for preset in ("seed", "fast", "balanced", "accurate"):
        for friction, ccd in (("true", "speculative"), ("false", "off")):
            scenes.append(load_scene_text(stack.format(preset=preset, friction=friction, ccd=ccd)))
    # a scene with joints: its driver, solver and the joints' kernels are specialisations of
    # their own (a scene without joints never compiles them)
    jointed = load_scene("scenes/car.yaml")
    for scene in (*scenes, jointed):
        scene = replace(scene, world=replace(scene.world, steps=6))
        sim = Simulation(scene, compile_ahead=False)  # compile here, not load from the cache
        encoder = StepEncoder(sim.model, tuple(float(g) for g in scene.world.gravity))
        for _ in range(3):
            encoder.encode(sim.step())  # the staged step
        for record in sim.run(3):  # the fused driver
            encoder.encode(record)
    # the world queries (isaac.engine.queries), on polygons and a circle
    queried = Simulation(load_scene("scenes/rolling.yaml"), compile_ahead=False)
    queried.ray_cast_many([[-5.0, 3.0], [0.0, 5.0]], [[10.0, -3.0], [0.0, -10.0]])
    queried.overlaps(0.5, (0.0, 0.5))
    queried.overlaps([[0, 0], [1, 0], [0, 1]], (0.0, 0.5, 0.2))
    queried.closest((0.0, 3.0))
    # the timed drivers (isaac run --profile), with either solver
    for scene in (*scenes[:3], jointed):
        scene = replace(scene, world=replace(scene.world, steps=3))
        Simulation(scene, compile_ahead=False, profile=True).advance(3)
    # the finiteness check the recorder's stats fall back on (on a record of the run: every
    # array read-only, one tuple type)
    from isaac.engine.diagnostics import all_finite

    all_finite(record)
    # what a writer process does with the records its parent packed without their state
    # hashes (`put_hashes`): here, and before any writer process runs, which would compile it
    # into the shared cache, and this process would load it from there (uninspectable)
    import numpy as np

    from recorder.mcap_pack import BatchPacker, put_hashes
    from recorder.mcap_writer import encode_world, record_channels

    sim = Simulation(scenes[1], compile_ahead=False)
    batch = next(sim.batches(4, size=4))
    channels = record_channels(False)
    gravity = tuple(float(g) for g in scenes[1].world.gravity)
    packer = BatchPacker(
        sim.model, gravity, scenes[1].world.dt, channels, (), encode_world=encode_world,
        hashes=False,
    )  # fmt: skip
    plan = packer.plan(batch, None)
    buf = np.zeros(int(plan.sizes.sum()), dtype=np.uint8)
    _, end, _ = packer.pack(buf, 0, 0, batch.steps, batch, plan)
    put_hashes(buf, 0, end, channels)
    # the recorder packs MCAP frames in this process: offload "none" writes the file here too,
    # "process" hands the packed frames to a child; both pack a batch with one compiled call
    import tempfile

    from recorder import Recorder

    with tempfile.TemporaryDirectory() as tmp:
        # (with the Foxglove channel a writer process is handed whole frames, `pack_frames`)
        for offload, foxglove in (
            ("none", False),
            ("thread", False),  # the run's thread checks each batch (`first_unfit`)
            ("process", False),
            ("process", True),
        ):
            sim = Simulation(scenes[1], compile_ahead=False)
            path = f"{tmp}/{offload}-{foxglove}.mcap"
            with Recorder(sim, mcap_path=path, offload=offload, foxglove=foxglove) as recorder:
                for batch in sim.batches(4, size=4):
                    recorder.write_batch(batch)


def _dispatchers():
    import importlib
    import pkgutil

    from numba.core.registry import CPUDispatcher

    import isaac.engine
    import recorder
    import replay

    seen = {}
    for package in (isaac.engine, recorder, replay):
        names = [package.__name__] + [
            m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")
        ]
        for name in sorted(names):
            module = importlib.import_module(name)
            for _attr, value in sorted(vars(module).items()):
                if isinstance(value, CPUDispatcher):
                    key = f"{value.py_func.__module__}.{value.py_func.__qualname__}"
                    seen.setdefault(key, value)
    return seen


def main() -> int:
    _exercise()
    out = {}
    for key, dispatcher in sorted(_dispatchers().items()):
        out[key] = {
            "inline": dispatcher.targetoptions.get("inline") == "always",
            "signatures": {
                str(sig): scan(dispatcher.inspect_asm(sig)) for sig in dispatcher.signatures
            },
            # loaded from numba's cache (a writer process compiled it first): numba shows no
            # code for those, so the scan above saw nothing
            "cached": sorted(
                str(sig)
                for sig, compiled in dispatcher.overloads.items()
                if getattr(compiled.library, "_disable_inspection", False)
            ),
        }
    with open(sys.argv[1], "w", encoding="utf-8") as f:
        json.dump(out, f)
    return 0


if __name__ == "__main__":
    # the project's root, not tests/ (whose recorder/ and replay/ folders would shadow the
    # packages)
    from pathlib import Path

    sys.path[0] = str(Path(__file__).resolve().parents[1])
    sys.exit(main())
