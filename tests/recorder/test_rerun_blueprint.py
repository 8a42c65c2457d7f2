"""The layout and the drawing conventions stored in every .rrd: read back from the file."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

sys.path.insert(0, str(Path(__file__).parent))
from test_recorder_mcap import record_run  # noqa: E402
from test_recorder_rerun import rrd_rows  # noqa: E402

from recorder import blueprint  # noqa: E402
from recorder.rerun_writer import PUSH_SCALE  # noqa: E402


def blueprint_rows(path) -> dict[str, dict]:
    """{entity: {column: first value}} of the blueprint stored in the .rrd."""
    reader = RrdReader(str(path))
    (store,) = reader.blueprints()
    out: dict[str, dict] = {}
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        row = out.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            if ":" not in name:  # the row id and the timelines
                continue
            values = batch.column(name).to_pylist()
            if values and values[0] is not None:
                row[name] = values[0]
    return out


def static_values(path, entity, component) -> list:
    """Every static value of one component of one entity, in file order (the viewer keeps the
    last)."""
    out = []
    for chunk in RrdReader(str(path)).stream():
        if chunk.entity_path != entity or not chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if component in batch.schema.names:
            out += [v for v in batch.column(component).to_pylist() if v is not None]
    return out


def _one(value):
    """A blueprint component as stored: a one-element list of its value (or the value)."""
    return value[0] if isinstance(value, list) and len(value) == 1 else value


def test_the_recording_opens_on_one_2d_view_of_slash_with_the_stats_beside_it(tmp_path):
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    record_run(mcap, n=8, contacts=3, steps=30, rrd=rrd)
    rows = blueprint_rows(rrd)
    views = {e: r for e, r in rows.items() if "ViewBlueprint:class_identifier" in r}
    kinds = sorted(_one(r["ViewBlueprint:class_identifier"]) for r in views.values())
    assert kinds == ["2D"] + ["TextDocument"] + ["TimeSeries"] * (1 + len(blueprint.OTHER_STATS))
    (world,) = [e for e, r in views.items() if _one(r["ViewBlueprint:class_identifier"]) == "2D"]
    # origin / : the y-flip logged on /world applies (a view never applies its own origin's)
    assert _one(views[world]["ViewBlueprint:space_origin"]) == "/"
    contents = rows[world + "/ViewContents"]["ViewContents:query"]
    assert contents == ["/world/**"]
    # one energy plot holds the three energies
    queries = [
        " ".join(rows[e + "/ViewContents"]["ViewContents:query"])
        for e, r in views.items()
        if _one(r["ViewBlueprint:class_identifier"]) == "TimeSeries"
    ]
    assert any(all(f"/stats/{s}" in q for s in blueprint.ENERGIES) for q in queries)
    # every /stats series is in some plot
    every = {s for _, series in blueprint.OTHER_STATS for s in series} | set(blueprint.ENERGIES)
    assert all(any(f"/stats/{s}" in q for q in queries) for s in every)
    # the 2D view's share of the top container's width
    top = _one(rows["/viewport"]["ViewportBlueprint:root_container"])
    assert top is not None
    shares = [
        r["ContainerBlueprint:col_shares"]
        for r in rows.values()
        if "ContainerBlueprint:col_shares" in r
    ]
    assert [blueprint.WORLD_SHARE, 1] in [[float(x) for x in s] for s in shares]
    assert _one(rows["/time_panel"]["TimePanelBlueprint:timeline"]) == "step"


def test_bodies_are_labelled_with_their_log_index_and_push_arrows_are_scaled(tmp_path):
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    sim, records = record_run(mcap, n=9, contacts=4, steps=40, rrd=rrd, leave_at=20)
    names = [str(x) for x in sim.model.names]
    labels = rrd_rows(rrd, "/world/bodies/moving", "LineStrips2D:labels")
    moving = np.flatnonzero(~sim.model.concrete)
    assert labels[0] == [f"{k}:{names[k]}" for k in moving]
    (static,) = static_values(rrd, "/world/bodies/concrete", "LineStrips2D:labels")
    assert static == [f"{k}:{names[k]}" for k in np.flatnonzero(sim.model.concrete)]
    # push arrows: the non-zero pushes of a then b, each PUSH_SCALE times its length
    vectors = rrd_rows(rrd, "/world/push", "Arrows2D:vectors")
    r = records[11]
    push = np.concatenate([r.contacts.push_a, r.contacts.push_b])
    push = push[np.any(push != 0.0, axis=1)]
    np.testing.assert_allclose(np.array(vectors[11]), PUSH_SCALE * push, rtol=1e-6, atol=1e-9)


def test_the_summary_text_says_how_the_run_ended_and_names_every_colour(tmp_path):
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    _, records = record_run(mcap, n=6, contacts=2, steps=25, rrd=rrd)
    text = _one(static_values(rrd, "/info", "TextDocument:text")[-1])
    assert "run complete" in text
    assert f"{len(records)} steps recorded: 0 to {records[-1].step}" in text
    for kind in blueprint.LEGEND:
        if kind in (blueprint.JOINT, blueprint.ANCHOR):  # a run without joints: not listed
            assert kind.label not in text
            continue
        assert kind.colour_name in text and kind.label in text
    # the legend's colours are the annotation context's: one class per kind, on /world
    (row,) = static_values(rrd, "/world", "AnnotationContext:context")
    got = {c["class_id"]: c["class_description"]["info"] for c in _one(row)}
    for kind in blueprint.LEGEND:
        r, g, b = kind.rgb
        assert got[kind.class_id]["label"] == kind.label
        assert got[kind.class_id]["color"] == (r << 24) | (g << 16) | (b << 8) | 0xFF  # RGBA
        if kind in (blueprint.JOINT, blueprint.ANCHOR):
            continue  # this run has no joints (test_rerun_joints_batches: a run with)
        # and each entity is drawn in its class (no colour of its own to disagree)
        archetype = {"contacts": "Points2D", "bodies/moving": "LineStrips2D"}.get(
            kind.entity, "LineStrips2D" if kind is blueprint.CONCRETE else "Arrows2D"
        )
        ids = static_values(rrd, f"/world/{kind.entity}", f"{archetype}:class_ids")
        assert ids and all(x == [kind.class_id] for x in ids), (kind.entity, ids)
        assert not static_values(rrd, f"/world/{kind.entity}", f"{archetype}:colors")


def test_the_legend_annotations_are_the_array_rerun_builds_itself():
    """The annotation context is built as an arrow array (Rerun's own conversion imports
    pyarrow.compute, 70-90 ms of a short recorded run): the same values and type as Rerun's
    conversion of the same `AnnotationInfo`s, without importing pyarrow.compute."""
    import subprocess

    import rerun as rr

    ours = blueprint.annotation_context().context.pa_array
    theirs = rr.AnnotationContext(
        [rr.AnnotationInfo(id=k.class_id, label=k.label, color=k.rgb) for k in blueprint.LEGEND]
    ).context.pa_array
    assert ours.type == theirs.type
    assert ours.equals(theirs)
    assert len(ours.to_pylist()[0]) == len(blueprint.LEGEND)
    code = (
        "import sys; from recorder import blueprint; blueprint.annotation_context(); "
        "print('pyarrow.compute' in sys.modules)"
    )
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "False"
