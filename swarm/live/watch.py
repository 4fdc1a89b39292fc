"""Drawing a run in a terminal (`swarm watch`): pure functions, no I/O, no zenoh.

World coordinates (metres, y up) map onto a grid of character cells (column right, row
down). A terminal cell is about twice as tall as it is wide, so one metre spans
`scale` columns but only `scale * aspect` rows (aspect 0.5 by default): circles look
round. Everything is drawn into a `Canvas` of cells, each with a character, a rich
style name and a layer; a higher layer overwrites a lower one, never the reverse
(orbits < edges < arrowheads < target < agents < labels).

    view = fit_view(points, width, height)        # world -> cells
    line_cells(c0, r0, c1, r1)                     # Bresenham, both ends included
    circle_cells(view, x, y, r)                    # a closed, 8-connected ring of cells
    dashed(cells)                                  # every other pair of cells
    draw_scene(target, bodies, width, height)      # the whole picture -> Canvas

The screen around the picture (header, agents table, legend) is in swarm/live/views.py.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

ARROWS = "→↗↑↖←↙↓↘"  # index k: direction k * 45 degrees, counter-clockwise from +x
DEAD_GLYPH = "x"
TARGET_GLYPH = "+"
EDGE_GLYPH = "·"
ORBIT_GLYPH = "."

# layers
L_ORBIT, L_EDGE, L_HEAD, L_TARGET, L_AGENT, L_LABEL = 1, 2, 3, 4, 5, 6

STYLES = {
    "leader": "bold blue",
    "follower": "bold yellow",
    "unrooted": "bold red",
    "dead": "grey50",
    "target": "bold red",
    "edge": "cyan",
    "orbit": "grey42",
    "leader_orbit": "blue",
}


@dataclass(frozen=True)
class View:
    """A mapping from world coordinates to grid cells."""

    cx: float  # world point drawn at the centre of the grid
    cy: float
    scale: float  # columns per metre
    width: int  # columns
    height: int  # rows
    aspect: float = 0.5  # rows per column for the same length

    def cell(self, x: float, y: float) -> tuple[int, int]:
        """(column, row) of a world point; may lie outside the grid."""
        col = (x - self.cx) * self.scale + (self.width - 1) / 2
        row = (self.cy - y) * self.scale * self.aspect + (self.height - 1) / 2
        return int(math.floor(col + 0.5)), int(math.floor(row + 0.5))


def fit_view(
    points: Iterable[tuple[float, float]], width: int, height: int, aspect: float = 0.5, margin: int = 1
) -> View:
    """The largest scale at which every point fits inside the grid, `margin` cells from
    its border, centred on the points' bounding box. No points: the origin, 1 col/m."""
    if width < 1 or height < 1:
        raise ValueError(f"grid of {width} x {height} cells: both must be >= 1")
    pts = [(float(x), float(y)) for x, y in points if math.isfinite(x) and math.isfinite(y)]
    if not pts:
        return View(0.0, 0.0, 1.0, width, height, aspect)
    xs, ys = zip(*pts)
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    usable_w, usable_h = max(width - 1 - 2 * margin, 1), max(height - 1 - 2 * margin, 1)
    span_x, span_y = x1 - x0, y1 - y0
    scales = []
    if span_x > 0:
        scales.append(usable_w / span_x)
    if span_y > 0:
        scales.append(usable_h / (span_y * aspect))
    scale = min(scales) if scales else 1.0
    return View(cx, cy, scale, width, height, aspect)


def line_cells(c0: int, r0: int, c1: int, r1: int) -> list[tuple[int, int]]:
    """Bresenham's line from (c0, r0) to (c1, r1), both ends included, in order."""
    cells = []
    dc, dr = abs(c1 - c0), -abs(r1 - r0)
    sc = 1 if c0 < c1 else -1
    sr = 1 if r0 < r1 else -1
    err = dc + dr
    c, r = c0, r0
    while True:
        cells.append((c, r))
        if c == c1 and r == r1:
            return cells
        e2 = 2 * err
        if e2 >= dr:
            err += dr
            c += sc
        if e2 <= dc:
            err += dc
            r += sr


