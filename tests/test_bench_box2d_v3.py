"""The Box2D v3 peer (bench/peers/box2d_v3.py): its source option, its build, its scene export.

The build test needs Box2D v3's source (the tarball the team keeps at
/work/shared/box2d_v3/, or ISAAC_BOX2D_V3), cmake and gcc; it skips, saying which is missing,
elsewhere (CI has no such tarball).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from bench import suite
from bench.geometry import LocalPolygons
from bench.peers import box2d_v3
from bench.scenes import build

TARBALL = Path("/work/shared/box2d_v3/box2d-v3.2.0-617d32ab.tar.gz")
HAS_PYMUNK = importlib.util.find_spec("pymunk") is not None
QUIET = ["--reps", "1", "--no-startup", "--no-recording", "--no-sweep", "--no-readme"]


def _source() -> Path | None:
    value = os.environ.get(box2d_v3.ENV)
    if value and Path(value).exists():
        return Path(value)
    return TARBALL if TARBALL.is_file() else None


def _parse_export(text: str) -> tuple[dict, list[list[str]]]:
    """The header fields and body rows of box2d_v3_scenes.c's scene format, read independently
    of the writer."""
    lines = text.splitlines()
    assert lines[0] == box2d_v3.SCENE_HEADER
    header = {}
    k = 1
    while "bodies" not in header:
        key, *values = lines[k].split()
        header[key] = values
        k += 1
    n = int(header["bodies"][0])
    rows = [line.split() for line in lines[k:]]
    assert len(rows) == n
    return header, rows


@pytest.mark.parametrize("name", ["pyramid-10", "pile-100", "pile-500", "head-on"])
def test_the_exported_scene_is_the_bench_scene_bit_for_bit_with_centred_vertices(name):
    bench = build(name)
    header, rows = _parse_export(box2d_v3.export_scene(bench.scene, 7, 11))
    assert header["steps"] == ["7", "11"]
    assert [float(x) for x in header["gravity"]] == list(bench.scene.world.gravity)
    assert float(header["dt"][0]) == bench.scene.world.dt
    assert header["friction_on"] == [str(int(bench.scene.world.friction))]

    ref = LocalPolygons.from_scene(bench.scene)
    counts = np.array([int(r[10]) for r in rows])
    np.testing.assert_array_equal(counts, ref.vertex_count)
    for k, (row, body) in enumerate(zip(rows, bench.scene.bodies, strict=True)):
        numbers = [float(x) for x in row[1:10]]
        assert row[0] == str(int(body.concrete))
        assert numbers == [
            body.density,
            body.friction,
            body.restitution,
            *body.position,
            body.angle,
            *body.velocity,
            body.angular_velocity,
        ]
        vertices = np.array([float(x) for x in row[11:]]).reshape(-1, 2)
        # exact equality: the same doubles as the vertices every other engine is given
        assert np.array_equal(vertices, ref.vertices_local[k, : counts[k]])


def test_no_source_skips_the_row_with_one_note_in_the_results(tmp_path, monkeypatch):
    if not HAS_PYMUNK:
        pytest.skip("pymunk (the bench extra) is not installed")
    monkeypatch.delenv(box2d_v3.ENV, raising=False)
    args = ["--scenes", "head-on", "--engines", "pymunk,box2d-v3", *QUIET, "--out", str(tmp_path)]
    assert suite.main(args) == 0
    text = (tmp_path / "partial.md").read_text()
    assert text.splitlines().count(box2d_v3.NO_SOURCE_NOTE) == 1
    assert "| head-on | 2 | pymunk |" in text
    assert "| head-on | 2 | box2d-v3 |" not in text


@pytest.mark.parametrize("use_env", [False, True])
def test_a_source_that_is_not_there_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys, use_env):
    missing = tmp_path / "no-such-box2d.tar.gz"
    args = ["--scenes", "head-on", *QUIET, "--out", str(tmp_path)]
    if use_env:
        monkeypatch.setenv(box2d_v3.ENV, str(missing))
    else:
        monkeypatch.delenv(box2d_v3.ENV, raising=False)
        args += ["--box2d-v3", str(missing)]
    assert suite.main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    origin = box2d_v3.ENV if use_env else "--box2d-v3"
    assert err == [f"bench: {origin} {missing}: no such file or folder"]
    assert not (tmp_path / "partial.md").exists()


def test_a_folder_or_file_that_is_not_box2d_is_refused(tmp_path):
    (tmp_path / "CMakeLists.txt").write_text("project(x)\n")
    with pytest.raises(box2d_v3.SourceError, match="no include/box2d/box2d.h"):
        box2d_v3.source_from(str(tmp_path))
    text = tmp_path / "box2d.tar.gz"
    text.write_text("not a tarball")
    with pytest.raises(box2d_v3.SourceError, match="not a Box2D v3 source tree or .tar.gz"):
        box2d_v3.source_from(str(text))


def _broken_tree(root: Path) -> Path:
    """A folder that passes the source check but whose CMakeLists.txt cmake refuses."""
    (root / "include" / "box2d").mkdir(parents=True)
    (root / "include" / "box2d" / "box2d.h").write_text("")
    (root / "CMakeLists.txt").write_text("this is not cmake (\n")
    return root


def test_a_missing_build_tool_names_the_step_and_the_log(tmp_path, monkeypatch):
    src = _broken_tree(tmp_path / "src")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    with pytest.raises(box2d_v3.BuildError) as err:
        box2d_v3.ensure_built(src, cache=tmp_path / "cache")
    assert err.value.step == "configure (cmake)"
    assert str(err.value) == (
        "Box2D v3: not run (build failed at configure (cmake): cmake not found on PATH; "
        f"log: {err.value.log})"
    )
    assert err.value.log.is_file()
    # nothing half-built is left for a later run to take
    assert [p.name for p in (tmp_path / "cache").iterdir()] == [err.value.log.name]


@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed")
def test_a_failed_build_is_one_note_naming_the_step_and_the_other_engines_run(
    tmp_path, monkeypatch, capsys
):
    if not HAS_PYMUNK:
        pytest.skip("pymunk (the bench extra) is not installed")
    src = _broken_tree(tmp_path / "src")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    args = ["--scenes", "head-on", "--engines", "pymunk,box2d-v3", "--box2d-v3", str(src)]
    assert suite.main([*args, *QUIET, "--out", str(tmp_path)]) == 0
    notes = [
        line
        for line in (tmp_path / "partial.md").read_text().splitlines()
        if line.startswith("Box2D v3: not run (build failed at configure (cmake): exit ")
    ]
    assert len(notes) == 1
    log = Path(notes[0].rsplit("log: ", 1)[1].rstrip(")"))
    assert log.is_file() and "CMakeLists.txt" in log.read_text()
    assert "Traceback" not in capsys.readouterr().err


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> box2d_v3.Build:
    src = _source()
    if src is None:
        pytest.skip(f"no Box2D v3 source ({TARBALL} or {box2d_v3.ENV})")
    for tool in ("cmake", "gcc"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")
    return box2d_v3.ensure_built(src, cache=tmp_path_factory.mktemp("cache"))


def test_the_driver_builds_into_the_cache_and_runs_pyramid_10(built):
    assert built.binary.is_file() and built.version.startswith("3.")
    again = box2d_v3.ensure_built(built.source, cache=built.binary.parent.parent)
    assert again.binary == built.binary  # the cache is used, not built twice

    bench = build("pyramid-10")
    engine = box2d_v3.Box2DV3Engine(bench.scene, built)
    figures = engine.run_scene(3, 5)
    assert figures["version"] == built.version
    assert (figures["bodies"], figures["substeps"]) == (56, box2d_v3.SUBSTEPS)
    assert (figures["warmup_steps"], figures["timed_steps"]) == (3, 5)
    assert figures["ms_per_step"] > 0 and figures["build_s"] >= 0
    assert 0 < figures["rss_before_build_bytes"] <= figures["rss_warm_bytes"]
    assert figures["contacts"] > 0

    # the start poses are the scene's positions rounded to float32 (vertices are centred, so
    # the centre of mass is the body origin), before any step
    pos, ang, vel = engine.start()
    expected = np.array([b.position for b in bench.scene.bodies], dtype=np.float32)
    np.testing.assert_array_equal(pos, expected.astype(float))
    assert np.all(ang == 0.0) and np.all(vel == 0.0)
    # 8 steps of semi-implicit Euler under gravity bound how far the top box can fall (m)
    top = bench.info["top"]
    fall = 9.81 * (8 / 60) ** 2
    final, _ = engine.poses()
    assert -fall <= final[top, 1] - pos[top, 1] <= 1e-3
    assert np.all(np.isfinite(final))


def test_pyramid_100_runs_in_box2d_v3(built):
    bench = build("pyramid-100")
    engine = box2d_v3.Box2DV3Engine(bench.scene, built)
    assert engine.run_scene(0, 1)["bodies"] == 5051
    assert engine.poses()[0].shape == (5051, 2)
