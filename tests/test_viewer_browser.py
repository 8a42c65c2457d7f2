"""What a person sees: a recording opened in the Rerun web viewer, in headless Chromium.

`make test-viewer` runs this (it is marked slow: the viewer takes 15-40 s to load on a quiet
machine, minutes on a loaded one). Chromium is Debian's package, installed with apt-get when
missing (tests/viewer_browser.py); the test is skipped only when that fails, saying why.
With ISAAC_VIEWER_FIGURE=PATH the screenshot is also copied to PATH (how
docs/figures/viewer_default.png was made).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from viewer_browser import Chromium, WebViewer, ensure_chromium  # noqa: E402

from recorder import blueprint  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
LOAD_TIMEOUT_S = 420  # a loaded 2-core machine took 150 s to show the first frame


def _near(image: np.ndarray, rgb, tol: int) -> np.ndarray:
    """(h, w) bool: pixels within ``tol`` of ``rgb`` in every channel."""
    diff = np.abs(image[:, :, :3].astype(np.int16) - np.array(rgb, dtype=np.int16))
    return np.all(diff <= tol, axis=2)


def look(png: Path) -> dict:
    """What the screenshot shows, from its pixels (image rows grow downwards):

    view_fraction: the bounding box of the 2D view's background colour, as a fraction of the
        window; view_box: that box, (top, bottom, left, right) rows and columns; floor_row: the
        topmost row of the lowest band of rows that are mostly concrete colour (the floor, seen
        across the view); body_rows: rows of moving-body outline pixels.
    """
    from PIL import Image

    image = np.asarray(Image.open(png).convert("RGB"))
    h, w = image.shape[:2]
    out: dict = {"size": (w, h), "view_fraction": 0.0, "floor_row": None, "body_rows": None}
    # the view's background colour, exactly; rows and columns where it is a fifth or more of
    # the pixels (anti-aliased edges elsewhere in the window hit the colour here and there)
    bg = _near(image, blueprint.BACKGROUND, 0)
    rows = np.flatnonzero(bg.sum(axis=1) > 0.2 * w)
    cols = np.flatnonzero(bg.sum(axis=0) > 0.2 * h)
    if rows.size == 0 or cols.size == 0:
        return out
    top, bottom, left, right = rows[0], rows[-1], cols[0], cols[-1]
    out["view_fraction"] = (bottom - top + 1) * (right - left + 1) / (w * h)
    out["view_box"] = (int(top), int(bottom), int(left), int(right))
    inside = image[top : bottom + 1, left : right + 1]
    concrete = _near(inside, blueprint.CONCRETE.rgb, 20)
    wide = np.flatnonzero(concrete.sum(axis=1) > 0.4 * inside.shape[1])
    if wide.size:
        # the lowest band of consecutive wide rows
        breaks = np.flatnonzero(np.diff(wide) > 1)
        start = wide[breaks[-1] + 1] if breaks.size else wide[0]
        out["floor_row"] = int(start + top)
    moving = _near(inside, blueprint.MOVING.rgb, 30)
    if moving.sum():
        out["body_rows"] = np.flatnonzero(moving) // inside.shape[1] + top
    return out


def _browser_and_recording(scene: str, tmp_path: Path) -> tuple[str, Path]:
    """Debian's Chromium (the test is skipped without it) and 300 steps of scenes/SCENE.yaml
    recorded by `isaac run --rrd`, as a user would."""
    chromium, why = ensure_chromium()
    if chromium is None:
        pytest.skip(f"no headless browser: {why}")
    rrd = tmp_path / f"{scene}.rrd"
    run = subprocess.run(
        [sys.executable, "-m", "isaac", "run", f"scenes/{scene}.yaml", "--steps", "300"]
        + ["--rrd", str(rrd), "--quiet"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    return chromium, rrd


def right_way_up(seen: dict) -> bool:
    rows = seen["body_rows"]
    floor = seen["floor_row"]
    if rows is None or floor is None or rows.size < 500:
        return False
    return bool(np.mean(rows < floor) > 0.95)


@pytest.mark.slow
def test_the_web_viewer_shows_the_pile_above_its_floor_in_a_view_taking_most_of_the_window(
    tmp_path,
):
    chromium, rrd = _browser_and_recording("default", tmp_path)
    png = tmp_path / "viewer.png"
    seen: dict = {}
    with WebViewer(rrd) as viewer, Chromium(chromium, width=1600, height=1000) as browser:
        browser.open(viewer.url)
        deadline = time.monotonic() + LOAD_TIMEOUT_S
        while time.monotonic() < deadline:
            time.sleep(5)
            browser.screenshot(png)
            seen = look(png)
            if right_way_up(seen) and seen["view_fraction"] > 0.5:
                time.sleep(3)  # the last batches drawn: a settled frame for the figure
                browser.screenshot(png)
                seen = look(png)
                break
        servers = [viewer.proc, browser.proc]
    assert all(p.poll() is not None for p in servers)  # both stopped
    figure = os.environ.get("ISAAC_VIEWER_FIGURE")
    if figure:
        shutil.copyfile(png, figure)
    assert seen.get("floor_row") is not None, f"no floor seen in {png}: {seen}"
    assert right_way_up(seen), (
        f"{png}: floor at row {seen['floor_row']}, bodies' median row "
        f"{np.median(seen['body_rows']) if seen['body_rows'] is not None else None}"
    )
    assert seen["view_fraction"] > 0.5, f"{png}: the 2D view fills {seen['view_fraction']:.0%}"


def test_the_pixel_check_tells_an_upside_down_scene_from_a_right_one(tmp_path):
    from PIL import Image

    window = np.full((1000, 1600, 3), 255, dtype=np.uint8)  # the viewer's own white panels
    view = window[40:960, 0:1200]
    view[:] = blueprint.BACKGROUND
    view[880:895, 100:1100] = blueprint.CONCRETE.rgb  # the floor
    view[100:880, 100:115] = blueprint.CONCRETE.rgb  # a wall: narrow, not a floor
    for k in range(40):  # bodies resting on the floor: outlines' pixels
        x, y = 150 + 23 * k, 700 + (k % 7) * 20
        view[y : y + 40, x : x + 3] = blueprint.MOVING.rgb
    right, flipped = tmp_path / "right.png", tmp_path / "flipped.png"
    Image.fromarray(window).save(right)
    window[40:960, 0:1200] = view[::-1].copy()
    Image.fromarray(window).save(flipped)
    seen = look(right)
    assert right_way_up(seen) and seen["floor_row"] == 40 + 880
    assert abs(seen["view_fraction"] - 1200 * 920 / (1600 * 1000)) < 1e-9
    assert not right_way_up(look(flipped))


@pytest.mark.slow
def test_the_web_viewer_draws_the_pendulums_rod_down_from_its_pivot(tmp_path):
    chromium, rrd = _browser_and_recording("pendulum", tmp_path)
    from PIL import Image

    png = tmp_path / "pendulum.png"
    rod = pivot = None
    with WebViewer(rrd) as viewer, Chromium(chromium, width=1600, height=1000) as browser:
        browser.open(viewer.url)
        deadline = time.monotonic() + LOAD_TIMEOUT_S
        while time.monotonic() < deadline:
            time.sleep(5)
            browser.screenshot(png)
            seen = look(png)
            if seen["view_fraction"] <= 0.5:
                continue
            top, bottom, left, right = seen["view_box"]
            view = np.asarray(Image.open(png).convert("RGB"))[top:bottom, left:right]
            rod = np.argwhere(_near(view, blueprint.JOINT.rgb, 25))  # (row, column)
            pivot = np.argwhere(_near(view, blueprint.CONCRETE.rgb, 20))
            if len(rod) > 300 and len(pivot) > 50:
                break
    assert rod is not None and len(rod) > 300, f"{png}: no joint line drawn"
    height = rod[:, 0].max() - rod[:, 0].min()
    width = rod[:, 1].max() - rod[:, 1].min()
    # a 1 m rod 0.1 rad or less off the vertical, in a view fitted to it: long and upright
    assert height > 0.25 * view.shape[0] and width < 0.3 * height, (png, height, width)
    # hanging: the pivot (the concrete box) at the rod's top end, the bob below it
    assert abs(np.median(pivot[:, 0]) - rod[:, 0].min()) < 0.1 * height, png
