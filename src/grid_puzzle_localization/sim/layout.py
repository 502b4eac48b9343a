"""Path networks and collision-free placement of objects beside them (used by the world generators).

A :class:`PathGraph` is the network the trajectories follow: nodes in the map plane [m] and straight
edges, each with a free half-width [m] that no object may enter. :class:`Placement` answers whether an
axis-aligned footprint is clear of every path corridor and of the footprints already taken.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from grid_puzzle_localization.util.iteration import zip_equal

_SAMPLE_STEP = 0.5  # [m] spacing of the corridor samples used for clearance tests


@dataclass(frozen=True)
class PathGraph:
    """Undirected path network: ``nodes`` (n, 2) [m], ``edges`` (m, 2) node indices, ``half_width`` (m,) [m]."""

    nodes: np.ndarray
    edges: np.ndarray
    half_width: np.ndarray

    def neighbours(self, node: int) -> list[tuple[int, int]]:
        """(edge index, other node) pairs for every edge at ``node``, in edge order."""
        out = []
        for e, (a, b) in enumerate(self.edges):
            if a == node:
                out.append((e, int(b)))
            elif b == node:
                out.append((e, int(a)))
        return out

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """Points every ~0.5 m along all edges (k, 2) and the half-width of their edge (k,)."""
        pts, hw = [], []
        for (a, b), w in zip_equal(self.edges, self.half_width):
            p, q = self.nodes[a], self.nodes[b]
            n = max(2, int(np.ceil(np.linalg.norm(q - p) / _SAMPLE_STEP)) + 1)
            f = np.linspace(0.0, 1.0, n)[:, None]
            pts.append(p + f * (q - p))
            hw.append(np.full(n, w))
        return np.concatenate(pts), np.concatenate(hw)


def grid_graph(xs: np.ndarray, ys: np.ndarray, half_x: np.ndarray, half_y: np.ndarray) -> PathGraph:
    """Street grid through the lines x = xs[i] (half-width half_x[i]) and y = ys[j] (half_y[j])."""
    nx, ny = len(xs), len(ys)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    nodes = np.stack([gx.ravel(), gy.ravel()], axis=1)
    edges, hw = [], []
    for i in range(nx):
        for j in range(ny):
            k = i * ny + j
            if i + 1 < nx:  # along x: a street of constant y
                edges.append((k, k + ny))
                hw.append(half_y[j])
            if j + 1 < ny:
                edges.append((k, k + 1))
                hw.append(half_x[i])
    return PathGraph(nodes, np.array(edges, dtype=np.int64), np.array(hw, dtype=np.float64))


def add_diagonals(graph: PathGraph, ny: int, cells: list[tuple[int, int, bool]], half_width: float) -> PathGraph:
    """Adds a diagonal edge across each grid cell (i, j); ``rising`` picks the (i,j)->(i+1,j+1) diagonal."""
    edges, hw = [graph.edges], [graph.half_width]
    for i, j, rising in cells:
        a, b = (i * ny + j, (i + 1) * ny + j + 1) if rising else (i * ny + j + 1, (i + 1) * ny + j)
        edges.append(np.array([[a, b]]))
        hw.append(np.array([half_width]))
    return PathGraph(graph.nodes, np.concatenate(edges), np.concatenate(hw))


class Placement:
    """Free-space bookkeeping: footprints are axis-aligned rectangles (x0, y0, x1, y1) [m]."""

    def __init__(self, graph: PathGraph) -> None:
        self._pts, self._hw = graph.samples()
        self._tree = cKDTree(self._pts)
        self._max_hw = float(self._hw.max())
        self._rects: list[tuple[float, float, float, float]] = []

    def clear_of_paths(self, rect: tuple[float, float, float, float], clearance: float) -> bool:
        """True when every corridor sample is at least its half-width + ``clearance`` from ``rect``."""
        x0, y0, x1, y1 = rect
        c = ((x0 + x1) / 2, (y0 + y1) / 2)
        reach = np.hypot(x1 - x0, y1 - y0) / 2 + self._max_hw + clearance + _SAMPLE_STEP
        idx = self._tree.query_ball_point(c, reach)
        if not idx:
            return True
        p = self._pts[idx]
        dx = np.maximum(np.maximum(x0 - p[:, 0], p[:, 0] - x1), 0.0)
        dy = np.maximum(np.maximum(y0 - p[:, 1], p[:, 1] - y1), 0.0)
        return bool(np.all(np.hypot(dx, dy) >= self._hw[idx] + clearance))

    def clear_of_objects(self, rect: tuple[float, float, float, float], gap: float) -> bool:
        if not self._rects:
            return True
        r = np.asarray(self._rects)
        x0, y0, x1, y1 = rect
        overlap = (r[:, 0] < x1 + gap) & (r[:, 2] > x0 - gap) & (r[:, 1] < y1 + gap) & (r[:, 3] > y0 - gap)
        return not bool(overlap.any())

    def try_take(self, rect: tuple[float, float, float, float], clearance: float, gap: float) -> bool:
        """Reserves ``rect`` when it is clear of paths and objects; returns whether it did."""
        if self.clear_of_paths(rect, clearance) and self.clear_of_objects(rect, gap):
            self._rects.append(rect)
            return True
        return False
