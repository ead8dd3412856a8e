"""The map panel: search area, home, vehicle and track, tag clouds, estimates and truth.

Frame: local ENU metres about home, north up. The widget keeps only what it was last shown
(a ``MapScene``) and its own view state (zoom, pan, truth toggle); drawing is in map_canvas.
"""

from __future__ import annotations

import math
from typing import Self

import numpy as np
from rich.segment import Segment
from rich.style import Style
from textual.geometry import Region
from textual.strip import Strip
from textual.widget import Widget

from mexgen_gcs.io.snapshot import MissionSnapshot
from mexgen_gcs.mission.state import MissionState
from mexgen_gcs.ui.map_canvas import MapScene, MapTag, Viewport, draw_canvas, fit_viewport

ZOOM_STEP = 1.5
ZOOM_MIN = 0.25
ZOOM_MAX = 200.0
PAN_FRACTION = 0.2


class MapView(Widget):
    """A braille map of one MapScene; zoom, pan and the truth overlay are its own state."""

    def __init__(self, *, id: str | None = None, classes: str | None = None) -> None:
        self._lines: list[Strip] | None = None
        super().__init__(id=id, classes=classes)
        self.scene = MapScene()
        self.zoom_factor = 1.0
        self.pan_en_m = (0.0, 0.0)
        self.show_truth = False
        self.border_title = "Map"
        self.border_subtitle = "+/- zoom · arrows pan · 0 fit"

    # -- what to draw ------------------------------------------------------------------------

    def show(self, scene: MapScene) -> None:
        self.scene = scene
        if self.truth_available:
            self.border_subtitle = "+/- zoom · arrows pan · 0 fit · t truth" + (
                " (on)" if self.show_truth else "")
        self.refresh()

    @property
    def truth_available(self) -> bool:
        return any(t.truth_en_m is not None for t in self.scene.tags)

    # -- view state --------------------------------------------------------------------------

    def zoom(self, steps: int) -> None:
        """Zoom in (steps > 0) or out about the view centre."""
        self.zoom_factor = float(np.clip(self.zoom_factor * ZOOM_STEP ** steps, ZOOM_MIN,
                                         ZOOM_MAX))
        self.refresh()

    def pan(self, dx: int, dy: int) -> None:
        """Move the view by a fraction of its width/height per step (x east, y north)."""
        view = self.viewport()
        w, h = self._cells()
        span_e = w * 2 * view.m_per_dot
        span_n = h * 4 * view.m_per_dot
        self.pan_en_m = (self.pan_en_m[0] + dx * PAN_FRACTION * span_e,
                         self.pan_en_m[1] + dy * PAN_FRACTION * span_n)
        self.refresh()

    def reset_view(self) -> None:
        self.zoom_factor = 1.0
        self.pan_en_m = (0.0, 0.0)
        self.refresh()

    def centre_on(self, east_m: float, north_m: float) -> None:
        """Pan so that an ENU point is in the middle (the zoom stays)."""
        if not (math.isfinite(east_m) and math.isfinite(north_m)):
            return
        base = self._fitted()
        self.pan_en_m = (east_m - base.centre_e_m, north_m - base.centre_n_m)
        self.refresh()

    def toggle_truth(self) -> bool:
        self.show_truth = not self.show_truth and self.truth_available
        self.show(self.scene)
        return self.show_truth

    def _cells(self) -> tuple[int, int]:
        return max(self.content_size.width, 1), max(self.content_size.height, 1)

    def _fitted(self) -> Viewport:
        w, h = self._cells()
        pts: list[tuple[float, float]] = [*self.scene.area_en_m, self.scene.home_en_m]
        if not self.scene.area_en_m:
            pts += [(t.east_m, t.north_m) for t in self.scene.tags]
            if self.scene.vehicle_en_m is not None:
                pts.append(self.scene.vehicle_en_m)
        return fit_viewport(np.array(pts, dtype=float), w, h)

    def viewport(self) -> Viewport:
        base = self._fitted()
        return Viewport(base.centre_e_m + self.pan_en_m[0], base.centre_n_m + self.pan_en_m[1],
                        base.m_per_dot / self.zoom_factor)

    def refresh(self, *regions: Region, repaint: bool = True, layout: bool = False,
                recompose: bool = False) -> Self:
        self._lines = None  # whatever changed, draw the canvas again
        return super().refresh(*regions, repaint=repaint, layout=layout, recompose=recompose)

    def on_resize(self) -> None:
        self.refresh()

    def render_line(self, y: int) -> Strip:
        """Line API: the canvas is drawn once per change and handed out row by row."""
        w, h = self._cells()
        if self._lines is None or len(self._lines) != h:
            canvas = draw_canvas(self.scene, self.viewport(), w, h, show_truth=self.show_truth)
            self._lines = [
                Strip([Segment(chunk, Style.parse(st) if st else None) for chunk, st in row], w)
                for row in canvas.runs()]
        return self._lines[y] if 0 <= y < len(self._lines) else Strip.blank(w)


def scene_from_snapshot(snap: MissionSnapshot) -> MapScene:
    """What the map needs from a mission snapshot (ENU metres about home)."""
    tags = tuple(
        MapTag(t.tag_id, t.east_m, t.north_m, t.cov_pos_m2, t.existence, t.localised,
               t.cloud_en_m, t.truth_en_m)
        for t in snap.tags)
    return MapScene(
        area_en_m=snap.area_en_m, home_en_m=(0.0, 0.0), vehicle_en_m=snap.vehicle_en_m,
        vehicle_yaw_deg=snap.telemetry.yaw_deg, track_en_m=snap.track_en_m, tags=tags,
        heading_deg=snap.plan.chosen_heading_deg if (
            snap.plan is not None and snap.state == MissionState.SEARCHING) else None)
