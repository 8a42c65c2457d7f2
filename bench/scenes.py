"""Every benchmark scene, defined once and built from that one definition in every engine.

A scene is a `BenchScene`: the ISAAC `Scene` (bodies as convex polygons with density,
restitution, friction and `concrete` for static) plus what the benchmark needs to know about it
(how many steps to warm up and to time, which quality figure applies). Pyramids and piles are
generator parameters, written as YAML text in the scene format and read with
`isaac.scene.load_scene_text`; when the loader is missing (or refuses the text) the same
parameters go straight to `isaac.scene.generators` and `Scene.source` says so. The three small
scenes are written out body by body.

All scenes: dt = 1/60 s, no sleeping in any engine, friction on except in the head-on case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from isaac.scene import PRESETS, BodySpec, Scene, WorldSettings

DT = 1.0 / 60.0
GRAVITY = (0.0, -9.81)

# pyramid boxes (m) and the pile's polygons
PYRAMID_BOX = (1.0, 1.0)
PILE_SIDES = (3, 8)
PILE_RADIUS = (0.15, 0.25)  # m, circumradius range
FRICTION = 0.6


@dataclass(frozen=True)
class BenchScene:
    """A scene and how the benchmark runs it.

    kind: "pyramid", "pile", "head_on", "mass_ratio", "tunneling", "drop" or "off_centre"
        (selects the quality figure).
    warmup_steps: steps taken before the clock starts (compile and start-up transients excluded).
    timed_steps: steps timed with one perf_counter block.
    info: indices of bodies the quality figure looks at, and scene facts for the report.
    """

    name: str
    kind: str
    scene: Scene
    warmup_steps: int
    timed_steps: int
    info: dict = field(default_factory=dict)

    @property
    def n_bodies(self) -> int:
        return len(self.scene.bodies)

    @property
    def n_dynamic(self) -> int:
        return sum(not b.concrete for b in self.scene.bodies)


def box(w: float, h: float) -> tuple[tuple[float, float], ...]:
    """A w x h box (m) centred on the origin, counter-clockwise."""
    return ((-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2))


def world(*, gravity=GRAVITY, friction: bool = True, steps: int = 300) -> WorldSettings:
    return WorldSettings(gravity=gravity, dt=DT, steps=steps, friction=friction)


def with_preset(scene: Scene, preset: str) -> Scene:
    """The same scene with ISAAC's world settings taken from `preset` (dt, gravity, friction and
    steps kept): the preset named in ISAAC's row."""
    settings = replace(scene.world, **PRESETS[preset], fidelity=preset)
    return replace(scene, world=settings)


# ---- scene definitions: generator parameters -> YAML text (loader) or the generator itself -----


def _generator_yaml(name: str, steps: int, generator: str, params: dict) -> str:
    """The scene as YAML text in the scene format (docs/scene-format.md)."""
    import yaml

    doc = dict(
        name=name,
        world=dict(dt=DT, steps=steps, gravity=list(GRAVITY), friction=True),
        generators=[{generator: params}],
    )
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


# a 5 cm gap between neighbours: Box2D 2.3 keeps a 1 cm skin around each polygon, so boxes that
# touch exactly would be pushed sideways in Box2D 2.3 alone
PYRAMID_SPACING = 0.05  # m


def _pyramid_params(rows: int, spacing: float = PYRAMID_SPACING) -> dict:
    return dict(
        rows=rows,
        box=list(PYRAMID_BOX),
        base=[0.0, 0.0],
        spacing=spacing,
        ground=True,
        density=1.0,
        friction=FRICTION,
        restitution=0.0,
        name="pyramid",
    )


def _expand_pyramid(rows: int, steps: int, spacing: float) -> Scene:
    from isaac.scene.generators import pyramid

    p = _pyramid_params(rows, spacing)
    p = dict(p, box=tuple(p["box"]), base=tuple(p["base"]))
    return Scene(name=f"pyramid-{rows}", world=world(steps=steps), bodies=tuple(pyramid(**p)))


PILE_ROWS = 15  # starting rows of the larger piles: every pile settles to about the same depth


def _pile_params(count: int, seed: int) -> dict:
    """A container wide enough for `count` bodies in PILE_ROWS starting rows (at least 10
    columns), so piles of every size have the same depth, settle in the same time and differ
    only in width: ms/step against count then measures how the engine scales, not how it copes
    with a deeper pile."""
    cell = 1.05 * 2.0 * PILE_RADIUS[1]  # the generator's cell side
    columns = max(10, math.ceil(count / PILE_ROWS))
    return dict(
        count=count,
        seed=seed,
        sides=list(PILE_SIDES),
        radius=list(PILE_RADIUS),
        container=dict(width=round(columns * cell + 0.01, 3), thickness=1.0),
        density=1.0,
        friction=FRICTION,
        restitution=0.0,
        name="pile",
    )


