"""Procedural worlds, deterministic by seed: ``courtyard`` (campus), ``urban`` (city blocks) and ``corridor``
(a road tunnel, degenerate along its axis).

A world is a triangle mesh in the ``map`` frame (x east, y north, z up, metres, centred on the origin),
an analytic ground height (so trajectories sit exactly on it) and the path network the trajectories
follow. ``scale`` shrinks the extent (and the number of blocks); object sizes stay physical.

- courtyard, full scale about 150 m x 200 m: a 3 x 4 grid of walkways (4 m wide) with some diagonal
  walkways, buildings (6-20 m high) around open courtyards, low walls, trees, benches and lamp posts,
  an outer ring of buildings, gentle ground slopes (a few percent).
- urban, full scale about 480 m x 710 m: a 5 x 7 street grid (10-25 m wide) with a few diagonal
  streets, blocks of buildings with very different heights (6-100 m, some with setbacks), parks,
  street lights, street trees, parked cars, slopes up to about 4 %.
- corridor, full scale about 1140 m x 30 m: one straight two-lane road tunnel (walls 6.5 m either side of the
  centre line, a flat 6 m ceiling) whose only features along the axis are the portals, a cross passage (a 5 m gap
  in alternate walls into an 8 m deep chamber) every 100-160 m, an emergency cabinet on alternate walls every
  40-70 m and a pair of jet fans under the ceiling every 90-130 m: between the passages LiDAR hardly
  constrains the position along the tunnel.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.sim import meshes
from grid_puzzle_localization.sim.layout import PathGraph, Placement, add_diagonals, grid_graph
from grid_puzzle_localization.sim.meshes import Mesh, MeshBuilder
from grid_puzzle_localization.util.iteration import zip_equal


@dataclass(frozen=True)
class Ground:
    """Smooth terrain z = tx x + ty y + amp sin(2 pi x / wave + px) sin(2 pi y / wave + py) [m]."""

    tilt_x: float
    tilt_y: float
    amp: float
    wave: float
    phase_x: float
    phase_y: float

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        k = 2 * np.pi / self.wave
        return (
            self.tilt_x * x + self.tilt_y * y + self.amp * np.sin(k * x + self.phase_x) * np.sin(k * y + self.phase_y)
        )

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = 2 * np.pi / self.wave
        ax, ay = k * x + self.phase_x, k * y + self.phase_y
        return (
            self.tilt_x + self.amp * k * np.cos(ax) * np.sin(ay),
            self.tilt_y + self.amp * k * np.sin(ax) * np.cos(ay),
        )


@dataclass(frozen=True)
class World:
    """A generated world: mesh, terrain, path network and the extent (x0, y0, x1, y1) [m]."""

    name: str
    mesh: Mesh
    ground: Ground
    graph: PathGraph
    extent: tuple[float, float, float, float]


def _ground_mesh(b: MeshBuilder, ground: Ground, extent, step: float, graph: PathGraph, path_refl: float, other: float):
    x0, y0, x1, y1 = extent
    xs = np.linspace(x0, x1, int(np.ceil((x1 - x0) / step)) + 1)
    ys = np.linspace(y0, y1, int(np.ceil((y1 - y0) / step)) + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    v, f = meshes.heightfield(xs, ys, ground.height(gx, gy))
    centroid = v[f].mean(axis=1)[:, :2]
    pts, hw = graph.samples()
    d, i = cKDTree(pts).query(centroid)
    on_path = d <= hw[i]
    for mask, refl in ((on_path, path_refl), (~on_path, other)):
        b.add((v, f[mask]), refl)


def _footprint_z(ground: Ground, rect) -> tuple[float, float]:
    """Lowest and highest terrain height under a footprint's corners and centre [m]."""
    x0, y0, x1, y1 = rect
    xs = np.array([x0, x1, x0, x1, (x0 + x1) / 2])
    ys = np.array([y0, y0, y1, y1, (y0 + y1) / 2])
    z = ground.height(xs, ys)
    return float(z.min()), float(z.max())


def _building(b: MeshBuilder, ground: Ground, rect, height: float, refl: float, setback: float = 0.0) -> None:
    zmin, zmax = _footprint_z(ground, rect)
    x0, y0, x1, y1 = rect
    b.add(meshes.box(x0, y0, x1, y1, zmin - 1.0, zmax + height), refl)
    if setback > 0 and min(x1 - x0, y1 - y0) > 2 * setback + 4:
        b.add(
            meshes.box(x0 + setback, y0 + setback, x1 - setback, y1 - setback, zmax + height, zmax + 1.6 * height), refl
        )


