"""Warnings about a valid scene that will not behave as its author expects: data, not errors.

`scene_warnings(scene, steps)` returns one-line messages (`FILE:LINE: KEY.PATH: what`, the line
and key of the body or generator at fault when the scene was read from YAML); the command line
prints them (a scene that warns still loads, runs and replays). One line per kind of trap, naming
the worst case and counting the others, so a scene of 100,000 bodies gives a few lines:

- mass ratio (below);
- friction given (a body's or a generator's `friction:`) while `world.friction` is off: the
  coefficients are ignored;
- a body that never exists in the run: it enters after the run's last step, or enters and
  leaves between two steps (a body exists at step k while enters_at <= k * dt < leaves_at, the
  engine's rule, isaac.engine.world.Model);
- a body whose centre of mass lies inside a concrete body when it first exists (a body does
  not move before it exists, a concrete body never moves, so this is known from the scene):
  the push-out can only move it the shortest way out, which may be through the concrete;
- joint geometry the step cannot hold (below): a run of it gains energy from nowhere;
- bodies that overlap at step 0 by more than the slop (`world.slop`, at most SLOP_SHARE of the
  thinner body's thickness, as isaac.engine.push_out caps it): the first steps push them apart
  instead of starting from the scene as written; and a body entering later that overlaps a
  concrete body by more than the slop when it appears.
The geometry is isaac.scene.overlaps (numpy; `isaac check` loads no compiled code).

Mass ratio. A light body under a much heavier one is squeezed into what it rests on once the
ratio passes what the solver can hold (pymunk and Box2D 2.3 lose a 1000:1 stack within 0.5 s).
HELD_MASS_RATIO is, per preset, the largest heavy:light ratio measured to stay stacked:
scenes/mass_ratio.yaml (a heavy 1 m box on a light one on concrete ground, dt 1/60 s) run for
10 s, held meaning neither box moves more than 5 cm and no overlap passes 5 cm (the criterion
of tests/extremes/test_mass_ratio.py), with friction on and off alike. Measured:

    seed      holds 1.5 (2: 5.0 cm)          fast      holds 70 (100: 7.3 cm)
    balanced  holds 100 (150: 6.3 cm)        accurate  holds 2500 (3000: 5.2 cm)

The table keeps a margin below the edge for fast (50) and accurate (1000, the ratio the
stability suite asserts). At 1e9:1 the light box ends inside the concrete ground.

Joint geometry. Two shapes of jointed scene make the sequential solver's step put energy in
(the energy check of isaac.engine.energy_check then flags the run), whatever the iterations;
what holds them is a shorter sub-step h = world.dt / world.substeps. With k = sqrt(I / m) a
body's radius of gyration (m) and |g| gravity's magnitude:
- an anchor far outside its body: R = 1 + r^2 / k^2 (the body's mass over the effective mass
  m / (1 + m r^2 / I) its anchor offers, r the anchor's distance from the centre of mass);
  ANCHOR_LIMIT bounds h sqrt(|g| / k) R^(5/4);
- a long chain of light links: N movable bodies joined together (one connected set of joints),
  links of length w = sqrt(12) k (a thin rod's); CHAIN_LIMIT bounds h sqrt(2 |g| N / w), the
  angle a link turns in a sub-step when the chain's end falls its length.
Measured under balanced (the energy check's flag within 600-2400 steps at dt 1/120 s unless
said): a 0.1 m box on a distance joint anchored r from its centre holds r = 0.35 m (28 for the
anchor figure) and fails at r = 0.4 m (39); anchored 1 m off it fails with 4 and 8 sub-steps (48)
and holds with 16 (24); a 1 m box anchored 5 m off holds (22). Chains of 0.1 x 0.02 m boxes hold
16 links for 2400 steps (0.47) and 18 for 600 (0.50), and fail at 20 (0.52); 0.25 x 0.05 m
links hold 20 (0.33) and fail at 40 (0.47), which 1/240 s holds (0.23). The limits sit between.
"""

from __future__ import annotations

import numpy as np

