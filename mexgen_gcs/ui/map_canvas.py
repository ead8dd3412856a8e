"""Pure drawing for the map panel: a braille dot canvas and the scene drawn on it.

Frame: local ENU metres about home (x = east, y = north), north up on the screen. No Textual
here; ``draw_map`` turns plain data into rows of Rich ``Text`` so it can be tested alone.

A terminal cell holds a 2 x 4 braille dot grid; cells are about twice as tall as wide, so a
dot is close to square and one metres-per-dot scale serves both axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from rich.text import Text

# braille dot bits, indexed [row 0..3][col 0..1] (Unicode braille patterns, U+2800 base)
_DOT_BITS = np.array([[0x01, 0x08], [0x02, 0x10], [0x04, 0x20], [0x40, 0x80]], dtype=np.uint8)
_BRAILLE_BASE = 0x2800
DOTS_X = 2
DOTS_Y = 4

#: chi-square quantile (2 dof) scaling a covariance ellipse to 95 % confidence: sqrt(5.991)
ELLIPSE_95_SCALE = math.sqrt(5.991464547107979)

#: per-tag colours, cycled in mission tag order
TAG_STYLES = ("bright_cyan", "bright_magenta", "bright_yellow", "bright_green", "orange1",
              "deep_sky_blue1", "hot_pink", "chartreuse1")

_ARROWS = "↑↗→↘↓↙←↖"


@dataclass(frozen=True, slots=True)
class MapTag:
    """One tag as the map draws it (ENU metres)."""

    tag_id: str
    east_m: float
    north_m: float
    cov_pos_m2: tuple[float, float, float]
    """(var_e, cov_en, var_n)."""
    existence: float
    localised: bool
    cloud_en_m: tuple[tuple[float, float], ...] = ()
    truth_en_m: tuple[float, float] | None = None


@dataclass(frozen=True, slots=True)
class MapScene:
    """Everything the map shows, as plain values."""

    area_en_m: tuple[tuple[float, float], ...] = ()
    home_en_m: tuple[float, float] = (0.0, 0.0)
    vehicle_en_m: tuple[float, float] | None = None
    vehicle_yaw_deg: float = 0.0
    track_en_m: tuple[tuple[float, float], ...] = ()
    tags: tuple[MapTag, ...] = ()
    heading_deg: float | None = None
    """The planner's chosen heading, drawn as a short ray from the vehicle."""


@dataclass(frozen=True, slots=True)
class Viewport:
    """What part of the plane is shown: a centre and a scale (metres per braille dot)."""

    centre_e_m: float
    centre_n_m: float
    m_per_dot: float

    def to_dots(self, e_m: np.ndarray, n_m: np.ndarray, width_cells: int,
                height_cells: int) -> tuple[np.ndarray, np.ndarray]:
        """ENU metres (N,) -> dot column and row (N,) float; row 0 at the top."""
        cx = width_cells * DOTS_X / 2.0
        cy = height_cells * DOTS_Y / 2.0
        col = cx + (e_m - self.centre_e_m) / self.m_per_dot
        row = cy - (n_m - self.centre_n_m) / self.m_per_dot
        return col, row

    def zoomed(self, factor: float) -> Viewport:
        return Viewport(self.centre_e_m, self.centre_n_m, self.m_per_dot / factor)

    def panned(self, de_m: float, dn_m: float) -> Viewport:
        return Viewport(self.centre_e_m + de_m, self.centre_n_m + dn_m, self.m_per_dot)


