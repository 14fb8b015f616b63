"""The Foxglove layout shipped with the package: one view of everything run.mcap holds.

A 3-D view (map frame, following the boat: cloud, walls, segments, plan, hull circles,
tracks), a map of the GPS fix, plots of commands, clearance and solve time, and the status
in time. Built with the SDK's own layout types (`foxglove.layouts`); the file
`canalnav.layout.json` beside this module is its output (`python -m
scenarios.results.foxglove_layout` writes it again; a test checks they agree).
"""

from __future__ import annotations

import sys
from pathlib import Path

from scenarios.results.mcap_log import TOPICS

LAYOUT_PATH = Path(__file__).with_name("canalnav.layout.json")


def build_layout() -> str:
    """The layout as JSON text."""
    from scenarios.results.foxglove_messages import require_viz

    require_viz()
    import foxglove.layouts as fl

    step = TOPICS["figures"]
    topics = {TOPICS[k]: fl.BaseRendererSceneUpdateTopicSettings(visible=True)
              for k in ("walls", "segments", "tracks", "plan", "hull")}
    topics[TOPICS["cloud"]] = fl.BaseRendererPointCloudTopicSettings(
        visible=True, point_size=2.0, color_mode="colormap", color_field="z")
    scene = fl.ThreeDeePanel(title="canal", config=fl.ThreeDeeConfig(
        fixed_frame="map", follow_tf="boat", follow_mode="follow-position", topics=topics,
        camera_state=fl.ThreeDeeCameraState(distance=80.0, perspective=False, phi=0.0)))

    def plot(title, *fields):
        return fl.PlotPanel(title=title, config=fl.PlotConfig(paths=[
            fl.PlotSeries(value=f"{step}.{f}", label=f) for f in fields], show_legend=True))

    plots = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(content=plot("commands [%]", "nT_cmd_pct", "nS_cmd_pct",
                                  "nT_actual_pct", "nS_actual_pct")),
        fl.SplitItem(content=plot("rates [%/s]", "dnT_pctps", "dnS_pctps")),
        fl.SplitItem(content=plot("clearance [m]", "clearance_bow_m", "clearance_stern_m",
                                  "desired_separation_m", "cross_track_m")),
        fl.SplitItem(content=plot("solve [ms], slack [m]", "solve_ms", "slack_m")),
        fl.SplitItem(content=fl.StateTransitionsPanel(
            title="status", config=fl.StateTransitionsConfig(paths=[
                fl.StateTransitionsSeries(value=f"{step}.status", label="status"),
                fl.StateTransitionsSeries(value=f"{step}.waiting", label="waiting"),
                fl.StateTransitionsSeries(value=f"{step}.blind", label="blind")]))),
    ])
    left = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=3, content=scene),
        fl.SplitItem(proportion=1, content=fl.MapPanel(title="GPS fix", config=fl.MapConfig(
            follow_topic=TOPICS["fix"]))),
    ])
    layout = fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=left), fl.SplitItem(proportion=2, content=plots)]))
    return layout.to_json() + "\n"


if __name__ == "__main__":
    LAYOUT_PATH.write_text(build_layout())
    sys.stdout.write(f"wrote {LAYOUT_PATH}\n")