from isaac.collision_filter import collides
from isaac.scene import overlaps
from isaac.scene.checks import mass_properties
from isaac.scene.reader import shown
from isaac.scene.spec import BodySpec, Scene

HELD_MASS_RATIO = {"seed": 1.5, "fast": 50.0, "balanced": 100.0, "accurate": 1000.0}
# isaac.engine.push_out.SLOP_SHARE (the scene layer may not import the engine; a test checks
# the two agree)
SLOP_SHARE = 0.05
# pairs whose bounding boxes meet, at most; then pairs given to SAT, at most (those whose boxes
# overlap by more than the slop on both axes: no pair left out is deeper than the slop, see
# _placement). Past
# either, the count says "at least": only bodies heaped on one another get near them.
MAX_PAIRS = 2_000_000
MAX_SAT_PAIRS = 200_000
_FILTER = ("category", "mask", "group")
# the joint-geometry figures past which the step is measured to gain energy (module docstring)
ANCHOR_LIMIT = 30.0
CHAIN_LIMIT = 0.45


def scene_warnings(scene: Scene, steps: int | None = None) -> list[str]:
    """One line per kind of trap in `scene` run for `steps` steps (default `world.steps`), in
    the order of the module docstring; [] for a scene that falls into none."""
    steps = scene.world.steps if steps is None else steps
    lines = _mass_ratio(scene)
    lines += _friction_ignored(scene)
    first, last = existence(scene.bodies, scene.world.dt, steps)
    lines += _never_exist(scene, steps, first, last)
    lines += _placement(scene, first, last)
    lines += _joint_geometry(scene)
    return lines


def _where(scene: Scene, i: int) -> str:
    """`FILE:LINE: KEY.PATH: ` of the scene key that made body i (`FILE: ` if unknown)."""
    marks = scene.marks
    if marks is not None:
        if i < len(marks.bodies):
            line, path = marks.bodies[i]
            return f"{scene.source}:{line}: {path}: "
        for first, end, line, path in marks.generators:
            if first <= i < end:
                return f"{scene.source}:{line}: {path}: "
    return f"{scene.source}: "


def _time(scene: Scene, i: int, field: str) -> str:
    """Body i's time `field` as the scene wrote it (`1/3`), else its repr."""
    written = dict(scene.as_written).get(f"bodies[{i}].{field}")
    return written or repr(getattr(scene.bodies[i], field))


def _more(count: int, what: str) -> str:
    return f"; and {count} more {what}" if count else ""


def _mass_ratio(scene: Scene) -> list[str]:
    """The ratio of the heaviest to the lightest movable (not concrete) body, when it exceeds
    HELD_MASS_RATIO for the scene's `world.fidelity` preset (keys given explicitly in `world:`
    are not taken into account)."""
    movable = [i for i, b in enumerate(scene.bodies) if not b.concrete]
    if len(movable) < 2:
        return []
    masses = mass_properties([scene.bodies[i] for i in movable]).mass
    heavy, light = int(masses.argmax()), int(masses.argmin())
    ratio = float(masses[heavy] / masses[light])
    held = HELD_MASS_RATIO.get(scene.world.fidelity)
    if held is None or not ratio > held:
        return []
    return [
        f"{scene.source}: the mass ratio {ratio:.3g}:1 between "
        f"{shown(scene.bodies[movable[heavy]].name)} ({float(masses[heavy]):.3g} kg) and "
        f"{shown(scene.bodies[movable[light]].name)} ({float(masses[light]):.3g} kg) is beyond "
        f"the {held:g}:1 the {scene.world.fidelity!r} preset is measured to hold in a stack: a "
        "light body under a heavy one may be pushed into what it rests on "
        "(docs/scene-format.md, Warnings)"
    ]