def circle_cells(view: View, x: float, y: float, radius: float) -> list[tuple[int, int]]:
    """The cells of a circle of `radius` m about (x, y), in order around it (counter-
    clockwise from +x), each next to the one before (8-connected), no cell twice in a
    row, and the last next to the first. Cells outside the grid are included."""
    if radius <= 0 or not math.isfinite(radius):
        return [view.cell(x, y)]
    n = max(8, int(math.ceil(2 * math.pi * radius * view.scale)) * 2)
    samples = [
        view.cell(x + radius * math.cos(2 * math.pi * k / n), y + radius * math.sin(2 * math.pi * k / n))
        for k in range(n)
    ]
    cells: list[tuple[int, int]] = []
    for a, b in zip(samples, samples[1:] + samples[:1]):
        for cell in line_cells(*a, *b)[:-1]:  # b starts the next segment
            if not cells or cells[-1] != cell:
                cells.append(cell)
    while len(cells) > 1 and cells[-1] == cells[0]:
        cells.pop()
    return cells


def dashed(cells: Sequence[tuple[int, int]], on: int = 2, off: int = 2) -> list[tuple[int, int]]:
    """Every other run of cells: `on` kept, `off` skipped, from the first cell."""
    if on < 1 or off < 0:
        raise ValueError("dashed: on >= 1 and off >= 0")
    period = on + off
    return [c for k, c in enumerate(cells) if k % period < on]


def direction_glyph(dx: float, dy: float) -> str:
    """The arrow closest to the direction (dx, dy) in world axes (y up)."""
    if dx == 0 and dy == 0:
        return "•"
    k = int(math.floor(math.atan2(dy, dx) / (math.pi / 4) + 0.5)) % 8
    return ARROWS[k]


def heading_glyph(heading: float) -> str:
    """An agent drawn as the arrow of its heading (rad, counter-clockwise from +x)."""
    return direction_glyph(math.cos(heading), math.sin(heading))


@dataclass
class Canvas:
    """A grid of cells: a character, a style (rich style string or None) and a layer."""

    width: int
    height: int
    chars: list[list[str]] = field(init=False)
    styles: list[list[str | None]] = field(init=False)
    layers: list[list[int]] = field(init=False)

    def __post_init__(self):
        self.chars = [[" "] * self.width for _ in range(self.height)]
        self.styles = [[None] * self.width for _ in range(self.height)]
        self.layers = [[0] * self.width for _ in range(self.height)]

    def put(self, col: int, row: int, ch: str, style: str | None = None, layer: int = 1) -> bool:
        """Draw one character unless outside or a higher layer holds the cell."""
        if not (0 <= col < self.width and 0 <= row < self.height) or layer < self.layers[row][col]:
            return False
        self.chars[row][col] = ch
        self.styles[row][col] = style
        self.layers[row][col] = layer
        return True

    def text(self, col: int, row: int, s: str, style: str | None = None, layer: int = L_LABEL) -> None:
        for k, ch in enumerate(s):
            self.put(col + k, row, ch, style, layer)

    def free(self, col: int, row: int, n: int, below: int) -> bool:
        """True when n cells from (col, row) are inside and under layer `below`."""
        return all(
            0 <= col + k < self.width and 0 <= row < self.height and self.layers[row][col + k] < below for k in range(n)
        )

    def lines(self) -> list[str]:
        return ["".join(r) for r in self.chars]

    def plain(self) -> str:
        return "\n".join(line.rstrip() for line in self.lines())

    def to_rich(self):
        """A rich Text of the canvas, styles included (rich is imported here only)."""
        from rich.text import Text  # lazy: rich only when a frame is drawn (a plain canvas needs none)

        out = Text(no_wrap=True, overflow="crop")
        for r in range(self.height):
            if r:
                out.append("\n")
            c = 0
            while c < self.width:  # one span per run of equal style
                style = self.styles[r][c]
                k = c
                while k < self.width and self.styles[r][k] == style:
                    k += 1
                out.append("".join(self.chars[r][c:k]), style=style or "")
                c = k
        return out


