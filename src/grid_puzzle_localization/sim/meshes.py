"""Triangle-mesh primitives for procedural worlds: boxes, prisms, ellipsoids and height fields.

Every primitive returns ``(vertices (n, 3) float64, faces (m, 3) int64)``; a :class:`MeshBuilder`
collects them with a per-triangle reflectivity in [0, 1] (used for the simulated intensity). Winding
order is irrelevant: rays hit both sides and intensity uses the absolute incidence cosine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Box corners (unit cube) and its 12 triangles.
_CUBE = np.array([[x, y, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)])
_CUBE_FACES = np.array(
    [
        [0, 2, 1], [1, 2, 3],  # bottom
        [4, 5, 6], [5, 7, 6],  # top
        [0, 1, 4], [1, 5, 4],  # y = 0
        [2, 6, 3], [3, 6, 7],  # y = 1
        [0, 4, 2], [2, 4, 6],  # x = 0
        [1, 3, 5], [3, 7, 5],  # x = 1
    ]
)  # fmt: skip


@dataclass(frozen=True)
class Mesh:
    """A static world: float32 vertices [m], int32 faces and per-face reflectivity in [0, 1]."""

    vertices: np.ndarray
    faces: np.ndarray
    reflectivity: np.ndarray

    @property
    def triangles(self) -> np.ndarray:
        """(m, 3, 3) float32 corner coordinates, the layout the ray caster consumes."""
        return self.vertices[self.faces]

    def face_normals(self) -> np.ndarray:
        """(m, 3) float32 unit normals (sign arbitrary)."""
        tri = self.triangles.astype(np.float64)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return (n / np.maximum(norm, 1e-12)).astype(np.float32)


class MeshBuilder:
    """Collects primitives into one :class:`Mesh`."""

    def __init__(self) -> None:
        self._vertices: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._reflectivity: list[np.ndarray] = []
        self._count = 0

    def add(self, part: tuple[np.ndarray, np.ndarray], reflectivity: float) -> None:
        vertices, faces = part
        self._vertices.append(np.asarray(vertices, dtype=np.float64))
        self._faces.append(np.asarray(faces, dtype=np.int64) + self._count)
        self._reflectivity.append(np.full(len(faces), reflectivity, dtype=np.float32))
        self._count += len(vertices)

    def build(self) -> Mesh:
        return Mesh(
            vertices=np.concatenate(self._vertices).astype(np.float32),
            faces=np.concatenate(self._faces).astype(np.int32),
            reflectivity=np.concatenate(self._reflectivity),
        )


def box(
    x0: float, y0: float, x1: float, y1: float, z0: float, z1: float, yaw: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Box spanning [x0, x1] x [y0, y1] x [z0, z1], optionally rotated by ``yaw`` [rad] about its centre."""
    v = _CUBE * np.array([x1 - x0, y1 - y0, z1 - z0]) + np.array([x0, y0, z0])
    if yaw:
        c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        cos, sin = np.cos(yaw), np.sin(yaw)
        d = v[:, :2] - c
        v[:, :2] = c + np.stack([cos * d[:, 0] - sin * d[:, 1], sin * d[:, 0] + cos * d[:, 1]], axis=1)
    return v, _CUBE_FACES.copy()


def prism(cx: float, cy: float, radius: float, z0: float, z1: float, sides: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Vertical regular prism (a pole or trunk) with closed top and bottom."""
    a = np.arange(sides) * (2 * np.pi / sides)
    ring = np.stack([cx + radius * np.cos(a), cy + radius * np.sin(a)], axis=1)
    v = np.concatenate([np.column_stack([ring, np.full(sides, z0)]), np.column_stack([ring, np.full(sides, z1)])])
    i = np.arange(sides)
    j = (i + 1) % sides
    sides_f = np.concatenate([np.stack([i, j, i + sides], 1), np.stack([j, j + sides, i + sides], 1)])
    caps = np.concatenate(
        [
            np.stack([np.zeros(sides - 2, int), i[1:-1], i[2:]], 1),
            sides + np.stack([np.zeros(sides - 2, int), i[2:], i[1:-1]], 1),
        ]
    )
    return v, np.concatenate([sides_f, caps])


def ellipsoid(
    cx: float, cy: float, cz: float, rx: float, ry: float, rz: float, n_lat: int = 6, n_lon: int = 10
) -> tuple[np.ndarray, np.ndarray]:
    """Closed latitude-longitude ellipsoid (a tree crown or a bush)."""
    lat = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 1)[1:-1]
    lon = np.arange(n_lon) * (2 * np.pi / n_lon)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    body = np.stack(
        [cx + rx * np.cos(la) * np.cos(lo), cy + ry * np.cos(la) * np.sin(lo), cz + rz * np.sin(la)], axis=-1
    ).reshape(-1, 3)
    v = np.concatenate([body, [[cx, cy, cz - rz], [cx, cy, cz + rz]]])
    south, north = len(body), len(body) + 1
    faces = []
    j = np.arange(n_lon)
    jn = (j + 1) % n_lon
    for r in range(n_lat - 2):
        a, b = r * n_lon + j, r * n_lon + jn
        c, d = a + n_lon, b + n_lon
        faces += [np.stack([a, b, c], 1), np.stack([b, d, c], 1)]
    top = (n_lat - 2) * n_lon
    faces += [np.stack([np.full(n_lon, south), jn, j], 1), np.stack([np.full(n_lon, north), top + j, top + jn], 1)]
    return v, np.concatenate(faces)


def heightfield(xs: np.ndarray, ys: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ground mesh over the grid ``xs`` x ``ys`` with heights ``z[i, j]`` at ``(xs[i], ys[j])``."""
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([gx, gy, z], axis=-1).reshape(-1, 3)
    nx, ny = len(xs), len(ys)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    a = (i * ny + j).ravel()
    b, c, d = a + ny, a + 1, a + ny + 1
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([b, d, c], 1)])
