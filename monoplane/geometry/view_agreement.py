"""Dense agreement of two views under a relative pose: what every registration hypothesis is
checked against.

Each view is sampled on a grid (:func:`view_geometry`); a pose hypothesis
``s·X_v = R·X_r + t`` (:class:`Hypothesis`; a point ``X_r`` of the reference camera in the
reference depth's units, seen by the other view at ``X_v`` in that view's own depth units) is
scored by moving each view's points into the other view (:func:`agreement`): they must land on
its depth (relative depth error and normal angle), and points landing in front of the surface
the other view sees are free-space violations. :mod:`monoplane.geometry.view_registration`
gives the whole method.

Frames: OpenCV camera axes (x right, y down, z forward); pixel centres at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monoplane.datamodel import pixel_rays


@dataclass
class ViewGeometry:
    """What registration uses of one view, on a subsampled pixel grid.

    Attributes
    ----------
    K : numpy.ndarray
        (3, 3) intrinsics at the view's native resolution.
    depth : numpy.ndarray
        (H, W) float32 z-depth in the view's own units (0 = invalid).
    normals : numpy.ndarray
        (H, W, 3) float32 unit normals, camera frame, facing the camera.
    points, point_normals : numpy.ndarray
        (M, 3) grid points (camera frame, the view's units) with valid depth, and their normals.
    colors : numpy.ndarray
        (M, 3) float32 colour of those points, each channel divided by the image's mean (so
        that a change of exposure or white balance between views cancels).
    image : numpy.ndarray
        (H, W, 3) float32 the whole image, normalised the same way.
    planes : numpy.ndarray
        (P, 4) planes ``n·X + d = 0`` in the camera frame and the view's units.
    plane_areas : numpy.ndarray
        (P,) pixel count of each plane.
    metric : bool
        Whether the depth is metric (then two metric views share their scale).
    """

    K: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    points: np.ndarray
    point_normals: np.ndarray
    colors: np.ndarray
    image: np.ndarray
    planes: np.ndarray
    plane_areas: np.ndarray
    metric: bool
    _index: object = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.depth.shape  # type: ignore[return-value]


def view_geometry(K: np.ndarray, depth: np.ndarray, normals: np.ndarray, rgb: np.ndarray | None,
                  planes: np.ndarray, plane_areas: np.ndarray, metric: bool,
                  grid: int = 96) -> ViewGeometry:
    """Sample a view for registration: every ``W // grid``-th pixel of valid depth.

    Parameters
    ----------
    K : numpy.ndarray
        (3, 3) intrinsics.
    depth : numpy.ndarray
        (H, W) z-depth in the view's units (0 or non-finite = invalid).
    normals : numpy.ndarray
        (H, W, 3) unit normals in the camera frame.
    rgb : numpy.ndarray or None
        (H, W, 3) uint8 image.
    planes, plane_areas : numpy.ndarray
        (P, 4) camera-frame planes and (P,) their pixel counts.
    metric : bool
        Whether the depth is metric.
    grid : int
        Samples across the image width.
    """
    h, w = depth.shape
    step = max(1, w // grid)
    d = np.nan_to_num(np.asarray(depth, np.float32)[::step, ::step])
    ok = d > 0
    rays = pixel_rays(K, h, w)[::step, ::step]
    pts = (rays[ok] * d[ok, None]).astype(np.float64)
    nrm = np.asarray(normals, np.float64)[::step, ::step][ok]
    if rgb is None:
        image = np.ones((h, w, 3), np.float32)
    else:
        image = np.asarray(rgb, np.float32)
        image = image / np.maximum(image.reshape(-1, 3).mean(axis=0), 1.0)
    col = image[::step, ::step][ok]
    return ViewGeometry(K=np.asarray(K, np.float64), depth=np.nan_to_num(depth).astype(np.float32),
                        normals=np.asarray(normals, np.float32), points=pts,
                        point_normals=nrm, colors=col, image=image,
                        planes=np.asarray(planes, np.float64).reshape(-1, 4),
                        plane_areas=np.asarray(plane_areas, np.float64).reshape(-1),
                        metric=metric)


@dataclass(frozen=True)
class Hypothesis:
    """A relative pose ``s·X_v = R·X_r + t`` and where it came from.

    Attributes
    ----------
    R : numpy.ndarray
        (3, 3) rotation from the reference camera to the other view's camera.
    t : numpy.ndarray
        (3,) translation, in the reference view's units.
    s : float
        Factor bringing the other view's depth into the reference view's units.
    source : str
        The generator: ``"features"``, ``"planes+features"``, ``"planes"``, ``"fpfh"``.
    support : int
        Its generator's own inlier count (feature matches or planes).
    """

    R: np.ndarray
    t: np.ndarray
    s: float
    source: str
    support: int = 0


@dataclass(frozen=True)
class Agreement:
    """Dense agreement of a hypothesis, both directions summed.

    Attributes
    ----------
    visible : int
        Grid points that land inside the other image, in front of it, on valid depth.
    agree : int
        Of those, points within the depth tolerance and normal angle of the other view's
        surface.
    violate : int
        Points landing clearly in front of the surface the other view sees (free space).
    colour : float
        Normalised cross-correlation of the grey levels of the agreeing points in both views
        (1: the images agree where the geometry does; near 0: another place of the same shape).
    total : int
        Grid points of both views.
    """

    visible: int
    agree: int
    violate: int
    colour: float
    total: int

    @property
    def overlap(self) -> float:
        """Share of both views' points that agree: the verified overlap."""
        return self.agree / max(self.total, 1)

    @property
    def violation(self) -> float:
        """Violations per agreeing point."""
        return self.violate / max(self.agree, 1)

    @property
    def score(self) -> float:
        """Ranking score, per point: the agreeing points weighted by how well the images agree
        on them, minus twice the violations. The colour term is what tells a room from its
        mirror or rotated twin, which fit the same walls."""
        return (self.agree * max(self.colour, 0.0) - 2.0 * self.violate) / max(self.total, 1)


