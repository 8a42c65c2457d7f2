"""First recorded run with an empty numba cache (`recorder.compile_ahead`): a helper process
compiles the recorder's kernels beside the engine's. It is only worth its CPU if it compiles
the very kernels the run calls (numba specialises on argument types: one type off and the run
compiles its own again), so the helper's signatures are checked against a real recorded run's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
KERNELS = (
    "mcap_pack.first_unfit mcap_pack.record_sizes mcap_pack.pack_records mcap_pack.scan_records "
    "mcap_pack.index_entries rerun_batch.step_outlines rerun_batch.draw_steps "
    "rerun_batch.batch_stats"
).split()

# what each kernel was compiled (or loaded) for, once the recording in {how} is done
_SIGNATURES = """
import json, os, sys, tempfile
from isaac import Simulation, load_scene
from recorder import Recorder, compile_ahead, mcap_pack, rerun_batch

scene = load_scene(sys.argv[1])
if sys.argv[2] == "helper":
    compile_ahead.compile_kernels(scene.world, mcap=True, rrd=True, joints=bool(scene.joints))
else:  # as `isaac run` records: the first record, then batches, the MCAP writer's thread
    sim = Simulation(scene)
    with tempfile.TemporaryDirectory() as tmp:
        with Recorder(sim, mcap_path=os.path.join(tmp, "a.mcap"),
                      rrd_path=os.path.join(tmp, "a.rrd"), offload="thread") as rec:
            for batch in sim.batches(120, size=50):
                rec.write_batch(batch)
modules = {"mcap_pack": mcap_pack, "rerun_batch": rerun_batch}
out = {}
for name in sys.argv[3].split(","):
    module, kernel = name.split(".")
    out[name] = sorted(str(s) for s in getattr(modules[module], kernel).signatures)
print(json.dumps(out))
"""


def _signatures(scene: str, how: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", _SIGNATURES, str(REPO / "scenes" / scene), how, ",".join(KERNELS)],
        capture_output=True, text=True, cwd=REPO, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.splitlines()[-1])


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="compares compiled kernels")
@pytest.mark.parametrize("scene", ["default.yaml", "pendulum.yaml"])
def test_the_helper_compiles_the_kernels_a_recorded_run_calls(scene):
    helper, run = _signatures(scene, "helper"), _signatures(scene, "run")
    assert all(run[k] for k in KERNELS)  # the run called every one of them
    assert helper == run


@pytest.mark.slow
def test_a_first_recorded_run_gets_the_recorders_kernels_from_the_helper(tmp_path):
    """A whole `isaac run --mcap --rrd` in an empty cache (about 30 s on 2 cores): the helper
    fills the cache with the recorder's kernels, the run's files are complete, and neither the
    helper nor its temporary folder is left behind."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "TMPDIR": str(tmp_path)}
    env.pop("NUMBA_DISABLE_JIT", None)
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    cmd = [str(Path(sys.executable).parent / "isaac"), "run", "scenes/bounce.yaml"]
    done = subprocess.run(
        [*cmd, "--mcap", str(mcap), "--rrd", str(rrd)],
        capture_output=True, text=True, cwd=REPO, env=env, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "compiling the engine's kernels" in done.stderr
    assert mcap.is_file() and rrd.is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("isaac-recorder-compile-")]
    cached = {p.name.split("-")[0] for p in (tmp_path / "cache").rglob("*.nbi")}
    assert {"mcap_pack.pack_records", "rerun_batch.draw_steps"} <= cached