def _tree(b: MeshBuilder, place: Placement, ground: Ground, x: float, y: float, rng: np.random.Generator) -> None:
    """A trunk and an ellipsoid crown starting 2.5-3.5 m up; its footprint (the crown) avoids paths."""
    crown = rng.uniform(1.5, 3.2)
    if not place.try_take((x - crown, y - crown, x + crown, y + crown), clearance=0.3, gap=-crown):
        return
    z = float(ground.height(np.array(x), np.array(y)))
    trunk_h = rng.uniform(2.5, 3.5)
    b.add(meshes.prism(x, y, rng.uniform(0.12, 0.3), z - 0.3, z + trunk_h + 0.5, sides=7), 0.3)
    b.add(meshes.ellipsoid(x, y, z + trunk_h + crown * 1.1, crown, crown, crown * 1.1), 0.55)


def _pole(b: MeshBuilder, ground: Ground, x: float, y: float, height: float) -> None:
    z = float(ground.height(np.array(x), np.array(y)))
    b.add(meshes.prism(x, y, 0.08, z - 0.3, z + height, sides=6), 0.7)
    b.add(meshes.box(x - 0.25, y - 0.25, x + 0.25, y + 0.25, z + height, z + height + 0.25), 0.8)


def _along_edges(graph: PathGraph, spacing: float, offset: Callable[[float], float], rng: np.random.Generator):
    """Yields (x, y, unit direction, half-width) at ~``spacing`` intervals on both sides of every edge,
    ``offset(half_width)`` metres from the centre line, skipping the ends (crossings)."""
    for (a, c), hw in zip_equal(graph.edges, graph.half_width):
        p, q = graph.nodes[a], graph.nodes[c]
        length = float(np.linalg.norm(q - p))
        u = (q - p) / length
        n = np.array([-u[1], u[0]])
        margin = hw + 2.5
        for side in (-1.0, 1.0):
            s = margin + rng.uniform(0, spacing)
            while s < length - margin:
                yield p + u * s + side * n * offset(hw), u, hw
                s += spacing * rng.uniform(0.8, 1.2)


def _cells(n_full: int, extent: float, scale: float, least: int) -> np.ndarray:
    """Grid-line coordinates: ``n_full`` cells at full scale, at least ``least``, over ``extent`` [m] centred on 0."""
    n = max(least, round(n_full * scale))
    return np.linspace(-extent / 2, extent / 2, n + 1)


