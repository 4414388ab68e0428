"""Rerun recording for every `ibrnav` command, the way rerun's examples do it:
`add_rerun_args` (rerun's standard --save / --connect / --headless ... flags), `rerun_setup`
and `rerun_teardown`. The entity tree is the same for every command (docs/ARCHITECTURE.md).

Each recording carries a blueprint (the viewer's layout) chosen by the command's application
id (`blueprint_for`): the 3-D world with cameras, particles and paths; the observed photo
beside the rendered one; time series of error, coverage and particle count, where the
command logs them. It also logs the command line and the ibrnav version as the text
document `meta/command`, so a recording says what made it."""

from __future__ import annotations

import argparse
import logging
import shlex
import sys

import rerun as rr
import rerun.blueprint as rrb

SINK_FLAGS = ("save", "connect", "serve", "stdout", "headless", "serve_web", "serve_grpc")
COMMAND_ENTITY = "meta/command"
ERROR_PLOTS = ("plots/estimate_error_m", "plots/estimate_error_deg", "plots/dead_reckoning_error_m",
               "plots/position_error_m", "plots/rotation_error_deg")
COVERAGE_PLOTS = ("plots/coverage", "plots/render/**", "plots/vueplan/**", "plots/eval/**")
PARTICLE_PLOTS = ("plots/particles",)
log = logging.getLogger(__name__)


def _images(observed: str | None, rendered: str | None) -> list:
    """The observed photo beside the rendered one (2-D views of image entities)."""
    views = []
    if observed:
        views.append(rrb.Spatial2DView(origin=observed, name="observed"))
    if rendered:
        views.append(rrb.Spatial2DView(origin=rendered, name="rendered"))
    return views


def analysis_blueprint(observed: str | None = None, rendered: str | None = None,
                       plots: bool = True) -> rrb.Blueprint:
    """The analyst's layout: the 3-D world (cameras, particles, paths) on the left; on the
    right the observed photo beside the rendered one, then error, coverage and particle-count
    time series, with the command line in a tab beside them."""
    right = []
    images = _images(observed, rendered)
    if images:
        right.append(rrb.Horizontal(*images))
    tabs = []
    if plots:
        tabs = [rrb.TimeSeriesView(origin="plots", contents=list(ERROR_PLOTS), name="error"),
                rrb.TimeSeriesView(origin="plots", contents=list(COVERAGE_PLOTS), name="coverage"),
                rrb.TimeSeriesView(origin="plots", contents=list(PARTICLE_PLOTS), name="particles"),
                rrb.TimeSeriesView(origin="plots", name="all plots")]
    right.append(rrb.Tabs(*tabs, rrb.TextDocumentView(origin=COMMAND_ENTITY, name="command")))
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial3DView(origin="world", name="world"), rrb.Vertical(*right),
                       column_shares=[3, 2]),
        collapse_panels=True)


MISSION = dict(observed="world/robot/camera", rendered="world/tour/camera")
TRACKING = dict(observed="localization/observed", rendered="localization/rendered_at_estimate")
BLUEPRINTS = {
    "ibrnav_demo": MISSION, "ibrnav_drive": dict(observed=MISSION["observed"]), "ibrnav_explore": MISSION,
    "ibrnav_eval_track": TRACKING, "ibrnav_localize": {**TRACKING, "plots": False},
    "ibrnav_eval_loc": TRACKING, "ibrnav_render": dict(rendered="world/render"),
    "ibrnav_eval_capture": dict(observed="world/eval/true", rendered="world/eval/ulr"),
    "ibrnav_scene_show": dict(plots=False),
    "ibrnav_scenic": dict(observed="world/cameras/agent0", rendered="world/cameras/agent1"),
}
"""Application id (prefix) -> the `analysis_blueprint` arguments of its command; others get
the 3-D world and every plot."""


def blueprint_for(app_id: str) -> rrb.Blueprint:
    """The blueprint of the command whose application id is (or starts with) app_id."""
    key = max((k for k in BLUEPRINTS if app_id.startswith(k)), key=len, default=None)
    return analysis_blueprint(**BLUEPRINTS.get(key, {}))


