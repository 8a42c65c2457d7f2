"""The settings to compare: presets x dt values by default, or any `--grid KEY=V1,V2` axes."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, fields, replace

from isaac.errors import IsaacError, SceneError
from isaac.scene import PRESETS, WorldSettings, load_scene_text
from isaac.scene.reader import fraction

PRESET_ORDER = ("seed", "fast", "balanced", "accurate")
DEFAULT_DT_FACTORS = (2.0, 1.0, 0.5)  # the default dt axis: the scene's dt times these
REFERENCE_DT_DIVISOR = 8  # default reference: `accurate` at the scene's dt / 8
# world settings a grid axis may vary (dt and preset are axes too)
SETTING_KEYS = tuple(
    f.name for f in fields(WorldSettings) if f.name not in ("gravity", "dt", "steps", "fidelity")
)
# a body "tunneled" when its centre's path crossed a concrete body (see `_crossed_concrete`)


class TradeoffError(IsaacError):
    """Bad `isaac tradeoff` arguments (grid, reference) for this scene."""


@dataclass(frozen=True)
class GridPoint:
    """One setting of the grid: a label, the dt (s) and the world-setting overrides."""

    label: str
    dt: float
    overrides: tuple[tuple[str, object], ...] = ()

    def world(self, base: WorldSettings, duration: float) -> WorldSettings:
        """The base world with this point's settings: a preset's settings replace the scene's
        fidelity settings; other overrides come after; gravity, friction and rules stay."""
        values: dict[str, object] = {}
        for key, value in self.overrides:
            if key == "preset":
                values.update(PRESETS[str(value)])
                values["fidelity"] = value
            else:
                values[key] = value
        steps = max(1, math.ceil(duration / self.dt - 1e-9))
        return replace(base, dt=self.dt, steps=steps, **values)


def parse_dt(text: str, scene_dt: float) -> float:
    """A dt value: seconds ("0.01", "1e-3"), a fraction ("1/60"), or a multiple of the scene's
    dt ("x2", "x1/2")."""
    text = text.strip()

    def number(part: str) -> float:  # fractions read as a scene's times are (one parser)
        return fraction(part) if "/" in part else float(part)

    try:
        value = number(text[1:]) * scene_dt if text.startswith("x") else number(text)
    except ValueError:
        raise TradeoffError(
            f"--grid dt: cannot read {text!r} as a time step (use 0.01, 1/60 or "
            f"x2 for twice the scene's dt)"
        ) from None
    if not (0.0 < value <= 1.0):
        raise TradeoffError(f"--grid dt: {text!r} = {value!r} s is out of range (0, 1]")
    return value


def _check_setting(key: str, raw: str):
    """Read and validate one world-setting value through the scene loader (same rules and
    messages as a scene file)."""
    try:
        scene = load_scene_text(
            f"world: {{{key}: {raw}}}\nbodies: [{{shape: {{box: [1, 1]}}}}]", source=f"--grid {key}"
        )
    except SceneError as exc:
        raise TradeoffError(str(exc)) from None
    return getattr(scene.world, key)


def parse_grid(
    specs: list[str] | None, scene_dt: float, *, joints: bool = False
) -> list[GridPoint]:
    """Grid points from `--grid KEY=V1,V2` specs (the product of the axes).

    Keys: `preset` (seed, fast, balanced, accurate), `dt` (see `parse_dt`) and any world
    setting (`iterations=4,10,20`, `ccd=off,speculative`, ...). Without a `dt` axis the dt
    values are the scene's dt times 2, 1 and 1/2. Without any preset or setting axis the presets
    are the axis (for a scene with `joints`, all but `seed`: its single pass has no joint rows);
    with setting axes but no preset the scene's own settings are the base.
    """
    axes: dict[str, list] = {}
    for spec in specs or []:
        for part in spec.split(";"):
            part = part.strip()
            if not part:
                continue
            key, sep, values = part.partition("=")
            key = key.strip()
            if not sep or not values.strip():
                raise TradeoffError(f"--grid: expected KEY=V1,V2,..., got {part!r}")
            if key in axes:
                raise TradeoffError(f"--grid: axis {key!r} given twice")
            items = [v.strip() for v in values.split(",") if v.strip()]
            if key == "preset":
                for v in items:
                    if v not in PRESETS:
                        raise TradeoffError(
                            f"--grid preset: unknown preset {v!r} "
                            f"(valid: {', '.join(PRESET_ORDER)})"
                        )
                axes[key] = items
            elif key == "dt":
                axes[key] = [parse_dt(v, scene_dt) for v in items]
            elif key in SETTING_KEYS:
                axes[key] = [_check_setting(key, v) for v in items]
            else:
                valid = ", ".join(("preset", "dt") + SETTING_KEYS)
                raise TradeoffError(f"--grid: unknown axis {key!r} (valid: {valid})")
    if "dt" not in axes:
        axes["dt"] = [scene_dt * f for f in DEFAULT_DT_FACTORS]
    if len(axes) == 1:
        axes["preset"] = [
            p for p in PRESET_ORDER if not (joints and PRESETS[p]["solver"] == "seed")
        ]
    keys = [k for k in axes if k != "dt"]
    points = []
    for combo in itertools.product(*(axes[k] for k in keys)):
        overrides = tuple(zip(keys, combo))
        label = " ".join(str(v) if k == "preset" else f"{k}={v}" for k, v in overrides)
        for dt in axes["dt"]:
            points.append(GridPoint(label=label or "scene", dt=float(dt), overrides=overrides))
    return points