def _one_way(src: ViewGeometry, dst: ViewGeometry, R: np.ndarray, t: np.ndarray,
             scale_dst: float, tol: float, cos_normal: float
             ) -> tuple[int, int, int, np.ndarray]:
    """Move ``src``'s points (in units where ``dst``'s depth is multiplied by ``scale_dst``)
    into ``dst`` and count visible, agreeing and violating points; also the sums of the grey
    levels of the agreeing points in both views (Σx, Σy, Σx², Σy², Σxy)."""
    q = src.points @ R.T + t
    z = q[:, 2]
    front = z > 1e-9
    q, z = q[front], z[front]
    u = dst.K[0, 0] * q[:, 0] / z + dst.K[0, 2]
    v = dst.K[1, 1] * q[:, 1] / z + dst.K[1, 2]
    h, w = dst.shape
    ui, vi = np.rint(u).astype(np.int64), np.rint(v).astype(np.int64)
    inside = (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
    ui, vi, z = ui[inside], vi[inside], z[inside]
    z_obs = dst.depth[vi, ui].astype(np.float64) * scale_dst
    valid = z_obs > 0
    z, z_obs = z[valid], z_obs[valid]
    rel = (z - z_obs) / z_obs
    n_src = (src.point_normals[front][inside][valid]) @ R.T
    n_dst = dst.normals[vi[valid], ui[valid]]
    close = np.abs(rel) < tol
    agree = close & (np.einsum("ij,ij->i", n_src, n_dst) > cos_normal)
    violate = rel < -3.0 * tol
    g_src = src.colors[front][inside][valid][agree].mean(axis=1).astype(np.float64)
    g_dst = dst.image[vi[valid][agree], ui[valid][agree]].mean(axis=1).astype(np.float64)
    sums = np.array([g_src.sum(), g_dst.sum(), (g_src * g_src).sum(), (g_dst * g_dst).sum(),
                     (g_src * g_dst).sum()])
    return int(valid.sum()), int(agree.sum()), int(violate.sum()), sums


def agreement(ref: ViewGeometry, other: ViewGeometry, hyp: Hypothesis, tol: float = 0.05,
              normal_deg: float = 30.0) -> Agreement:
    """Dense agreement of two views under ``hyp`` (module docstring).

    Parameters
    ----------
    ref, other : ViewGeometry
        The reference view and the view being placed.
    hyp : Hypothesis
        ``s·X_other = R·X_ref + t``.
    tol : float
        Relative depth tolerance (a point agrees when ``|z − z_obs| < tol·z_obs``).
    normal_deg : float
        Largest normal angle of an agreeing point.
    """
    cos_n = float(np.cos(np.radians(normal_deg)))
    a = _one_way(ref, other, hyp.R, hyp.t, hyp.s, tol, cos_n)
    # other -> ref: X_ref = R^T (s X_other - t)
    b = _one_way(other, ref, hyp.R.T, -hyp.R.T @ hyp.t / hyp.s, 1.0 / hyp.s, tol, cos_n)
    n = a[1] + b[1]
    sx, sy, sxx, syy, sxy = a[3] + b[3]
    var_x, var_y = sxx - sx * sx / max(n, 1), syy - sy * sy / max(n, 1)
    ncc = (sxy - sx * sy / max(n, 1)) / np.sqrt(max(var_x * var_y, 1e-300)) if n > 2 else 0.0
    return Agreement(visible=a[0] + b[0], agree=n, violate=a[2] + b[2], colour=float(ncc),
                     total=len(ref.points) + len(other.points))