def _diagonal_cells(rng: np.random.Generator, nx: int, ny: int, count: int) -> list[tuple[int, int, bool]]:
    """``count`` distinct cells, alternating rising and falling diagonals so both headings exist."""
    order = rng.permutation(nx * ny)[:count]
    return [(int(k // ny), int(k % ny), bool(i % 2 == 0)) for i, k in enumerate(order)]


def courtyard(seed: int, scale: float) -> World:
    rng = np.random.default_rng([seed, 101])
    ext_x, ext_y = 150.0 * scale, 200.0 * scale
    band = max(12.0, min(18.0, 0.12 * min(ext_x, ext_y)))
    xs, ys = _cells(3, ext_x - 2 * band, scale, 1), _cells(4, ext_y - 2 * band, scale, 2)
    path_hw = 2.0
    graph = grid_graph(xs, ys, np.full(len(xs), path_hw), np.full(len(ys), path_hw))
    nx, ny = len(xs) - 1, len(ys) - 1
    graph = add_diagonals(graph, len(ys), _diagonal_cells(rng, nx, ny, (nx * ny) // 3), path_hw)
    extent = (-ext_x / 2, -ext_y / 2, ext_x / 2, ext_y / 2)
    ground = Ground(*rng.uniform(-0.02, 0.02, 2), 1.0, 120.0, *rng.uniform(0, 2 * np.pi, 2))
    b = MeshBuilder()
    _ground_mesh(b, ground, extent, 2.0, graph, path_refl=0.15, other=0.35)
    place = Placement(graph)

    def building(rect, height):
        if place.try_take(rect, clearance=1.5, gap=2.0):
            _building(b, ground, rect, height, rng.uniform(0.35, 0.8))

    # Outer ring: buildings beyond the outermost walkways.
    for rect in _ring_lots(extent, band - path_hw - 2.0, rng, lot=(12.0, 30.0)):
        building(rect, rng.uniform(6.0, 20.0))
    # Courtyards: buildings along cell edges, an open middle.
    for i in range(nx):
        for j in range(ny):
            cx0, cx1, cy0, cy1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
            w, h = cx1 - cx0, cy1 - cy0
            inset = path_hw + 1.6
            for _ in range(8):
                depth = max(3.0, rng.uniform(0.18, 0.28) * min(w, h))
                side = rng.integers(4)
                span = (h if side < 2 else w) - 2 * inset - 0.5  # margin keeps the range below non-empty
                length = min(rng.uniform(0.35, 0.75) * (h if side < 2 else w), span)
                if length < 4.0 or depth < 3.0:
                    continue
                if side < 2:  # along a y-edge (left/right)
                    y0 = rng.uniform(cy0 + inset, cy1 - inset - length)
                    x0 = cx0 + inset if side == 0 else cx1 - inset - depth
                    rect = (x0, y0, x0 + depth, y0 + length)
                else:
                    x0 = rng.uniform(cx0 + inset, cx1 - inset - length)
                    y0 = cy0 + inset if side == 2 else cy1 - inset - depth
                    rect = (x0, y0, x0 + length, y0 + depth)
                building(rect, rng.uniform(6.0, 20.0))
            for _ in range(rng.integers(2, 5)):  # low walls
                length, thick = rng.uniform(4.0, 12.0), 0.3
                x, y = rng.uniform(cx0, cx1), rng.uniform(cy0, cy1)
                rect = (x, y, x + length, y + thick) if rng.random() < 0.5 else (x, y, x + thick, y + length)
                if place.try_take(rect, clearance=0.8, gap=1.0):
                    zmin, zmax = _footprint_z(ground, rect)
                    b.add(meshes.box(*rect[:2], *rect[2:], zmin - 0.3, zmax + rng.uniform(0.8, 2.5)), 0.5)
            for _ in range(int(w * h / 50)):  # trees in the courtyard
                x, y = rng.uniform(cx0, cx1), rng.uniform(cy0, cy1)
                _tree(b, place, ground, x, y, rng)
    for (x, y), _, _ in _along_edges(graph, 9.0, lambda hw: hw + 0.6, rng):
        _pole(b, ground, x, y, rng.uniform(3.5, 5.0))
    for (x, y), u, _ in _along_edges(graph, 15.0, lambda hw: hw + 1.2, rng):
        rect = (x - 0.9, y - 0.9, x + 0.9, y + 0.9)
        if place.try_take(rect, clearance=0.3, gap=0.5):
            z = float(ground.height(np.array(x), np.array(y)))
            yaw = float(np.arctan2(u[1], u[0]))
            b.add(meshes.box(x - 0.9, y - 0.25, x + 0.9, y + 0.25, z - 0.1, z + 0.45, yaw), 0.4)
    return World("courtyard", b.build(), ground, graph, extent)


def _ring_lots(extent, band: float, rng: np.random.Generator, lot: tuple[float, float]):
    """Lots along the inside of the world border, ``band`` deep."""
    x0, y0, x1, y1 = extent
    if band < 3.0:
        return
    for horizontal, fixed0, fixed1, start, stop in (
        (True, y0, y0 + band, x0, x1),
        (True, y1 - band, y1, x0, x1),
        (False, x0, x0 + band, y0 + band + 2.5, y1 - band - 2.5),
        (False, x1 - band, x1, y0 + band + 2.5, y1 - band - 2.5),
    ):
        s = start
        while s < stop - 4.0:
            length = min(rng.uniform(*lot), stop - s)
            a, c = s + 1.0, s + length - 1.0
            yield (a, fixed0, c, fixed1) if horizontal else (fixed0, a, fixed1, c)
            s += length


def urban(seed: int, scale: float) -> World:
    rng = np.random.default_rng([seed, 202])
    ext_x, ext_y = 480.0 * scale, 710.0 * scale
    band = 30.0
    xs, ys = _cells(5, ext_x - 2 * band, scale, 1), _cells(7, ext_y - 2 * band, scale, 2)
    widths = np.array([10.0, 12.0, 15.0, 20.0, 25.0])
    hx, hy = rng.choice(widths, len(xs)) / 2, rng.choice(widths, len(ys)) / 2
    graph = grid_graph(xs, ys, hx, hy)
    nx, ny = len(xs) - 1, len(ys) - 1
    graph = add_diagonals(graph, len(ys), _diagonal_cells(rng, nx, ny, (nx * ny) // 8), 6.0)
    extent = (-ext_x / 2, -ext_y / 2, ext_x / 2, ext_y / 2)
    ground = Ground(*rng.uniform(-0.03, 0.03, 2), 3.0, 300.0, *rng.uniform(0, 2 * np.pi, 2))
    b = MeshBuilder()
    _ground_mesh(b, ground, extent, 4.0, graph, path_refl=0.1, other=0.25)
    place = Placement(graph)

    def height() -> float:
        return float(np.clip(rng.lognormal(np.log(16.0), 0.7), 6.0, 100.0))

    def block(rect, lot_range):
        for lx0, ly0, lx1, ly1 in _split(rect, lot_range, rng):
            lot = (lx0 + 0.8, ly0 + 0.8, lx1 - 0.8, ly1 - 0.8)
            if place.try_take(lot, clearance=3.0, gap=0.5):
                setback = rng.uniform(3.0, 6.0) if rng.random() < 0.3 else 0.0
                _building(b, ground, lot, height(), rng.uniform(0.3, 0.85), setback)

    for rect in _ring_lots(extent, band - hx.max() - 3.5, rng, lot=(15.0, 40.0)):
        if place.try_take(rect, clearance=3.0, gap=0.5):
            _building(b, ground, rect, height(), rng.uniform(0.3, 0.85))
    for i in range(nx):
        for j in range(ny):
            rect = (xs[i] + hx[i] + 3, ys[j] + hy[j] + 3, xs[i + 1] - hx[i + 1] - 3, ys[j + 1] - hy[j + 1] - 3)
            if rect[2] - rect[0] < 8 or rect[3] - rect[1] < 8:
                continue
            if rng.random() < 0.15:  # a park
                for _ in range(int((rect[2] - rect[0]) * (rect[3] - rect[1]) / 150)):
                    x, y = rng.uniform(rect[0], rect[2]), rng.uniform(rect[1], rect[3])
                    _tree(b, place, ground, x, y, rng)
            else:
                block(rect, (15.0, 40.0))
    for (x, y), _, _ in _along_edges(graph, 28.0, lambda hw: hw + 1.0, rng):
        _pole(b, ground, x, y, rng.uniform(7.0, 9.0))
    for (x, y), _, _ in _along_edges(graph, 16.0, lambda hw: hw + 2.0, rng):
        if rng.random() < 0.6:
            _tree(b, place, ground, x, y, rng)
    for (x, y), u, hw in _along_edges(graph, 7.0, lambda hw: hw - 1.2, rng):
        if hw >= 7.0 and rng.random() < 0.5:
            car(b, ground, x, y, float(np.arctan2(u[1], u[0])), rng.uniform(0.15, 0.9))
    return World("urban", b.build(), ground, graph, extent)


def car(b: MeshBuilder, ground: Ground, x: float, y: float, yaw: float, refl: float) -> None:
    """A car (body and cabin boxes, 4.4 m x 1.8 m x 1.5 m) on the terrain at (x, y) heading ``yaw`` [rad]."""
    z = float(ground.height(np.array(x), np.array(y)))
    b.add(meshes.box(x - 2.2, y - 0.9, x + 2.2, y + 0.9, z + 0.25, z + 1.0, yaw), refl)
    c, s = np.cos(yaw), np.sin(yaw)
    cx, cy = x - 0.3 * c, y - 0.3 * s
    b.add(meshes.box(cx - 1.2, cy - 0.8, cx + 1.2, cy + 0.8, z + 1.0, z + 1.5, yaw), refl)


def _split(rect, lot_range: tuple[float, float], rng: np.random.Generator):
    """Guillotine split of a block into lots whose sides are within ``lot_range`` [m] where possible."""
    x0, y0, x1, y1 = rect
    w, h = x1 - x0, y1 - y0
    if max(w, h) <= lot_range[1]:
        yield rect
        return
    if w >= h:
        cut = x0 + rng.uniform(lot_range[0], min(lot_range[1], w - lot_range[0]))
        yield from _split((x0, y0, cut, y1), lot_range, rng)
        yield from _split((cut, y0, x1, y1), lot_range, rng)
    else:
        cut = y0 + rng.uniform(lot_range[0], min(lot_range[1], h - lot_range[0]))
        yield from _split((x0, y0, x1, cut), lot_range, rng)
        yield from _split((x0, cut, x1, y1), lot_range, rng)


CORRIDOR_LENGTH = 1100.0  # [m] of road between the portals' approaches at full scale


def corridor(seed: int, scale: float) -> World:
    rng = np.random.default_rng([seed, 303])
    length = CORRIDOR_LENGTH * scale
    half_road, wall_y, ceiling = 5.0, 6.5, 6.0
    ext_x, ext_y = length + 40.0, 30.0
    graph = PathGraph(
        np.array([[-length / 2, 0.0], [length / 2, 0.0]]), np.array([[0, 1]], dtype=np.int64), np.array([half_road])
    )
    extent = (-ext_x / 2, -ext_y / 2, ext_x / 2, ext_y / 2)
    ground = Ground(*rng.uniform(-0.005, 0.005, 2), 0.0, 300.0, 0.0, 0.0)  # a straight, nearly level road
    b = MeshBuilder()
    _ground_mesh(b, ground, extent, 2.0, graph, path_refl=0.1, other=0.25)
    x0, x1 = -ext_x / 2 + 5.0, ext_x / 2 - 5.0  # the tunnel, between its portals
    corners = ground.height(np.array([x0, x1, x0, x1]), np.array([-wall_y, -wall_y, wall_y, wall_y]))
    zlo, ztop = float(corners.min()) - 0.5, float(corners.max()) + ceiling + 0.5
    # Cross passages: a 5 m gap in alternate walls every 100-160 m, into an 8 m deep chamber.
    passages = {-1.0: [], 1.0: []}
    x, side = x0 + rng.uniform(30.0, 80.0), 1.0
    while x < x1 - 20.0:
        passages[side].append(x)
        x, side = x + rng.uniform(100.0, 160.0), -side
    for side, gaps in passages.items():
        start = x0
        for xp in gaps:
            b.add(meshes.box(start, side * wall_y, xp - 2.5, side * (wall_y + 0.5), zlo, ztop), 0.4)
            far = side * (wall_y + 8.0)
            b.add(meshes.box(xp - 3.0, far, xp + 3.0, far + side * 0.5, zlo, ztop), 0.4)
            for xs in (xp - 3.0, xp + 2.5):
                b.add(meshes.box(xs, side * wall_y, xs + 0.5, far, zlo, ztop), 0.4)
            start = xp + 2.5
        b.add(meshes.box(start, side * wall_y, x1, side * (wall_y + 0.5), zlo, ztop), 0.4)
    # The ceiling is the (planar) road surface raised by `ceiling`, over the chambers too: no steps along x.
    xs, ys = np.array([x0, x1]), np.array([-wall_y - 8.5, wall_y + 8.5])
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    b.add(meshes.heightfield(xs, ys, ground.height(gx, gy) + ceiling), 0.3)
    x, side = x0 + rng.uniform(20.0, 60.0), 1.0
    while x < x1 - 10.0:  # emergency cabinets, 2 m long, standing 0.5 m out of alternate walls
        y = side * (wall_y - 0.25)
        z = float(ground.height(np.array(x), np.array(y)))
        b.add(meshes.box(x - 1.0, y - 0.25, x + 1.0, y + 0.25, z - 0.1, z + 2.5), 0.7)
        x, side = x + rng.uniform(40.0, 70.0), -side
    x = x0 + rng.uniform(50.0, 100.0)
    while x < x1 - 10.0:  # jet fans: a pair of 1 m x 4 m cylinders under the ceiling
        z = float(ground.height(np.array(x), np.array(0.0))) + ceiling
        for y in (-2.5, 2.5):
            v, f = meshes.prism(0.0, 0.0, 0.5, -2.0, 2.0, sides=8)
            v = v[:, [2, 0, 1]] + np.array([x, y, z - 0.8])  # the prism's axis turned along x
            b.add((v, f), 0.5)
        x += rng.uniform(90.0, 130.0)
    return World("corridor", b.build(), ground, graph, extent)


WORLDS: dict[str, Callable[[int, float], World]] = {"courtyard": courtyard, "urban": urban, "corridor": corridor}


def check_world(name: str) -> str:
    if name not in WORLDS:
        raise UserError(f"unknown scenario {name!r}: choose one of {', '.join(WORLDS)}")
    return name


def make_world(name: str, seed: int, scale: float) -> World:
    """Builds world ``name`` (one of WORLDS) deterministically from ``seed`` at ``scale`` (0.2 <= scale <= 1)."""
    check_world(name)
    if not (0.2 <= scale <= 1.0):
        raise UserError(f"--scale must be between 0.2 and 1 (got {scale}); for example --scale 0.25")
    return WORLDS[name](seed, scale)