def _expand_pile(count: int, seed: int, steps: int) -> Scene:
    from isaac.scene.generators import pile

    p = _pile_params(count, seed)
    container = p.pop("container")
    p = dict(p, sides=tuple(p["sides"]), radius=tuple(p["radius"]), **container)
    return Scene(name=f"pile-{count}", world=world(steps=steps), bodies=tuple(pile(**p)))


def _body_doc(
    name: str,
    size: tuple[float, float],
    position,
    *,
    velocity=(0.0, 0.0),
    density: float = 1.0,
    restitution: float = 0.0,
    friction: float = 0.0,
    concrete: bool = False,
) -> dict:
    return dict(
        name=name,
        shape=dict(box=list(size)),
        position=list(position),
        velocity=list(velocity),
        density=density,
        restitution=restitution,
        friction=friction,
        concrete=concrete,
    )


def _head_on_doc(steps: int) -> dict:
    """Two equal 1 m boxes, restitution 1, no gravity, closing at 4 m/s: they exchange
    velocities."""
    return dict(
        name="head-on",
        world=dict(dt=DT, steps=steps, gravity=[0.0, 0.0], friction=False),
        bodies=[
            _body_doc("a", (1.0, 1.0), (-3.0, 0.0), velocity=(3.0, 0.0), restitution=1.0),
            _body_doc("b", (1.0, 1.0), (3.0, 0.0), velocity=(-1.0, 0.0), restitution=1.0),
        ],
    )


def _mass_ratio_doc(steps: int) -> dict:
    """A 1 m box 1000x denser resting on a light 1 m box on the ground."""
    return dict(
        name="mass-ratio",
        world=dict(dt=DT, steps=steps, gravity=list(GRAVITY), friction=True),
        bodies=[
            _body_doc("ground", (20.0, 1.0), (0.0, -0.5), friction=FRICTION, concrete=True),
            _body_doc("light", (1.0, 1.0), (0.0, 0.5), friction=FRICTION),
            _body_doc("heavy", (1.0, 1.0), (0.0, 1.5), density=1000.0, friction=FRICTION),
        ],
    )


TUNNEL_LANES = 10
TUNNEL_SPEED = 200.0  # m/s
TUNNEL_WALL_X = 10.0  # m, centre of each 0.1 m wall


def _tunneling_doc(steps: int) -> dict:
    """A 0.2 m box at 200 m/s against a 0.1 m static wall, in 10 separate lanes whose starting
    offsets cover one step's travel in tenths (tunneling depends on where the step lands)."""
    bodies = []
    travel = TUNNEL_SPEED * DT
    for k in range(TUNNEL_LANES):
        y = 4.0 * k
        bodies.append(_body_doc(f"wall_{k}", (0.1, 2.0), (TUNNEL_WALL_X, y), concrete=True))
        bodies.append(
            _body_doc(
                f"bullet_{k}",
                (0.2, 0.2),
                (-k * travel / TUNNEL_LANES, y),
                velocity=(TUNNEL_SPEED, 0.0),
            )
        )
    return dict(
        name="tunneling",
        world=dict(dt=DT, steps=steps, gravity=[0.0, 0.0], friction=False),
        bodies=bodies,
    )


def _expand_doc(doc: dict) -> Scene:
    """The fallback for a scene written body by body (box shapes only)."""
    w = doc["world"]
    bodies = tuple(
        BodySpec(
            name=b["name"],
            vertices=box(*b["shape"]["box"]),
            position=tuple(b["position"]),
            velocity=tuple(b["velocity"]),
            density=b["density"],
            restitution=b["restitution"],
            friction=b["friction"],
            concrete=b["concrete"],
        )
        for b in doc["bodies"]
    )
    return Scene(
        name=doc["name"],
        bodies=bodies,
        world=world(gravity=tuple(w["gravity"]), friction=w["friction"], steps=w["steps"]),
    )


def _doc_scene(doc: dict) -> Scene:
    import yaml

    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    return _load_or_expand(text, lambda: _expand_doc(doc))


def _load_or_expand(yaml_text: str | None, expand) -> Scene:
    """The scene from the YAML text through ISAAC's loader if it is there, else the fallback."""
    if yaml_text is not None:
        try:
            from isaac.scene import load_scene_text  # type: ignore[attr-defined]
        except ImportError:
            load_scene_text = None
        if load_scene_text is not None:
            try:
                return load_scene_text(yaml_text)
            except Exception as exc:  # the loader's format moved on: say so in the output
                scene = expand()
                return replace(scene, source=f"bench fallback (loader: {exc})")
    return replace(expand(), source="bench expansion (isaac.scene.load_scene_text missing)")


