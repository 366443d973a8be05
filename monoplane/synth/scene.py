"""Random indoor scene layouts with exact planar geometry, in a z-up world frame.

A layout is a closed room (floor, ceiling, four walls) furnished with boxes (cabinets, shelves,
small boxes on tables), wall panels (pictures, boards, doors), tables (slab top on cylindrical
legs) and curved objects (spheres, domed cylinders, tori). Every planar face is one
:class:`Surface` carrying its exact world plane; curved objects are surfaces without a plane.
All geometry is packed in one triangle mesh with a per-triangle surface index, ready for
Open3D's ``RaycastingScene``.

World frame: metres, z up, floor at ``z = 0``, room spanning ``[0, Lx] x [0, Ly] x [0, Lz]``.
World planes ``n · x + d = 0`` have their unit normal on the side the surface is seen from (into
the room for the room's faces, outwards for objects), so :func:`monoplane.datamodel.plane_to_camera`
turns them directly into camera-facing planes for any camera inside the room.

The camera of view 0 is drawn first, then objects keep a free disk around it, so that extra
views (drawn afterwards from their own random stream, see :func:`extra_camera`) never change the
furniture: view 0 of a two-view scene is the single-view scene of the same seed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from monoplane.geometry.camera import look_at
from monoplane.synth.texture import Material, random_material

#: The synthetic world's up direction (z up); up in every rendered picture.
WORLD_UP = np.array([0.0, 0.0, 1.0])
#: Free radius (m, in the floor plane) kept around the first camera centre.
CAMERA_CLEARANCE = 1.3
#: Extra views stay this close (m) to the first camera, inside its free disk.
MAX_BASELINE = 0.8


@dataclass
class Surface:
    """One textured surface of the layout.

    Attributes
    ----------
    kind : str
        What it is (``"floor"``, ``"wall"``, ``"box"``, ``"panel"``, ``"sphere"``, ...).
    material : Material
        Procedural texture.
    plane : numpy.ndarray or None
        (4,) float64 world plane ``n · x + d = 0`` with ``n`` towards the visible side; ``None``
        for curved surfaces.
    origin, e1, e2 : numpy.ndarray
        Texture frame. Planar: a point of the face and two orthonormal in-plane axes, so texture
        coordinates are metres along the face. Curved: ``origin`` is the object's centre and
        ``e1[0]`` a characteristic radius (texture ``u`` = radius x azimuth, ``v`` = height).
    """

    kind: str
    material: Material
    plane: np.ndarray | None
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray

    @property
    def planar(self) -> bool:
        """True for planar faces (they get ground-truth plane ids)."""
        return self.plane is not None

    def texture_coords(self, points: np.ndarray) -> np.ndarray:
        """Texture coordinates of world points on this surface.

        Parameters
        ----------
        points : numpy.ndarray
            (N, 3) float64 world points on the surface.

        Returns
        -------
        numpy.ndarray
            (N, 2) float64 coordinates in metres.
        """
        rel = points - self.origin
        if self.planar:
            return np.stack([rel @ self.e1, rel @ self.e2], axis=1)
        azimuth = np.arctan2(rel[:, 1], rel[:, 0])
        return np.stack([self.e1[0] * azimuth, rel[:, 2]], axis=1)


@dataclass
class Layout:
    """A furnished room as one triangle mesh.

    Attributes
    ----------
    vertices : numpy.ndarray
        (V, 3) float32 world vertex positions.
    vertex_normals : numpy.ndarray
        (V, 3) float32 unit normals towards the visible side (flat for faces, analytic for curved
        objects), interpolated at hit points for shading and curved ground-truth normals.
    triangles : numpy.ndarray
        (T, 3) uint32 vertex indices.
    tri_surface : numpy.ndarray
        (T,) int32 index into ``surfaces``.
    surfaces : list of Surface
    size : numpy.ndarray
        (3,) room extent ``(Lx, Ly, Lz)`` in metres.
    light : numpy.ndarray
        (3,) world position of the point light.
    camera_center, camera_target : numpy.ndarray
        (3,) world centre of view 0 and the point it looks at.
    hfov_deg : float
        Horizontal field of view shared by all views.
    footprints : numpy.ndarray
        (F, 3) floor-standing object discs ``(x, y, radius)``, used to keep extra cameras clear.
    """

    vertices: np.ndarray
    vertex_normals: np.ndarray
    triangles: np.ndarray
    tri_surface: np.ndarray
    surfaces: list[Surface]
    size: np.ndarray
    light: np.ndarray
    camera_center: np.ndarray
    camera_target: np.ndarray
    hfov_deg: float
    footprints: np.ndarray


@dataclass
class _MeshBuilder:
    """Accumulates triangles and surfaces; planar faces are added as convex quads."""

    verts: list[np.ndarray] = field(default_factory=list)
    norms: list[np.ndarray] = field(default_factory=list)
    tris: list[np.ndarray] = field(default_factory=list)
    tri_surf: list[np.ndarray] = field(default_factory=list)
    surfaces: list[Surface] = field(default_factory=list)
    n_verts: int = 0

    def _append(self, verts: np.ndarray, norms: np.ndarray, tris: np.ndarray, surface: Surface
                ) -> None:
        self.verts.append(verts)
        self.norms.append(norms)
        self.tris.append(tris + self.n_verts)
        self.tri_surf.append(np.full(len(tris), len(self.surfaces), dtype=np.int32))
        self.surfaces.append(surface)
        self.n_verts += len(verts)

    def quad(self, center: np.ndarray, a: np.ndarray, b: np.ndarray, normal: np.ndarray,
             kind: str, material: Material) -> None:
        """Add the planar rectangle ``center + s a + t b`` (s, t in [-1, 1]) seen from ``normal``.

        ``a`` and ``b`` are orthogonal half-extent vectors; ``normal`` is the unit normal on the
        visible side.
        """
        corners = np.array([center - a - b, center + a - b, center + a + b, center - a + b])
        tris = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
        plane = np.append(normal, -normal @ center)
        e1 = a / np.linalg.norm(a)
        e2 = b / np.linalg.norm(b)
        surf = Surface(kind, material, plane, center.copy(), e1, e2)
        self._append(corners, np.tile(normal, (4, 1)), tris, surf)

    def box(self, center: np.ndarray, half: np.ndarray, yaw: float, kind: str,
            material: Material, skip_bottom: bool = True, skip: tuple[int, ...] = ()) -> None:
        """Add an axis-aligned-in-z box rotated by ``yaw`` about z, one surface per face.

        ``half`` is (hx, hy, hz) along the box's local axes; faces are indexed 0..5 as +x, -x,
        +y, -y, +z, -z and those in ``skip`` (and the bottom if ``skip_bottom``) are left out
        because they can never be seen.
        """
        c, s = np.cos(yaw), np.sin(yaw)
        axes = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        for face in range(6):
            if face in skip or (skip_bottom and face == 5):
                continue
            k, sign = face // 2, 1.0 - 2.0 * (face % 2)
            n = sign * axes[k]
            i, j = [m for m in range(3) if m != k]
            self.quad(center + half[k] * n, half[i] * axes[i], half[j] * axes[j], n, kind,
                      material)

    def grid(self, pos: np.ndarray, nrm: np.ndarray, closed_u: bool, kind: str,
             material: Material, origin: np.ndarray, radius: float) -> None:
        """Add a curved surface sampled on a (nu, nv) grid of positions and unit normals."""
        nu, nv = pos.shape[:2]
        cols = nu if closed_u else nu - 1
        i, j = np.meshgrid(np.arange(cols), np.arange(nv - 1), indexing="ij")
        i1 = (i + 1) % nu
        v00, v10, v01, v11 = i * nv + j, i1 * nv + j, i * nv + j + 1, i1 * nv + j + 1
        tris = np.concatenate([np.stack([v00, v10, v11], -1).reshape(-1, 3),
                               np.stack([v00, v11, v01], -1).reshape(-1, 3)])
        surf = Surface(kind, material, None, origin.copy(), np.array([radius, 0.0, 0.0]),
                       np.zeros(3))
        self._append(pos.reshape(-1, 3), nrm.reshape(-1, 3), tris, surf)

    def build(self, **kw: object) -> Layout:
        return Layout(
            vertices=np.concatenate(self.verts).astype(np.float32),
            vertex_normals=np.concatenate(self.norms).astype(np.float32),
            triangles=np.concatenate(self.tris).astype(np.uint32),
            tri_surface=np.concatenate(self.tri_surf),
            surfaces=self.surfaces,
            **kw,  # type: ignore[arg-type]
        )


def _sphere(b: _MeshBuilder, center: np.ndarray, r: float, mat: Material) -> None:
    az = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    el = np.linspace(-np.pi / 2, np.pi / 2, 21)
    A, E = np.meshgrid(az, el, indexing="ij")
    nrm = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1)
    b.grid(center + r * nrm, nrm, True, "sphere", mat, center, r)


def _domed_cylinder(b: _MeshBuilder, base: np.ndarray, r: float, h: float, mat: Material
                    ) -> None:
    """Vertical cylinder of radius r and wall height h standing on ``base``, closed by a dome."""
    az = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    # Wall rows then dome rows share one grid, so the normal field is continuous at the rim.
    zs = np.linspace(0.0, h, 8)
    el = np.linspace(0.0, np.pi / 2, 9)[1:]
    A, Z = np.meshgrid(az, zs, indexing="ij")
    wall_n = np.stack([np.cos(A), np.sin(A), np.zeros_like(A)], -1)
    wall_p = base + np.stack([r * np.cos(A), r * np.sin(A), Z], -1)
    A2, E2 = np.meshgrid(az, el, indexing="ij")
    dome_n = np.stack([np.cos(E2) * np.cos(A2), np.cos(E2) * np.sin(A2), np.sin(E2)], -1)
    dome_p = base + np.array([0.0, 0.0, h]) + r * dome_n
    pos = np.concatenate([wall_p, dome_p], axis=1)
    nrm = np.concatenate([wall_n, dome_n], axis=1)
    b.grid(pos, nrm, True, "cylinder", mat, base + np.array([0.0, 0.0, h / 2]), r)


def _tube(b: _MeshBuilder, base: np.ndarray, r: float, h: float, mat: Material) -> None:
    """Open vertical cylinder (table leg); its ends touch the floor and the table top."""
    az = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    A, Z = np.meshgrid(az, np.array([0.0, h]), indexing="ij")
    nrm = np.stack([np.cos(A), np.sin(A), np.zeros_like(A)], -1)
    b.grid(base + np.stack([r * np.cos(A), r * np.sin(A), Z], -1), nrm, True, "leg", mat,
           base, r)


def _torus(b: _MeshBuilder, center: np.ndarray, R: float, r: float, mat: Material) -> None:
    """Torus lying flat (axis along z), resting on ``center.z - r``."""
    u = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    v = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    U, V = np.meshgrid(u, v, indexing="ij")
    nrm = np.stack([np.cos(V) * np.cos(U), np.cos(V) * np.sin(U), np.sin(V)], -1)
    ring = np.stack([R * np.cos(U), R * np.sin(U), np.zeros_like(U)], -1)
    pos = center + ring + r * nrm
    # Close the minor circle too: append the first column of v after the last.
    pos = np.concatenate([pos, pos[:, :1]], axis=1)
    nrm = np.concatenate([nrm, nrm[:, :1]], axis=1)
    b.grid(pos, nrm, True, "torus", mat, center, R)


def _look_from_target(rng: np.random.Generator, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre near one side of the room and a target towards the opposite side."""
    lx, ly, lz = size
    for _ in range(100):
        c = np.array([rng.uniform(0.3, 0.7) * lx, rng.uniform(0.12, 0.3) * ly,
                      rng.uniform(1.3, min(1.75, lz - 0.5))])
        tgt = np.array([rng.uniform(0.15, 0.85) * lx, rng.uniform(0.55, 0.95) * ly,
                        rng.uniform(0.4, 1.1)])
        if np.linalg.norm((tgt - c)[:2]) > 2.0 and c[1] > 0.6:
            return c, tgt
    raise RuntimeError("could not place the camera")  # unreachable for the room sizes used


