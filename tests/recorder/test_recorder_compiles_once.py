"""Each of the recorder's compiled packers and drawers compiles once per run, not once per kind
of array it is handed: numba compiles a kernel per argument types, and a writable and a
read-only array are two types (`recorder.pack.read_only`). Before, the first record's writable
arrays, the batches' read-only ones and the writable placeholders compiled `pack_records` three
times on a first run (14.3 + 8.8 + 2.8 s)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

# a whole recorded run (both files, written by a thread of this process, as `isaac run` does),
# then the number of signatures each kernel compiled or loaded
_RUN = """
import json, sys
from isaac import Simulation, load_scene
from recorder import Recorder, mcap_pack, rerun_batch

sim = Simulation(load_scene(sys.argv[1]))
with Recorder(sim, mcap_path=sys.argv[2], rrd_path=sys.argv[3], offload="thread") as rec:
    rec.write(sim.record())
    for batch in sim.batches(int(sys.argv[4]), size=50):
        rec.write_batch(batch)
kernels = [mcap_pack.first_unfit, mcap_pack.record_sizes, mcap_pack.pack_records,
           mcap_pack.scan_records, mcap_pack.index_entries, rerun_batch.step_outlines,
           rerun_batch.draw_steps, rerun_batch.batch_stats]
print(json.dumps({k.__name__: len(k.signatures) for k in kernels}))
"""


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="counts compiled kernels")
def test_a_recorded_run_compiles_each_packer_and_drawer_once(tmp_path):
    # a scene whose bodies enter and leave (its batches carry /world records, others none)
    out = subprocess.run(
        [sys.executable, "-c", _RUN, str(REPO / "scenes" / "default.yaml"),
         str(tmp_path / "run.mcap"), str(tmp_path / "run.rrd"), "400"],
        capture_output=True, text=True, cwd=REPO, check=True,
    )  # fmt: skip
    counts = json.loads(out.stdout.splitlines()[-1])
    assert counts == {name: 1 for name in counts}, counts
    assert len(counts) == 8