PYRAMID_ROWS = (10, 20, 40)
# Box2D v3's own `large_pyramid` benchmark (benchmark/main.c, built by CreateLargePyramid in
# shared/benchmarks.c): a base of 100 boxes of b2MakeSquare(0.5), i.e. 1 m, each row's boxes
# touching (centres 1 m apart, no gap), row k's first centre at x = -49.5 + 0.5 k, y = k + 0.5,
# density 1, Box2D's default friction 0.6: 5,050 boxes, the same as this pyramid of 100 rows
# with no spacing. Its ground is a 200 m x 2 m box with its top at y = 0; here the generator's
# ground (104 m x 1 m, its top at y = 0 too) carries it: the boxes touch its top face alone.
LARGE_PYRAMID_ROWS = 100
PILE_COUNTS = (100, 500, 2000, 10000)
PILE_SEED = 7


def _pyramid(rows: int, spacing: float = PYRAMID_SPACING) -> BenchScene:
    warm, timed = 60, 240
    steps = warm + timed
    text = _generator_yaml(f"pyramid-{rows}", steps, "pyramid", _pyramid_params(rows, spacing))
    scene = _load_or_expand(text, lambda: _expand_pyramid(rows, steps, spacing))
    dynamic = [k for k, b in enumerate(scene.bodies) if not b.concrete]
    top = max(dynamic, key=lambda k: scene.bodies[k].position[1])
    return BenchScene(
        f"pyramid-{rows}",
        "pyramid",
        scene,
        warm,
        timed,
        info=dict(top=top, tolerance_m=0.5 * PYRAMID_BOX[1], angle_tolerance_rad=0.1),
    )


def _pile(count: int) -> BenchScene:
    # 2 s to settle (the 15-row piles have stopped collapsing by ~1.5 s in pymunk and Box2D),
    # then the timed block; the 10,000 pile has fewer timed steps (budget: ~15 min in all)
    warm, timed = (120, 120) if count < 10000 else (120, 60)
    steps = warm + timed
    scene = _load_or_expand(
        _generator_yaml(f"pile-{count}", steps, "pile", _pile_params(count, PILE_SEED)),
        lambda: _expand_pile(count, PILE_SEED, steps),
    )
    return BenchScene(f"pile-{count}", "pile", scene, warm, timed)


def _head_on() -> BenchScene:
    return BenchScene("head-on", "head_on", _doc_scene(_head_on_doc(120)), 10, 110)


def _index(scene: Scene, name: str) -> int:
    return next(k for k, b in enumerate(scene.bodies) if b.name == name)


def _mass_ratio() -> BenchScene:
    scene = _doc_scene(_mass_ratio_doc(120))
    return BenchScene(
        "mass-ratio",
        "mass_ratio",
        scene,
        10,
        110,
        info=dict(heavy=_index(scene, "heavy"), light=_index(scene, "light")),
    )


def _tunneling() -> BenchScene:
    return BenchScene(
        "tunneling",
        "tunneling",
        _doc_scene(_tunneling_doc(60)),
        10,
        50,
        info=dict(wall_x=TUNNEL_WALL_X, lanes=TUNNEL_LANES),
    )


def _shipped(name: str, kind: str, file: str) -> BenchScene:
    """A scene shipped in scenes/, as a user runs it (its own dt and steps)."""
    from pathlib import Path

    from isaac.scene import load_scene

    scene = load_scene(str(Path(__file__).resolve().parents[1] / "scenes" / file))
    steps = scene.world.steps
    return BenchScene(name, kind, scene, 10, steps - 10, info=dict(source=f"scenes/{file}"))


BUILDERS = {
    **{f"pyramid-{r}": (lambda r=r: _pyramid(r)) for r in PYRAMID_ROWS},
    f"pyramid-{LARGE_PYRAMID_ROWS}": lambda: _pyramid(LARGE_PYRAMID_ROWS, spacing=0.0),
    **{f"pile-{c}": (lambda c=c: _pile(c)) for c in PILE_COUNTS},
    "head-on": _head_on,
    "mass-ratio": _mass_ratio,
    "tunneling": _tunneling,
    # the small scenes, as shipped: a box bouncing on the ground, an off-centre blow
    "bounce": lambda: _shipped("bounce", "drop", "bounce.yaml"),
    "off-centre": lambda: _shipped("off-centre", "off_centre", "off_centre.yaml"),
}
ALL_SCENES = tuple(BUILDERS)
QUICK_SCENES = ("pyramid-10", "pyramid-20", "pile-100", "pile-500", "head-on")
GROWTH_SCENES = tuple(f"pile-{c}" for c in PILE_COUNTS)


def build(name: str) -> BenchScene:
    """The named benchmark scene (deterministic: the same bodies in the same order every time)."""
    try:
        return BUILDERS[name]()
    except KeyError:
        raise KeyError(f"unknown bench scene {name!r}; known: {', '.join(ALL_SCENES)}") from None
