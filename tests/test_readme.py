"""The README stays a short guide that is true to the code: its two set-up commands open it, its
scene example loads, and the physics version it names is the engine's."""

from __future__ import annotations

import re
from pathlib import Path

from isaac.engine import PHYSICS_VERSION
from isaac.scene import load_scene_text

README = (Path(__file__).resolve().parent.parent / "README.md").read_text()


def test_the_readme_is_at_most_150_lines_and_opens_with_make_run_and_make_test():
    assert len(README.splitlines()) <= 150
    first_block = re.search(r"```sh\n(.*?)```", README, re.S).group(1)
    commands = [line.split("#")[0].strip() for line in first_block.splitlines()]
    assert commands == ["make run", "make test"]


def test_the_readme_scene_example_loads():
    (example,) = re.findall(r"```yaml\n(.*?)```", README, re.S)
    scene = load_scene_text(example)
    assert scene.name == "drop" and len(scene.bodies) > 3  # the pile expanded


def test_the_readme_names_the_engines_physics_version():
    versions = re.findall(r"physics version (\d+)", README)
    assert versions and all(int(v) == PHYSICS_VERSION for v in versions)