def log_command_line(argv: list[str]) -> None:
    """`meta/command`: the command line and the ibrnav version, as a static text document."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("ibrnav")
    except PackageNotFoundError:
        v = "unknown"
    text = f"{shlex.join(argv)}\n\nibrnav {v}, rerun-sdk {rr.__version__}, Python {sys.version.split()[0]}\n"
    rr.log(COMMAND_ENTITY, rr.TextDocument(text), static=True)


def add_rerun_args(parser: argparse.ArgumentParser) -> None:
    """rerun's standard --save/--connect/--headless/... flags."""
    rr.script_add_args(parser)


def recording_requested(args: argparse.Namespace) -> bool:
    """Whether the user gave a rerun sink flag (commands that record only when asked)."""
    return any(getattr(args, f, None) for f in SINK_FLAGS)


def rerun_setup(args: argparse.Namespace, app_id: str, default_save: str | None) -> None:
    """Start recording. With no sink flag given (and no viewer on a headless machine to
    spawn), record to `default_save` so a first run always leaves a file to open."""
    if default_save and not recording_requested(args):
        args.save = default_save
    rr.script_setup(args, app_id, default_blueprint=blueprint_for(app_id))
    rr.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    log_command_line(getattr(args, "command_line", None) or ["ibrnav", *sys.argv[1:]])
    if getattr(args, "save", None):
        log.info("recording to %s (open it with: rerun %s)", args.save, args.save)


def rerun_teardown(args: argparse.Namespace) -> None:
    """End the recording: rerun's own teardown, then flush and close the sinks, so a
    `.rrd` is complete (footer included) when the command returns, also when the command
    ran in-process (a notebook, a test) rather than as its own process."""
    rr.script_teardown(args)
    rr.disconnect()


def recording_layout(rrd: str) -> dict:
    """What a `.rrd` file says about itself, read with rerun's chunk reader: its application
    id, its blueprint's views as (kind, name, origin) (e.g. ("3D", "world", "/world")), and
    the `meta/command` text (empty when it has none)."""
    reader = rr.chunk.RrdReader(rrd)
    recordings = reader.recordings()
    if not recordings:
        raise ValueError(f"{rrd}: no recording in the file")
    views = {}
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            row = chunk.to_record_batch().to_pylist()
            if chunk.entity_path.startswith("/view/") and row and "ViewBlueprint:class_identifier" in row[-1]:
                r = row[-1]
                views[chunk.entity_path] = tuple(_scalar(r[f"ViewBlueprint:{k}"])
                                                 for k in ("class_identifier", "display_name", "space_origin"))
    command = ""
    for chunk in reader.stream(store=recordings[0]):
        if chunk.entity_path == f"/{COMMAND_ENTITY}":
            command = _scalar(chunk.to_record_batch().to_pylist()[-1]["TextDocument:text"])
    return {"application_id": recordings[0].application_id, "views": sorted(views.values()), "command": command}


def _scalar(cell):
    """The one value of a rerun component cell (a list of one)."""
    return cell[0] if isinstance(cell, list) else cell


def recording_scalars(rrd: str, index: str = "step"):
    """The scalar time series under `plots/` of a `.rrd`, read with rerun's dataframe API, as
    a pandas DataFrame: one row per value of the timeline `index`, one column per plot
    (named by its entity path, e.g. "plots/coverage"), NaN where a plot has no value at that
    row; the other timelines (e.g. `sensor_time`) as columns too. Needs `rerun-sdk[catalog]`."""
    import numpy as np

    store = rr.chunk.RrdReader(str(rrd)).stream().collect()
    df = store.reader(index=index, contents="/plots/**").to_pandas()
    out = df[[c for c in df.columns if ":" not in c and c != "log_time"]].copy()
    for c in df.columns:
        if c.endswith(":Scalars:scalars"):
            out[c.split(":")[0].lstrip("/")] = [float(v[0]) if v is not None and len(v) else np.nan for v in df[c]]
    return out.set_index(index)