def fit_viewport(points_en_m: np.ndarray, width_cells: int, height_cells: int,
                 margin: float = 0.06) -> Viewport:
    """The viewport that shows all points (K, 2) with a relative margin."""
    pts = np.asarray(points_en_m, dtype=float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        pts = np.zeros((1, 2))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = np.maximum(hi - lo, 10.0) * (1.0 + 2.0 * margin)
    w_dots = max(width_cells * DOTS_X, 1)
    h_dots = max(height_cells * DOTS_Y, 1)
    m_per_dot = float(max(span[0] / w_dots, span[1] / h_dots))
    centre = (lo + hi) / 2.0
    return Viewport(float(centre[0]), float(centre[1]), m_per_dot)


@dataclass
class BrailleCanvas:
    """A width x height cell canvas of braille dots, one style per cell, text on top."""

    width: int
    height: int
    dots: np.ndarray = field(init=False)
    """(height, width) uint8 dot bits."""
    style: np.ndarray = field(init=False)
    """(height, width) int16 index into ``styles`` (-1 = none); the last layer drawn wins."""
    styles: list[str] = field(init=False, default_factory=list)
    text: dict[tuple[int, int], tuple[str, str]] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        self.dots = np.zeros((self.height, self.width), dtype=np.uint8)
        self.style = np.full((self.height, self.width), -1, dtype=np.int16)

    def style_index(self, style: str) -> int:
        if style not in self.styles:
            self.styles.append(style)
        return self.styles.index(style)

    def plot(self, col: np.ndarray, row: np.ndarray, style: str) -> np.ndarray:
        """Set dots at float dot coordinates (N,); returns the (M, 2) cells touched."""
        c = np.floor(np.asarray(col, dtype=float)).astype(np.int64, copy=False)
        r = np.floor(np.asarray(row, dtype=float)).astype(np.int64, copy=False)
        ok = (c >= 0) & (r >= 0) & (c < self.width * DOTS_X) & (r < self.height * DOTS_Y)
        c, r = c[ok], r[ok]
        if len(c) == 0:
            return np.empty((0, 2), dtype=np.int64)
        cell_r, cell_c = r // DOTS_Y, c // DOTS_X
        np.bitwise_or.at(self.dots, (cell_r, cell_c), _DOT_BITS[r % DOTS_Y, c % DOTS_X])
        self.style[cell_r, cell_c] = self.style_index(style)
        return np.stack([cell_r, cell_c], axis=1)

    def polyline(self, col: np.ndarray, row: np.ndarray, style: str) -> None:
        """Connect consecutive dot coordinates (N,) with lines, in one vectorised plot."""
        col = np.asarray(col, dtype=float)
        row = np.asarray(row, dtype=float)
        if len(col) < 2:
            self.plot(col, row, style)
            return
        # one sample per dot along each segment; a far off-screen segment at high zoom is
        # clipped to a generous box first so the sample count stays bounded
        lim_c, lim_r = 4.0 * self.width * DOTS_X, 4.0 * self.height * DOTS_Y
        col = np.clip(col, -lim_c, lim_c)
        row = np.clip(row, -lim_r, lim_r)
        n = (np.maximum(np.abs(np.diff(col)), np.abs(np.diff(row))) + 2).astype(np.int64)
        seg = np.repeat(np.arange(len(n)), n)
        start = np.repeat(np.cumsum(n) - n, n)
        t = (np.arange(len(seg)) - start) / np.repeat(np.maximum(n - 1, 1), n)
        self.plot(col[seg] + np.diff(col)[seg] * t, row[seg] + np.diff(row)[seg] * t, style)

    def put_text(self, row: int, col: int, s: str, style: str) -> None:
        """Write characters over the dots (clipped to the canvas)."""
        for i, ch in enumerate(s):
            if 0 <= row < self.height and 0 <= col + i < self.width:
                self.text[(row, col + i)] = (ch, style)

    def runs(self) -> list[list[tuple[str, str]]]:
        """Per row, (characters, style) runs with one style each ("" = plain)."""
        chars = np.where(self.dots > 0, self.dots.astype(np.int32) + _BRAILLE_BASE, 0x20)
        style = np.where(self.dots > 0, self.style, -1)
        out: list[list[tuple[str, str]]] = []
        for r in range(self.height):
            row_chars = [chr(c) for c in chars[r].tolist()]
            row_styles = [self.styles[i] if i >= 0 else "" for i in style[r].tolist()]
            for (tr, tc), (ch, st) in self.text.items():
                if tr == r:
                    row_chars[tc], row_styles[tc] = ch, st
            line: list[tuple[str, str]] = []
            start = 0
            for c in range(1, self.width + 1):
                if c == self.width or row_styles[c] != row_styles[start]:
                    line.append(("".join(row_chars[start:c]), row_styles[start]))
                    start = c
            out.append(line)
        return out

    def rows(self) -> list[Text]:
        """Rich Text per row (for tests and anything printing the map)."""
        out: list[Text] = []
        for line in self.runs():
            text = Text(no_wrap=True, overflow="crop")
            for chunk, st in line:
                text.append(chunk, style=st or None)
            out.append(text)
        return out


def ellipse_points(e_m: float, n_m: float, cov_pos_m2: tuple[float, float, float],
                   scale: float = ELLIPSE_95_SCALE, k: int = 96) -> np.ndarray:
    """(k, 2) ENU points on the covariance ellipse scaled by `scale` sigma (95 % by default)."""
    var_e, cov_en, var_n = cov_pos_m2
    cov = np.array([[var_e, cov_en], [cov_en, var_n]], dtype=float)
    if not np.all(np.isfinite(cov)):
        return np.empty((0, 2))
    vals, vecs = np.linalg.eigh(cov)
    vals = np.clip(vals, 0.0, None)
    ang = np.linspace(0.0, 2.0 * math.pi, k, endpoint=False)
    unit = np.stack([np.cos(ang), np.sin(ang)], axis=1)  # (k, 2)
    pts = (unit * (scale * np.sqrt(vals))) @ vecs.T
    return pts + np.array([e_m, n_m])


def heading_arrow(yaw_deg: float) -> str:
    """The arrow character nearest a compass heading (0 north, clockwise)."""
    return _ARROWS[int(((yaw_deg % 360.0) + 22.5) // 45.0) % 8]


def scale_bar(m_per_dot: float, width_cells: int) -> tuple[str, int]:
    """A round length (label, cells) for a scale bar at most a quarter of the width."""
    max_m = m_per_dot * DOTS_X * max(width_cells // 4, 1)
    nice = 1.0
    for step in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10_000, 20_000, 50_000):
        if step <= max_m:
            nice = float(step)
    cells = max(round(nice / (m_per_dot * DOTS_X)), 1)
    label = f"{nice / 1000:g} km" if nice >= 1000 else f"{nice:g} m"
    return label, cells


def tag_style(index: int) -> str:
    return TAG_STYLES[index % len(TAG_STYLES)]


def draw_map(scene: MapScene, view: Viewport, width_cells: int, height_cells: int, *,
             show_truth: bool = False) -> list[Text]:
    """`draw_canvas` as Rich Text, one per row of `width_cells` characters."""
    return draw_canvas(scene, view, width_cells, height_cells, show_truth=show_truth).rows()


def draw_canvas(scene: MapScene, view: Viewport, width_cells: int, height_cells: int, *,
                show_truth: bool = False) -> BrailleCanvas:
    """Render a scene: area, track, particle clouds, ellipses, tags, home, vehicle, labels.

    Layers are drawn back to front; where layers share a cell the later one sets its colour.
    """
    w, h = max(width_cells, 1), max(height_cells, 1)
    canvas = BrailleCanvas(w, h)

    def dots(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return view.to_dots(p[:, 0], p[:, 1], w, h)

    def cell_of(e_m: float, n_m: float) -> tuple[int, int]:
        c, r = view.to_dots(np.array([e_m]), np.array([n_m]), w, h)
        return math.floor(r[0] / DOTS_Y), math.floor(c[0] / DOTS_X)

    # search area outline
    if len(scene.area_en_m) >= 2:
        canvas.polyline(*dots(np.array(scene.area_en_m + scene.area_en_m[:1])), "grey62")
    # particle clouds: dense cells in bold
    for i, tag in enumerate(scene.tags):
        if not tag.cloud_en_m:
            continue
        c, r = dots(np.array(tag.cloud_en_m))
        cells = canvas.plot(c, r, tag_style(i))
        if len(cells):
            uniq, counts = np.unique(cells, axis=0, return_counts=True)
            dense = uniq[counts >= 4]
            if len(dense):
                canvas.style[dense[:, 0], dense[:, 1]] = canvas.style_index(
                    f"bold {tag_style(i)}")
    # vehicle track
    if len(scene.track_en_m) >= 2:
        canvas.polyline(*dots(np.array(scene.track_en_m)), "white")
    # estimate ellipses
    for i, tag in enumerate(scene.tags):
        if not (math.isfinite(tag.east_m) and math.isfinite(tag.north_m)):
            continue
        pts = ellipse_points(tag.east_m, tag.north_m, tag.cov_pos_m2)
        if len(pts):
            canvas.polyline(*dots(np.vstack([pts, pts[:1]])), f"bold {tag_style(i)}")
    # planned heading: a ray of 6 cells from the vehicle
    if scene.vehicle_en_m is not None and scene.heading_deg is not None:
        ve, vn = scene.vehicle_en_m
        if math.isfinite(ve) and math.isfinite(vn):
            length_m = 6 * DOTS_X * view.m_per_dot
            rad = math.radians(scene.heading_deg)
            canvas.polyline(*dots(np.array([[ve, vn], [ve + length_m * math.sin(rad),
                                                       vn + length_m * math.cos(rad)]])),
                            "bold bright_white")
    # labels: tag estimates (marked when localised), truth, home, vehicle last (on top)
    for i, tag in enumerate(scene.tags):
        st = tag_style(i)
        if math.isfinite(tag.east_m) and math.isfinite(tag.north_m):
            er, ec = cell_of(tag.east_m, tag.north_m)
            if tag.localised:
                canvas.put_text(er, ec, "◉", f"bold reverse {st}")
                canvas.put_text(er, ec + 1, f"{tag.tag_id}✓", f"bold {st}")
            else:
                canvas.put_text(er, ec, "+", f"bold {st}")
                canvas.put_text(er, ec + 1, tag.tag_id, st)
    if show_truth:  # after the estimates; beside the mark when they share a cell
        for i, tag in enumerate(scene.tags):
            if tag.truth_en_m is not None:
                tr, tc = cell_of(*tag.truth_en_m)
                if (tr, tc) in canvas.text:
                    tc -= 1
                canvas.put_text(tr, tc, "×", f"bold reverse {tag_style(i)}")
    hr, hc = cell_of(*scene.home_en_m)
    canvas.put_text(hr, hc, "H", "bold black on bright_white")
    if scene.vehicle_en_m is not None and all(map(math.isfinite, scene.vehicle_en_m)):
        vr, vc = cell_of(*scene.vehicle_en_m)
        canvas.put_text(vr, vc, heading_arrow(scene.vehicle_yaw_deg), "bold black on bright_red")
    # compass and scale bar
    canvas.put_text(0, w - 3, "N↑", "bold")
    label, bar_cells = scale_bar(view.m_per_dot, w)
    canvas.put_text(h - 1, 1, "├" + "─" * max(bar_cells - 2, 0) + "┤", "bold")
    canvas.put_text(h - 1, 1 + max(bar_cells, 2) + 1, label, "bold")
    return canvas
