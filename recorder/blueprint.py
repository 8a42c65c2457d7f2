"""The Rerun viewer layout (a `rerun.blueprint`) and the colours every ISAAC recording is drawn in.

Sent with every .rrd (`recorder.rerun_writer.RerunLogWriter`, so also by the Rerun writer
process and by ``isaac view LOG.mcap``), made active on load: without one, Rerun's heuristic
builds a different grid on every load, gives the 2D scene a twelfth of the window, and picks the
origin ``/world`` for it, whose y-flip a view never applies to itself (every scene upside down).

Layout (docs/log-format.md, "Rerun"):
- left, three quarters of the width: one 2D view with origin ``/`` (so the static
  ``Transform3D(scale=[1, -1, 1])`` on ``world`` applies: physics y up), showing ``world/**``
  on a fixed light background, the same in the viewer's light and dark themes;
- right: tabs of time series on the ``step`` timeline: the three energies on one plot, then
  the momenta, the contact count, the largest depth and the largest impulse (each tab a
  quantity of one unit); below them the run's summary and colour legend (the ``info`` text);
- the time panel in its one-line form on ``step``; the blueprint and selection panels closed.

Colours: one `rr.AnnotationContext` on ``world`` names each kind of thing drawn (hovering an
arrow says "impulse" rather than only its entity path); `LEGEND` is that list, also written
into the summary in words.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

# rerun-sdk is imported inside the functions that build its objects: the constants below are
# also read by the drawing half of the writer (`recorder.rerun_writer`), which runs in the
# simulating process and must not pay for importing rerun (a large import); only the process
# that sends (`recorder.rerun_send`) calls the functions


@dataclass(frozen=True)
class Kind:
    """One kind of thing drawn in the 2D view: its annotation class and colour."""

    class_id: int
    entity: str  # below world/
    label: str
    colour_name: str  # how the legend says it
    rgb: tuple[int, int, int]


# colours picked to read apart on the view's light background (and for red-green colour
# blindness: bodies blue, contacts red, arrows orange / purple / green differ in lightness too)
MOVING = Kind(1, "bodies/moving", "moving body", "blue outline", (40, 100, 210))
CONCRETE = Kind(2, "bodies/concrete", "concrete body", "thick dark grey outline", (70, 70, 70))
CONTACT = Kind(3, "contacts", "contact point", "red dot", (220, 30, 30))
NORMAL = Kind(4, "normals", "normal (a to b)", "orange arrow", (245, 150, 0))
IMPULSE = Kind(5, "impulses", "impulse j n", "purple arrow", (150, 40, 200))
PUSH = Kind(6, "push", "push-out", "green arrow", (0, 160, 60))
# a joint: a line between its bodies' anchors (a distance joint's rod, a prismatic joint's slide
# along its axis; none to see for a revolute or weld joint, whose anchors coincide) and the
# anchors as dots (a revolute joint's pivot); both darker than the bodies' blue, so they read on
# top of an outline
JOINT = Kind(7, "joints/lines", "joint (anchor a to anchor b)", "thick teal line", (0, 140, 150))
ANCHOR = Kind(8, "joints/anchors", "joint anchor, pivot", "dark teal dot", (0, 70, 80))
LEGEND = (MOVING, CONCRETE, CONTACT, NORMAL, IMPULSE, PUSH, JOINT, ANCHOR)

BACKGROUND = (250, 250, 247)  # the 2D view's, near white

# the `/stats` values as the Rerun recording holds them (``stats/<name>``), in this order in
# every stats row the writer buffers and sends
STAT_NAMES = (
    "kinetic_energy",
    "potential_energy",
    "total_energy",
    "linear_momentum_x",
    "linear_momentum_y",
    "angular_momentum",
    "contact_count",
    "max_depth",
    "max_impulse",
)
ENERGIES = ("kinetic_energy", "potential_energy", "total_energy")
# the other /stats series, one tab per unit: (tab name, series)
OTHER_STATS = (
    ("momentum", ("linear_momentum_x", "linear_momentum_y", "angular_momentum")),
    ("contacts", ("contact_count",)),
    ("max depth", ("max_depth",)),
    ("max impulse", ("max_impulse",)),
)
SERIES_COLOURS = {
    "kinetic_energy": (220, 60, 40),
    "potential_energy": (40, 110, 210),
    "total_energy": (30, 30, 30),
    "linear_momentum_x": (220, 60, 40),
    "linear_momentum_y": (40, 110, 210),
    "angular_momentum": (0, 150, 70),
    "contact_count": (150, 40, 200),
    "max_depth": (220, 30, 30),
    "max_impulse": (150, 40, 200),
}
SERIES_UNITS = {
    "kinetic_energy": "J",
    "potential_energy": "J",
    "total_energy": "J",
    "linear_momentum_x": "kg m/s",
    "linear_momentum_y": "kg m/s",
    "angular_momentum": "kg m^2/s",
    "contact_count": "rows",
    "max_depth": "m",
    "max_impulse": "N s",
}

WORLD_SHARE = 3  # the 2D view's share of the width, against 1 for the plots and the summary


def annotation_context() -> rr.AnnotationContext:
    """The legend as Rerun annotations: class id -> label and colour (logged on ``world``).

    Built as the arrow array of Rerun's own component type: Rerun's conversion of
    `rr.AnnotationInfo`s casts a list array, which imports ``pyarrow.compute`` (most of the
    Rerun sender's work in a short run, on the recorded run's critical path).
    The same array (tests/recorder/test_rerun_blueprint.py compares it with Rerun's conversion).
    """
    import pyarrow as pa
    import rerun as rr

    entries = [
        {
            "class_id": k.class_id,
            "class_description": {
                "info": {"id": k.class_id, "label": k.label, "color": _rgba(k.rgb)},
                "keypoint_annotations": [],
                "keypoint_connections": [],
            },
        }
        for k in LEGEND
    ]
    context = pa.array([entries], type=rr.components.AnnotationContextBatch._ARROW_DATATYPE)
    return rr.AnnotationContext(context=context)


def _rgba(rgb: tuple[int, int, int]) -> int:
    """An opaque colour as Rerun packs an RGB triple: 0xRRGGBBAA."""
    r, g, b = rgb
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def series_style(name: str) -> rr.SeriesLines:
    """How the ``stats/<name>`` series is drawn: its colour and a name with its unit."""
    import rerun as rr

    return rr.SeriesLines(
        colors=[SERIES_COLOURS[name]], names=[f"{name} ({SERIES_UNITS[name]})"], widths=[1.5]
    )


def legend_markdown(joints: bool = True) -> str:
    """The colour legend in words (for the summary text beside the view); joints: whether the
    run has any (else JOINT and ANCHOR are left out)."""
    lines = ["| colour | what |", "|---|---|"]
    for k in LEGEND if joints else [k for k in LEGEND if k not in (JOINT, ANCHOR)]:
        lines.append(f"| {k.colour_name} | {k.label} (`{k.entity}`) |")
    return "\n".join(lines)


def _series_view(name: str, series, origin: str = "/stats") -> rrb.TimeSeriesView:
    import rerun.blueprint as rrb

    return rrb.TimeSeriesView(
        origin=origin,
        contents=[f"{origin}/{s}" for s in series],
        name=name,
        plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop),
    )


def blueprint() -> rrb.Blueprint:
    """The layout every ISAAC recording opens in (see the module docstring)."""
    import rerun.blueprint as rrb

    world = rrb.Spatial2DView(
        origin="/",
        contents="/world/**",
        name="world (x right, y up; m)",
        background=rrb.Background(color=BACKGROUND),
    )
    plots = rrb.Tabs(
        _series_view("energy", ENERGIES),
        *(_series_view(tab, series) for tab, series in OTHER_STATS),
        active_tab=0,
    )
    summary = rrb.TextDocumentView(origin="/info", name="run")
    return rrb.Blueprint(
        rrb.Horizontal(
            world,
            rrb.Vertical(plots, summary, row_shares=[1, 1]),
            column_shares=[WORLD_SHARE, 1],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="step"),
        auto_layout=False,
        auto_views=False,
    )
