"""bench/sweep.py: the sweeps it times are the issue's cases, and it judges its targets right
(no timing is asserted: the figures are the bench's, bench/README.md)."""

from __future__ import annotations

from bench import sweep as sweep_bench
from isaac.app.sweep import load_sweep


def test_the_timed_sweeps_are_the_issues_cases(tmp_path):
    sweeps = sweep_bench.write_sweeps(tmp_path)
    assert set(sweeps) == {(c, r) for c in ("bounce", "pile-100") for r in ("none", "mcap")}
    for (case, record), path in sweeps.items():
        s = load_sweep(path)
        assert s.n_runs == (1000 if case == "bounce" else 100)
        assert s.steps == 200 and s.record == record
        polygons = [b for b in s.scene.bodies if not b.concrete]
        assert len(polygons) == (1 if case == "bounce" else 100)
        assert len({s.params(i)[s.axes[0].key] for i in range(20)}) == 20  # drawn per run
    assert load_sweep(sweep_bench.write_sweeps(tmp_path / "q", 0.1)["bounce", "none"]).n_runs == 100


def _case(name, record, one, two):
    return dict(
        case=name, record=record, speedup=two / one, w1={"runs_per_s": one}, w2={"runs_per_s": two}
    )


def test_targets_are_judged_against_the_issues_limits():
    result = {
        "cases": [
            _case("bounce", "none", 200.0, 350.0),  # 1.75x, 350 runs/s: both met
            _case("bounce", "mcap", 60.0, 90.0),  # 1.5x, 90 runs/s: neither
            _case("pile-100", "none", 10.0, 17.0),  # exactly 1.7x: met
            _case("pile-100", "mcap", 5.0, 8.0),
        ]
    }
    got = {t["what"]: t["met"] for t in sweep_bench.targets(result)}
    assert got == {
        "speed-up 1 -> 2 workers, bounce, record none": True,
        "speed-up 1 -> 2 workers, bounce, record mcap": False,
        "speed-up 1 -> 2 workers, pile-100, record none": True,
        "speed-up 1 -> 2 workers, pile-100, record mcap": False,
        "runs/s, bounce, record none, 2 workers": True,
        "runs/s, bounce, record mcap, 2 workers": False,
    }