@dataclass(frozen=True)
class Body:
    """What the picture needs of one agent."""

    id: int
    role: str  # "leader" | "follower"
    x: float
    y: float
    heading: float
    alive: bool = True
    out: int | None = None
    rooted: bool = True
    orbit_radius: float | None = None  # leaders
    expected_radius: float | None = None  # followers: v_i / omega of its root

    @property
    def kind(self) -> str:
        """Style key: dead, leader, unrooted (a follower with no path to a leader) or follower."""
        if not self.alive:
            return "dead"
        if self.role == "leader":
            return "leader"
        return "follower" if self.rooted else "unrooted"


def orbit_radii(bodies: Iterable[Body]) -> list[tuple[float, bool]]:
    """The distinct circles to draw about the target: (radius m, is a leader's orbit),
    leaders' orbits first; radii within 1 mm are the same circle."""
    seen: dict[int, tuple[float, bool]] = {}
    for b in sorted(bodies, key=lambda b: b.role != "leader"):
        if not b.alive:
            continue
        r = b.orbit_radius if b.role == "leader" else b.expected_radius
        if r is None or not math.isfinite(r) or r <= 0:
            continue
        key = round(r * 1000)
        if key not in seen:
            seen[key] = (float(r), b.role == "leader")
    return list(seen.values())


def scene_view(
    target: tuple[float, float], bodies: Sequence[Body], width: int, height: int, aspect: float = 0.5
) -> View:
    """A view holding the target, every agent and every orbit circle drawn."""
    tx, ty = target
    pts = [(tx, ty)] + [(b.x, b.y) for b in bodies]
    for r, _ in orbit_radii(bodies):
        pts += [(tx - r, ty - r), (tx + r, ty + r)]
    return fit_view(pts, width, height, aspect, margin=1)


def draw_scene(
    target: tuple[float, float],
    bodies: Sequence[Body],
    width: int,
    height: int,
    aspect: float = 0.5,
    labels: bool = True,
) -> Canvas:
    """The top-down picture: dashed orbits about the target, out-neighbour edges as dotted
    lines with an arrowhead next to the out-neighbour, the target, the agents as arrows of
    their headings (x when dead) in their role's colour, and their ids beside them."""
    canvas = Canvas(width, height)
    view = scene_view(target, bodies, width, height, aspect)
    tx, ty = target
    for r, is_leader in orbit_radii(bodies):
        style = STYLES["leader_orbit" if is_leader else "orbit"]
        for c, rr in dashed(circle_cells(view, tx, ty, r)):
            canvas.put(c, rr, ORBIT_GLYPH, style, L_ORBIT)
    where = {b.id: view.cell(b.x, b.y) for b in bodies}
    by_id = {b.id: b for b in bodies}
    for b in bodies:
        if not b.alive or b.out is None or b.out not in by_id or not by_id[b.out].alive:
            continue
        (c0, r0), (c1, r1) = where[b.id], where[b.out]
        cells = line_cells(c0, r0, c1, r1)[1:-1]
        for c, rr in cells:
            canvas.put(c, rr, EDGE_GLYPH, STYLES["edge"], L_EDGE)
        if cells:
            o = by_id[b.out]
            c, rr = cells[-1]
            canvas.put(c, rr, direction_glyph(o.x - b.x, o.y - b.y), STYLES["edge"], L_HEAD)
    canvas.put(*view.cell(tx, ty), TARGET_GLYPH, STYLES["target"], L_TARGET)
    order = sorted(bodies, key=lambda b: (b.alive, b.role == "leader", -b.id))  # live leaders on top
    for b in order:
        c, rr = where[b.id]
        glyph = heading_glyph(b.heading) if b.alive else DEAD_GLYPH
        canvas.put(c, rr, glyph, STYLES[b.kind], L_AGENT)
    if labels:
        for b in order:
            c, rr = where[b.id]
            label = str(b.id)
            if canvas.free(c + 1, rr, len(label), L_AGENT):
                canvas.text(c + 1, rr, label, STYLES[b.kind], L_LABEL)
            elif canvas.free(c - len(label), rr, len(label), L_AGENT):
                canvas.text(c - len(label), rr, label, STYLES[b.kind], L_LABEL)
            else:  # no room: over whatever lies beside it, inside the grid
                start = min(max(c + 1, 0), max(width - len(label), 0))
                canvas.text(start, rr, label, STYLES[b.kind], L_LABEL)
    return canvas