def _free(xy: np.ndarray, r: float, discs: list[np.ndarray], size: np.ndarray,
          margin: float | None = 0.02) -> bool:
    """True when the disc (xy, r) overlaps no disc of ``discs`` and, unless ``margin`` is None,
    stays ``margin`` inside the walls."""
    if margin is not None:
        if xy[0] - r < margin or xy[1] - r < margin:
            return False
        if xy[0] + r > size[0] - margin or xy[1] + r > size[1] - margin:
            return False
    return all(np.hypot(*(xy - d[:2])) > r + d[2] for d in discs)


def _room(b: _MeshBuilder, rng: np.random.Generator, size: np.ndarray
          ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """Add the floor, ceiling and walls of a room of ``size`` (m) to ``b``.

    Returns
    -------
    list
        Per wall: (point on the wall, inward normal, in-wall horizontal axis, wall length).
    """
    lx, ly, lz = size
    ex, ey, ez = np.eye(3)
    half = size / 2
    # Room: floor, ceiling, walls; normals point into the room. Each face overhangs its
    # neighbours by 1 cm (out of sight behind them) so no ray slips through a corner crack.
    over = half + 0.01
    b.quad(np.array([lx / 2, ly / 2, 0.0]), over[0] * ex, over[1] * ey, ez, "floor",
           random_material(rng, "floor"))
    b.quad(np.array([lx / 2, ly / 2, lz]), over[0] * ex, over[1] * ey, -ez, "ceiling",
           random_material(rng, "ceiling"))
    # Opposite walls share a material, so every vertical corner shows a texture edge.
    wall_mats = (random_material(rng, "wall"), random_material(rng, "wall"))
    walls = [  # (point on wall, inward normal, in-wall horizontal axis, wall length)
        (np.array([0.0, half[1], half[2]]), ex, ey, ly),
        (np.array([lx, half[1], half[2]]), -ex, ey, ly),
        (np.array([half[0], 0.0, half[2]]), ey, ex, lx),
        (np.array([half[0], ly, half[2]]), -ey, ex, lx),
    ]
    for k, (p, n, a, length) in enumerate(walls):
        b.quad(p, (length / 2 + 0.01) * a, over[2] * ez, n, "wall", wall_mats[k // 2])
    return walls


class _Furnisher:
    """Places the objects of one room: each placer tries to add one object of its kind and
    says whether it did, keeping every object's footprint disc free of the others and of the
    first camera."""

    def __init__(self, rng: np.random.Generator, b: _MeshBuilder, size: np.ndarray,
                 walls: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]],
                 cam: np.ndarray, target: np.ndarray, objects: int | None) -> None:
        self.rng, self.b, self.size, self.walls = rng, b, size, walls
        self.cam, self.objects = cam, objects
        self.discs: list[np.ndarray] = [np.array([cam[0], cam[1], CAMERA_CLEARANCE])]
        self.footprints: list[np.ndarray] = []
        self.wall_used: list[list[tuple[float, float]]] = [[] for _ in walls]
        self.gaze = (target - cam)[:2] / np.linalg.norm((target - cam)[:2])

    def in_view(self, xy: np.ndarray) -> bool:
        """Whether a placement counts: always for the usual furnishing; with a set number of
        objects, only within 25 degrees of view 0's gaze (every field of view is >= 55)."""
        if self.objects is None:
            return True
        ray = xy - self.cam[:2]
        return bool(ray @ self.gaze > np.cos(np.radians(25.0)) * np.linalg.norm(ray))

    def floor_spot(self, r: float) -> np.ndarray | None:
        """A uniformly drawn floor point (x, y) whose disc of radius r is free, else None."""
        lx, ly = self.size[:2]
        xy = self.rng.uniform([r, r], [lx - r, ly - r])
        return xy if _free(xy, r, self.discs, self.size) and self.in_view(xy) else None

    def occupy(self, xy: np.ndarray, r: float) -> None:
        """Reserve the disc for later placements and record it as a footprint."""
        disc = np.array([xy[0], xy[1], r])
        self.discs.append(disc)
        self.footprints.append(disc)

    def cabinet(self) -> bool:
        """A cabinet or shelf against a wall."""
        rng = self.rng
        for _try in range(30):
            k = int(rng.integers(4))
            p, n, a, length = self.walls[k]
            w, dpt, h = rng.uniform(0.5, 1.3), rng.uniform(0.3, 0.6), rng.uniform(0.45, 1.9)
            s = rng.uniform(w / 2 + 0.05, length - w / 2 - 0.05)
            center = p.copy()
            center[2] = h / 2
            center += (s - length / 2) * a + (dpt / 2 + 0.01) * n
            r = float(np.hypot(w, dpt) / 2)
            if (not _free(center[:2], r, self.discs, self.size, margin=None)
                    or not self.in_view(center[:2])):
                continue
            yaw = float(np.arctan2(a[1], a[0]))
            self.b.box(center, np.array([w / 2, dpt / 2, h / 2]), yaw, "box",
                       random_material(rng, "object"))
            self.occupy(center, r)
            self.wall_used[k].append((s - w / 2, s + w / 2))
            return True
        return False

    def _on_floor(self, width: tuple[float, float], depth: tuple[float, float],
                  height: tuple[float, float],
                  build: Callable[[float, float, float, np.ndarray], None]) -> bool:
        """Place a box-shaped floor object: draw its size (uniform in each range) and a free
        floor spot for its footprint disc, up to 30 times; on success call ``build`` with
        ``(w, depth, h, xy)`` and reserve the disc (:meth:`occupy`)."""
        rng = self.rng
        for _try in range(30):
            w, dpt, h = rng.uniform(*width), rng.uniform(*depth), rng.uniform(*height)
            r = float(np.hypot(w, dpt) / 2)
            xy = self.floor_spot(r)
            if xy is not None:
                build(w, dpt, h, xy)
                self.occupy(xy, r)
                return True
        return False

    def free_box(self) -> bool:
        """A free-standing box with random yaw."""
        return self._on_floor((0.3, 0.8), (0.3, 0.8), (0.3, 1.0), self._build_free_box)

    def _build_free_box(self, w: float, dpt: float, h: float, xy: np.ndarray) -> None:
        rng = self.rng
        self.b.box(np.array([xy[0], xy[1], h / 2]), np.array([w / 2, dpt / 2, h / 2]),
                   float(rng.uniform(0, np.pi)), "box", random_material(rng, "object"))

    def table(self) -> bool:
        """A table: slab top, tube legs, and one or two things on top."""
        return self._on_floor((0.8, 1.6), (0.6, 1.0), (0.68, 0.8), self._build_table)

    def _build_table(self, w: float, dpt: float, h: float, xy: np.ndarray) -> None:
        rng, b = self.rng, self.b
        yaw = float(rng.uniform(0, np.pi))
        th = 0.04
        b.box(np.array([xy[0], xy[1], h - th / 2]), np.array([w / 2, dpt / 2, th / 2]), yaw,
              "table", random_material(rng, "object"), skip_bottom=False)
        c, s = np.cos(yaw), np.sin(yaw)
        ax, ay = np.array([c, s]), np.array([-s, c])
        leg_mat = random_material(rng, "object")
        leg_r = rng.uniform(0.02, 0.035)
        for sx in (-1, 1):
            for sy in (-1, 1):
                lxy = xy + sx * (w / 2 - 0.07) * ax + sy * (dpt / 2 - 0.07) * ay
                _tube(b, np.array([lxy[0], lxy[1], 0.0]), leg_r, h - th, leg_mat)
        for _obj in range(int(rng.integers(1, 3))):
            oxy = xy + rng.uniform(-0.3, 0.3) * w * ax + rng.uniform(-0.25, 0.25) * dpt * ay
            kind = int(rng.integers(3))
            mat = random_material(rng, "object")
            if kind == 0:
                rad = rng.uniform(0.08, 0.15)
                _sphere(b, np.array([oxy[0], oxy[1], h + rad]), rad, mat)
            elif kind == 1:
                bw, bd, bh = rng.uniform(0.15, 0.35, size=3)
                b.box(np.array([oxy[0], oxy[1], h + bh / 2]),
                      np.array([bw / 2, bd / 2, bh / 2]), float(rng.uniform(0, np.pi)),
                      "box", mat)
            else:
                rr = rng.uniform(0.03, 0.06)
                _torus(b, np.array([oxy[0], oxy[1], h + rr]), rng.uniform(0.1, 0.18), rr,
                       mat)

    def curved(self) -> bool:
        """A sphere, domed cylinder or torus on the floor."""
        rng, b = self.rng, self.b
        for _try in range(30):
            kind = int(rng.integers(3))
            mat = random_material(rng, "object")
            if kind == 0:
                rad = rng.uniform(0.15, 0.35)
                xy = self.floor_spot(rad)
                if xy is None:
                    continue
                _sphere(b, np.array([xy[0], xy[1], rad]), rad, mat)
            elif kind == 1:
                rad = rng.uniform(0.1, 0.25)
                xy = self.floor_spot(rad)
                if xy is None:
                    continue
                _domed_cylinder(b, np.array([xy[0], xy[1], 0.0]), rad, rng.uniform(0.3, 1.0),
                                mat)
            else:
                big, small = rng.uniform(0.2, 0.35), rng.uniform(0.05, 0.1)
                rad = big + small
                xy = self.floor_spot(rad)
                if xy is None:
                    continue
                _torus(b, np.array([xy[0], xy[1], small]), big, small, mat)
            self.occupy(xy, rad)
            return True
        return False

    def panel(self) -> bool:
        """A wall panel (picture, board) or door: a thin box whose back face lies on the wall."""
        rng = self.rng
        lz = self.size[2]
        ez = np.eye(3)[2]
        for _try in range(30):
            k = int(rng.integers(4))
            p, n, a, length = self.walls[k]
            door = rng.uniform() < 0.25
            if door:
                w, h, z0 = rng.uniform(0.8, 1.0), rng.uniform(1.95, 2.1), 0.0
            else:
                w, h = rng.uniform(0.4, 1.4), rng.uniform(0.3, 1.0)
                z0 = rng.uniform(0.9, lz - h - 0.2)
            th = rng.uniform(0.02, 0.06)
            s = rng.uniform(w / 2 + 0.1, length - w / 2 - 0.1)
            lo, hi = s - w / 2, s + w / 2
            if any(lo < u1 + 0.05 and hi > u0 - 0.05 for u0, u1 in self.wall_used[k]):
                continue
            center = p.copy()
            center[2] = z0 + h / 2
            center += (s - length / 2) * a + (th / 2) * n
            if not self.in_view(center[:2]):
                continue
            yaw = float(np.arctan2(a[1], a[0]))
            # Local +y of the box is the wall normal for yaw along a; skip the face on the wall.
            back = 3 if np.allclose(np.cross(a, ez), -n) else 2
            # A door starts at the floor, so its bottom face is hidden; a picture's is not.
            self.b.box(center, np.array([w / 2, th / 2, h / 2]), yaw, "panel",
                       random_material(rng, "panel"), skip_bottom=door, skip=(back,))
            self.wall_used[k].append((lo, hi))
            return True
        return False

    def furnish(self) -> None:
        """The usual furnishing, or exactly :attr:`objects` objects of uniformly drawn kinds.

        Raises
        ------
        RuntimeError
            When that many objects cannot all be placed.
        """
        rng = self.rng
        if self.objects is None:
            # The counts are drawn kind by kind, each right before its placements.
            for place, (low, high) in ((self.cabinet, (2, 5)), (self.free_box, (0, 3)),
                                       (self.table, (1, 3)), (self.curved, (2, 5)),
                                       (self.panel, (2, 5))):
                for _ in range(int(rng.integers(low, high))):
                    place()
            return
        placers = (self.cabinet, self.free_box, self.table, self.curved, self.panel)
        placed = 0
        for _try in range(50 * max(self.objects, 1)):
            if placed == self.objects:
                break
            placed += placers[int(rng.integers(len(placers)))]()
        if placed < self.objects:
            raise RuntimeError(f"could place only {placed} of {self.objects} objects in view")


def build_layout(rng: np.random.Generator, objects: int | None = None) -> Layout:
    """Draw a random furnished room and the first camera.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of all randomness (the layout is a pure function of its state).
    objects : int, optional
        ``None``: the usual furnishing, 2-4 cabinets and shelves, 0-2 free-standing boxes,
        1-2 tables with 1-2 things on each, 2-4 curved objects and 2-4 wall panels or doors
        (about 7-16 objects, most of them in view). A number: exactly that many objects, each
        of a kind drawn uniformly from those five, placed in view 0's horizontal field of view
        (a table counts as one object with what stands on it); a scene-complexity knob for
        benchmarks. The room and the camera are the same either way, the objects are not.

    Returns
    -------
    Layout

    Raises
    ------
    RuntimeError
        When ``objects`` pieces cannot all be placed (the room is full; not reached below about
        a dozen).
    """
    size = np.array([rng.uniform(4.0, 6.5), rng.uniform(4.5, 7.0), rng.uniform(2.5, 3.1)])
    lx, ly, lz = size
    b = _MeshBuilder()
    walls = _room(b, rng, size)
    cam, target = _look_from_target(rng, size)
    furnisher = _Furnisher(rng, b, size, walls, cam, target, objects)
    furnisher.furnish()
    light = np.array([rng.uniform(0.3, 0.7) * lx, rng.uniform(0.3, 0.7) * ly, lz - 0.25])
    hfov = float(rng.uniform(55.0, 68.0))
    return b.build(size=size, light=light, camera_center=cam, camera_target=target,
                   hfov_deg=hfov, footprints=np.array(furnisher.footprints).reshape(-1, 3))


def extra_camera(layout: Layout, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A further view of the same room with a moderate baseline and rotation to view 0.

    The centre moves 0.3-0.8 m (mostly sideways) from view 0 and the camera looks at a point near
    view 0's target, with a small roll; the draw is repeated until the relative rotation is
    10-30 degrees, so the views overlap widely but are not near-duplicates.

    Returns
    -------
    R, t : numpy.ndarray
        World-to-camera pose.
    """
    c0, tgt0 = layout.camera_center, layout.camera_target
    R0, _ = look_at(c0, tgt0, WORLD_UP)
    fwd = (tgt0 - c0)[:2] / np.linalg.norm((tgt0 - c0)[:2])
    side = np.array([-fwd[1], fwd[0]])
    for _ in range(200):
        base = rng.uniform(0.3, MAX_BASELINE)
        ang = rng.uniform(-0.6, 0.6) + (0.0 if rng.uniform() < 0.5 else np.pi)
        dxy = base * (np.cos(ang) * side + np.sin(ang) * fwd)
        dz = rng.uniform(-0.15, 0.15)
        c1 = c0 + np.array([dxy[0], dxy[1], dz])
        if not _free(c1[:2], 0.3, list(layout.footprints), layout.size, margin=0.3):
            continue
        tgt1 = tgt0 + rng.uniform(-0.5, 0.5, size=3) * np.array([1.0, 1.0, 0.4])
        R1, t1 = look_at(c1, tgt1, WORLD_UP, roll_deg=rng.uniform(-5.0, 5.0))
        cos_rel = (np.trace(R1 @ R0.T) - 1) / 2
        rel = np.rad2deg(np.arccos(np.clip(cos_rel, -1, 1)))
        if 10.0 <= rel <= 30.0:
            return R1, t1
    raise RuntimeError("could not place an extra camera")
