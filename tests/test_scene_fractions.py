"""Times written as fractions (`dt: 1/120`, `enters_at: 1/3`): read as the correctly rounded
float, kept as written in the scene text a log embeds, refused in one line when malformed."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from isaac.app.tradeoff.grid import TradeoffError, parse_dt
from isaac.errors import SceneError
from isaac.scene import fast_reader, load_scene_text, scene_to_yaml

ROOT = Path(__file__).resolve().parents[1]

SCENE = """world: {dt: 1/120, steps: 40}
bodies:
  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
  - {name: box, shape: {box: [1, 1]}, position: [0, 0.5], enters_at: 1/3, leaves_at: 5/3}
"""


def test_a_fraction_is_the_float_python_divides_to():
    scene = load_scene_text(SCENE)
    assert scene.world.dt == 1 / 120
    assert scene.bodies[1].enters_at == 1 / 3 and scene.bodies[1].leaves_at == 5 / 3
    # the same scene written in decimals is the same scene
    decimals = SCENE.replace("1/120", repr(1 / 120)).replace("1/3", repr(1 / 3))
    assert load_scene_text(decimals.replace("5/3", repr(5 / 3))) == scene


def test_the_written_scene_keeps_fractions_as_written_and_reads_back_through_both_readers():
    scene = load_scene_text(SCENE)
    text = scene_to_yaml(scene)
    assert "  dt: 1/120\n" in text
    assert "    enters_at: 1/3\n    leaves_at: 5/3\n" in text
    again = load_scene_text(text)  # the log's line reader
    with mock.patch.object(fast_reader, "read", lambda *args, **kwargs: None):
        by_yaml = load_scene_text(text)
    for other in (again, by_yaml):
        assert other == scene and other.world.dt == 1 / 120
        assert scene_to_yaml(other) == text


def test_a_scene_changed_in_python_writes_its_new_value_not_the_old_fraction():
    scene = load_scene_text(SCENE)
    changed = dataclasses.replace(scene, world=dataclasses.replace(scene.world, dt=0.01))
    text = scene_to_yaml(changed)
    assert "  dt: 0.01\n" in text and "1/120" not in text
    assert load_scene_text(text).world.dt == 0.01


@pytest.mark.parametrize(
    ("value", "says"),
    [
        ("1/0", "world.dt: the fraction 1/0 divides by zero; give seconds (0.01) or whole "
                "numbers either side of one / (1/120)"),
        ("1.5/60", "world.dt: cannot read 1.5/60 as a fraction of whole numbers; give seconds"),
        ("1/2/3", "world.dt: cannot read 1/2/3 as a fraction of whole numbers"),
        ("-1/60", "world.dt: -1/60 = -0.016666666666666666 s is out of range (must be > 0.0 "
                  "and <= 1.0)"),
        ("3/2", "world.dt: 3/2 = 1.5 s is out of range"),
    ],
)  # fmt: skip
def test_a_bad_fraction_is_one_line_naming_the_key(value, says):
    with pytest.raises(SceneError) as info:
        load_scene_text(SCENE.replace("1/120", value), source="s.yaml")
    message = str(info.value)
    assert message.startswith("s.yaml:1: ") and says in message and "\n" not in message


def test_a_bad_fraction_in_a_logs_form_gets_the_yaml_readers_message_at_its_line():
    text = scene_to_yaml(load_scene_text(SCENE)).replace("enters_at: 1/3", "enters_at: 1/0")
    with pytest.raises(SceneError) as info:
        load_scene_text(text, source="log")
    assert "bodies[1].enters_at: the fraction 1/0 divides by zero" in str(info.value)
    line = text.splitlines().index("    enters_at: 1/0") + 1
    assert str(info.value).startswith(f"log:{line}: ")


def test_leaves_at_as_a_fraction_must_still_come_after_enters_at():
    with pytest.raises(SceneError) as info:
        load_scene_text(SCENE.replace("5/3", "1/4"))
    assert "leaves_at (0.25 s) must be later than enters_at (0.3333333333333333 s)" in str(
        info.value
    )


def test_tradeoff_grid_reads_dt_fractions_with_the_same_function():
    assert parse_dt("1/120", 0.01) == 1 / 120 and parse_dt("x1/2", 0.01) == 0.005
    with pytest.raises(TradeoffError):
        parse_dt("1/0", 0.01)


def test_the_log_embeds_the_fraction_as_written_and_replays_identical(tmp_path):
    scene = tmp_path / "frac.yaml"
    scene.write_text(SCENE)
    log = tmp_path / "frac.mcap"
    run = [sys.executable, "-m", "isaac"]
    done = subprocess.run(
        [*run, "run", str(scene), "--quiet", "--mcap", str(log)], cwd=ROOT, capture_output=True,
        text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    from recorder.reader import LogReader

    embedded = LogReader(str(log)).scene_text
    assert "  dt: 1/120\n" in embedded and "    enters_at: 1/3\n" in embedded
    done = subprocess.run(
        [*run, "replay", str(log)], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0 and done.stdout.startswith("identical"), done.stdout + done.stderr


@settings(max_examples=100, deadline=None)
@given(
    st.integers(1, 10**6),
    st.integers(1, 10**6),
    st.integers(0, 10**6),
    st.integers(1, 10**6),
)
def test_any_fraction_reads_as_python_divides_and_writes_back_as_written(n, d, e, f):
    dt = f"{min(n, d)}/{d}"  # in (0, 1]
    enters = f"{e}/{f}"
    text = (
        f"world: {{dt: {dt}}}\nbodies:\n"
        f"  - {{name: a, shape: {{box: [1, 1]}}, enters_at: {enters}}}\n"
    )
    scene = load_scene_text(text)
    assert scene.world.dt == min(n, d) / d and scene.bodies[0].enters_at == e / f
    written = scene_to_yaml(scene)
    assert f"  dt: {dt}\n" in written and f"    enters_at: {enters}\n" in written
    again = load_scene_text(written)
    assert again == scene and scene_to_yaml(again) == written


def test_check_prints_the_time_step_as_written_and_its_value(tmp_path):
    scene = tmp_path / "frac.yaml"
    scene.write_text(SCENE)
    done = subprocess.run(
        [sys.executable, "-m", "isaac", "check", str(scene)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert f"dt 1/120 s ({1 / 120!r}), 40 steps" in done.stdout


def test_a_warning_names_a_time_as_written():
    from isaac.scene.warnings import scene_warnings

    (line,) = scene_warnings(load_scene_text(SCENE), steps=20)  # the box enters at 1/3 s
    assert "the body 'box' enters at 1/3 s, after the run's last step (20, t = 0.166667 s)" in line