def _friction_ignored(scene: Scene) -> list[str]:
    """`friction:` given while world.friction is off. Without marks (a scene not read from
    YAML), the bodies whose friction differs from BodySpec's default."""
    if scene.world.friction:
        return []
    marks = scene.marks
    if marks is not None:
        if not marks.friction:
            return []
        (line, path), others = marks.friction[0], len(marks.friction) - 1
        where = f"{scene.source}:{line}: {path}: "
    else:
        default = BodySpec.__dataclass_fields__["friction"].default
        given = [i for i, b in enumerate(scene.bodies) if b.friction != default]
        if not given:
            return []
        where, others = _where(scene, given[0]), len(given) - 1
    return [
        f"{where}friction is given but world.friction is off, so no friction acts (set "
        f"world.friction: true to use it){_more(others, 'friction keys likewise')}"
    ]


def existence(bodies, dt: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(first, last): (n,) int64, the first and last of steps 0..steps at which each body
    exists (enters_at <= k * dt < leaves_at, with k * dt the float64 product the engine
    computes); first > last for a body that never exists in the run."""
    n = len(bodies)
    enters = np.fromiter((b.enters_at for b in bodies), dtype=np.float64, count=n)
    leaves = np.fromiter(
        (np.inf if b.leaves_at is None else b.leaves_at for b in bodies), np.float64, count=n
    )
    cap = float(steps + 1)  # beyond the run; keeps huge times within int64
    # the smallest k with k * dt >= enters: the quotient, corrected for its rounding
    k = np.minimum(np.ceil(enters / dt), cap)
    k = np.where(k * dt < enters, k + 1, k)
    k = np.where((k >= 1) & ((k - 1) * dt >= enters), k - 1, k)
    first = np.minimum(k, cap).astype(np.int64)
    # the largest k with k * dt < leaves
    finite = np.isfinite(leaves)
    j = np.minimum(np.ceil(np.where(finite, leaves, 0.0) / dt) - 1, cap)
    j = np.where((j + 1) * dt < leaves, j + 1, j)
    j = np.where(j * dt >= leaves, j - 1, j)
    last = np.where(finite, np.minimum(j, steps), steps).astype(np.int64)
    return first, last


def _never_exist(scene: Scene, steps: int, first: np.ndarray, last: np.ndarray) -> list[str]:
    dt = scene.world.dt
    end = f"the run's last step ({steps}, t = {steps * dt:.6g} s)"
    lines = []
    late = np.flatnonzero(first > steps)
    if len(late):
        i = int(late[0])
        b = scene.bodies[i]
        enters = _time(scene, i, "enters_at")
        lines.append(
            f"{_where(scene, i)}the body {shown(b.name)} enters at {enters} s, after "
            f"{end}: it never exists in the run (raise world.steps or --steps, or enter "
            f"earlier){_more(len(late) - 1, 'bodies likewise')}"
        )
    between = np.flatnonzero((first <= steps) & (first > last))
    if len(between):
        i = int(between[0])
        b = scene.bodies[i]
        k = int(first[i])
        enters, leaves = _time(scene, i, "enters_at"), _time(scene, i, "leaves_at")
        lines.append(
            f"{_where(scene, i)}the body {shown(b.name)} enters at {enters} s and "
            f"leaves at {leaves} s, between steps {k - 1} and {k} (dt {dt!r} s): it "
            f"never exists at a step{_more(len(between) - 1, 'bodies likewise')}"
        )
    return lines


def _placement(scene: Scene, first: np.ndarray, last: np.ndarray) -> list[str]:
    """Bodies inside concrete bodies, overlaps at step 0 beyond the slop, and bodies entering
    later that overlap a concrete body beyond it. A body does not move before it exists, so it
    appears where the scene puts it; a concrete body never moves: their overlap at the movable
    body's first step is known from the scene alone."""
    bodies = scene.bodies
    n = len(bodies)
    if n < 2:
        return []
    placed = overlaps.place(bodies)
    a, b, complete = overlaps.box_pairs(placed.lo, placed.hi, MAX_PAIRS)
    concrete = np.fromiter((x.concrete for x in bodies), dtype=bool, count=n)
    keep = ~(concrete[a] & concrete[b])  # two concrete bodies never collide
    if any(x.filtered for x in bodies):  # nor two bodies their filters keep apart
        f = {k: np.array([getattr(x, k) for x in bodies], dtype=np.int64) for k in _FILTER}
        cat, mask, group = f["category"], f["mask"], f["group"]
        keep &= collides(cat[a], mask[a], group[a], cat[b], mask[b], group[b])
    apart = [(min(j.a, j.b), max(j.a, j.b)) for j in scene.joints if not j.collide_connected]
    if apart:  # nor two bodies a joint connects (a wheel inside its chassis), unless it says so
        keys = np.unique(np.array([lo * n + hi for lo, hi in apart], dtype=np.int64))
        pair = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
        keep &= ~np.isin(pair, keys)
    a, b = a[keep], b[keep]
    lines = []
    # a movable body beside a concrete one that exists at the movable body's first step
    one = concrete[a] ^ concrete[b]
    c = np.where(concrete[a], a, b)
    m = np.where(concrete[a], b, a)
    k = first[m]
    meets = one & (k <= last[m]) & (first[c] <= k) & (k <= last[c])
    # inside: the movable body's centre inside the concrete one
    deep = np.zeros(len(a))
    deep[meets] = overlaps.centre_depths(placed, c[meets], m[meets])
    inside = deep > 0.0
    if inside.any():
        worst = int(np.argmax(np.where(inside, deep, -np.inf)))
        i, j = int(m[worst]), int(c[worst])
        lines.append(
            f"{_where(scene, i)}the body {shown(bodies[i].name)} is placed inside the "
            f"concrete body {shown(bodies[j].name)} (its centre {float(deep[worst]):.3g} m "
            "deep): the push-out moves it out the shortest way, which may be through the "
            f"concrete{_more(int(inside.sum()) - 1, 'bodies inside concrete bodies')}"
        )
    # overlaps beyond the slop: any two bodies at step 0; a body entering later and a
    # concrete body (pairs reported as inside are not reported again)
    at_start = (first[a] == 0) & (last[a] >= 0) & (first[b] == 0) & (last[b] >= 0)
    entering = meets & (k > 0)
    asked = (at_start | entering) & ~inside
    slop = np.minimum(
        scene.world.slop, SLOP_SHARE * np.minimum(placed.thickness[a], placed.thickness[b])
    )
    # SAT only where the boxes overlap by more than the slop on both axes. Where they overlap
    # by less on one axis, neither box holds the other's span along it (a span held is at least
    # the inner body's thickness, > 20 slops), so moving one body that little along that axis
    # parts the boxes: the MTD is at most the slop
    box_overlap = np.minimum(placed.hi[a], placed.hi[b]) - np.maximum(placed.lo[a], placed.lo[b])
    asked &= box_overlap.min(axis=1) > slop
    ask = np.flatnonzero(asked)
    complete = complete and len(ask) <= MAX_SAT_PAIRS
    ask = ask[:MAX_SAT_PAIRS]
    depth = np.zeros(len(a))
    depth[ask] = overlaps.depths(placed, a[ask], b[ask])
    over = asked & (depth > slop)
    slop_is = (
        f"the slop (world.slop {scene.world.slop!r} m, at most {SLOP_SHARE:.0%} of the thinner "
        "body's thickness)"
    )
    for group, what in ((over & at_start, "start"), (over & ~at_start, "enter")):
        if not group.any():
            continue
        worst = int(np.argmax(np.where(group, depth, -np.inf)))
        count = int(group.sum())
        if what == "start":
            i, j = int(a[worst]), int(b[worst])
            many = f"{count}" if complete else f"at least {count}"
            pairs = "pair of bodies overlaps" if count == 1 else "pairs of bodies overlap"
            lines.append(
                f"{_where(scene, i)}{many} {pairs} at step 0 by more than {slop_is}: "
                f"{shown(bodies[i].name)} and {shown(bodies[j].name)} by "
                f"{float(depth[worst]):.3g} m, the most; the first steps push them apart "
                "instead of starting from the scene as written"
            )
        else:
            i, j = int(m[worst]), int(c[worst])
            lines.append(
                f"{_where(scene, i)}the body {shown(bodies[i].name)} enters at step "
                f"{int(k[worst])} (t = {int(k[worst]) * scene.world.dt:.6g} s) overlapping the "
                f"concrete body {shown(bodies[j].name)} by {float(depth[worst]):.3g} m, more "
                f"than {slop_is}: it is pushed out as it appears"
                f"{_more(count - 1, 'bodies entering into concrete bodies')}"
            )
    return lines


def _joint_geometry(scene: Scene) -> list[str]:
    """The worst anchor and the worst chain past ANCHOR_LIMIT and CHAIN_LIMIT (module
    docstring), each with the sub-steps that would bring it under its limit."""
    joints = scene.joints
    world = scene.world
    g = float(np.hypot(*world.gravity))
    if not joints or g == 0.0:
        return []
    props = mass_properties(scene.bodies)
    with np.errstate(all="ignore"):
        k = np.sqrt(props.inertia / props.mass)  # radius of gyration (m)
    concrete = np.fromiter((b.concrete for b in scene.bodies), bool, count=len(scene.bodies))
    h = world.dt / world.substeps
    lines = []
    # anchors: the worst movable body's
    worst = None
    for i, j in enumerate(joints):
        for body, local in ((j.a, j.local_a), (j.b, j.local_b)):
            if concrete[body]:
                continue
            ratio = 1.0 + float(np.hypot(*local)) ** 2 / float(k[body]) ** 2
            figure = h * np.sqrt(g / k[body]) * ratio**1.25
            if worst is None or figure > worst[0]:
                worst = (float(figure), i, body, ratio)
    if worst is not None and worst[0] > ANCHOR_LIMIT:
        figure, i, body, ratio = worst
        lines.append(
            f"{scene.source}: joints[{i}] ({shown(joints[i].name)}): the anchor on "
            f"{shown(scene.bodies[body].name)} is {float(np.hypot(*_local(joints[i], body))):.3g} "
            f"m from its centre, where it offers 1/{ratio:.3g} of the body's mass: beyond what "
            f"a sub-step of {h:.3g} s holds ({figure:.3g} > {ANCHOR_LIMIT:g}), the run may gain "
            f"energy from nowhere; {_substeps_hint(world, figure / ANCHOR_LIMIT)} "
            "(docs/scene-format.md, Warnings)"
        )
    # chains: connected sets of joined movable bodies
    parent = list(range(len(scene.bodies)))

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for j in joints:
        if not (concrete[j.a] or concrete[j.b]):
            parent[root(j.a)] = root(j.b)
    sets: dict[int, list[int]] = {}
    for body in sorted({b for j in joints for b in (j.a, j.b) if not concrete[b]}):
        sets.setdefault(root(body), []).append(body)
    worst = None
    for members in sets.values():
        w = float(np.sqrt(12.0) * np.mean(k[members]))
        figure = h * np.sqrt(2.0 * g * len(members) / w)
        if worst is None or figure > worst[0]:
            worst = (float(figure), members, w)
    if worst is not None and worst[0] > CHAIN_LIMIT:
        figure, members, w = worst
        lines.append(
            f"{scene.source}: joints: a chain of {len(members)} links about {w:.3g} m long "
            f"(from {shown(scene.bodies[members[0]].name)}) is beyond what a sub-step of "
            f"{h:.3g} s holds ({figure:.3g} > {CHAIN_LIMIT:g}), the run may gain energy from "
            f"nowhere; {_substeps_hint(world, figure / CHAIN_LIMIT)} "
            "(docs/scene-format.md, Warnings)"
        )
    return lines


def _local(joint, body: int):
    return joint.local_a if body == joint.a else joint.local_b


def _substeps_hint(world, factor: float) -> str:
    """The fix: sub-steps (or a dt) `factor` times finer, rounded up to a power of two."""
    need = world.substeps * 2 ** int(np.ceil(np.log2(factor)))
    return f"set world.substeps: {need} (now {world.substeps}), or a dt as many times smaller"
