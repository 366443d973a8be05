"""Joint refinement of camera poses, per-view depth scales and global planes (plane-aware BA).

The unknowns are, for every view but the first (which fixes the gauge: its pose and its depth
scale), a pose update and a depth scale; every global plane; every sparse SfM point. The
residuals, each divided by its expected noise so that they are unitless and comparable, are

* **reprojection**: ``(π(K_v (R_v X_p + t_v)) − u_vp) / σ_px`` for every SfM observation
  (pixels);
* **SfM point on plane**: ``(n_g · X_p + d_g) / (σ_point · z_p)`` for every SfM point whose
  keypoints fall inside the mask of a view plane linked to global plane ``g`` (``z_p`` its
  depth in the observing views). These triangulated points are the multi-view evidence on
  the planes; without them a plane only averages its views' monocular depths, and the
  refinement cannot make it more accurate than the fusion;
* **point-to-plane**: ``(n_g · R_vᵀ (s_v x_vi − t_v) + d_g) / (σ_rel · z_vi)`` for a
  subsample of each view's plane pixels, where ``x_vi`` is the pixel lifted with the view's
  (scale-aligned) depth ``z_vi`` in camera ``v``, ``s_v`` the view's depth scale and ``g`` the
  global plane its local plane is linked to. Dividing by the depth makes the term a relative
  depth error, as monocular depth errors grow with depth;
* **normals**: ``(R_vᵀ m_vl − n_g) / σ_normal`` for every view plane ``l`` (camera-frame unit
  normal ``m_vl``) linked to a refined global plane;
* **pose prior**: each view's rotation change over ``prior_rot_deg`` and translation change
  over ``prior_t``.

These are the :data:`TERMS` whose robust costs the before/after summaries break down.

It is solved with :func:`scipy.optimize.least_squares` (trust-region reflective, robust
``soft_l1`` loss) and the problem's sparse Jacobian structure (``jac_sparsity``): a residual
depends on one camera, one scale and one plane, or on one camera and one point, so finite
differences need only a dozen function evaluations per Jacobian whatever the problem size.

Acceptance: the solution is kept only if its robust cost, evaluated with the very residual
function the solver minimised, is not above the cost of the initial state; otherwise
:func:`adjust` returns the initial state unchanged with ``accepted = False`` and the reason.

Parametrisation: ``R_v = exp([ω_v]×) R_v⁰``; ``t_v`` directly; ``s_v = exp(λ_v)``; a plane is
``n = normalise(n⁰ + B α)`` with ``B`` a (3, 2) basis of the tangent plane of ``n⁰``, and ``d``.

Frames: world-to-camera ``x_cam = R x_world + t``, OpenCV camera axes; pixel centres at
integer coordinates; planes ``n · x + d = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.polygons import plane_basis

if TYPE_CHECKING:
    from scipy.sparse import coo_matrix


@dataclass
class AdjustmentProblem:
    """Input of :func:`adjust`.

    Attributes
    ----------
    K : numpy.ndarray
        (V, 3, 3) intrinsics.
    R, t : numpy.ndarray
        (V, 3, 3) and (V, 3) initial world-to-camera poses.
    points : numpy.ndarray
        (M, 3) initial world points.
    obs_view, obs_point : numpy.ndarray
        (O,) int view and point index of each SfM observation.
    obs_uv : numpy.ndarray
        (O, 2) observed pixel ``(u, v)``.
    planes : numpy.ndarray
        (G, 4) initial global planes, unit normals.
    samp_view, samp_plane : numpy.ndarray
        (S,) int view and global plane of each plane-pixel sample.
    samp_x : numpy.ndarray
        (S, 3) sample lifted into its camera with the current depth (scale 1), ``z > 0``.
    norm_view, norm_plane : numpy.ndarray
        (L,) int view and global plane of each view-plane normal.
    norm_m : numpy.ndarray
        (L, 3) unit normal of that view plane in its camera frame.
    pp_point, pp_plane : numpy.ndarray
        (Q,) int SfM point and global plane of each point-on-plane residual.
    pp_depth : numpy.ndarray
        (Q,) depth of that point in its observing views (weights the residual, fixed).
    sigma_px : float
        Expected reprojection noise (pixels).
    sigma_rel : float
        Expected relative depth noise of plane pixels.
    sigma_normal_deg : float
        Expected angle between a view plane's normal and its global plane's (degrees).
    sigma_point : float
        Expected distance of an SfM point to its plane, relative to its depth.
    prior_rot_deg : float
        Pose prior: expected rotation change (degrees).
    prior_t : numpy.ndarray or None
        (V,) pose prior: expected translation change of each view (world units); None
        disables the prior.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    points: np.ndarray
    obs_view: np.ndarray
    obs_point: np.ndarray
    obs_uv: np.ndarray
    planes: np.ndarray
    samp_view: np.ndarray
    samp_plane: np.ndarray
    samp_x: np.ndarray
    norm_view: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    norm_plane: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    norm_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pp_point: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    pp_plane: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    pp_depth: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sigma_px: float = 1.0
    sigma_rel: float = 0.03
    sigma_normal_deg: float = 2.0
    sigma_point: float = 0.01
    prior_rot_deg: float = 1.0
    prior_t: np.ndarray | None = None

    def __post_init__(self) -> None:
        v = len(self.R)
        if v < 1 or self.K.shape != (v, 3, 3) or self.t.shape != (v, 3):
            raise InvalidInput("plane adjustment: K, R, t must be (V, 3, 3), (V, 3, 3), (V, 3)")
        if len(self.obs_view) != len(self.obs_point) or len(self.obs_uv) != len(self.obs_view):
            raise InvalidInput("plane adjustment: observation arrays differ in length")
        if len(self.samp_view) != len(self.samp_plane) or len(self.samp_x) != len(
                self.samp_view):
            raise InvalidInput("plane adjustment: plane sample arrays differ in length")
        if len(self.norm_view) != len(self.norm_plane) or len(self.norm_m) != len(
                self.norm_view):
            raise InvalidInput("plane adjustment: normal arrays differ in length")
        if not len(self.pp_point) == len(self.pp_plane) == len(self.pp_depth):
            raise InvalidInput("plane adjustment: point-on-plane arrays differ in length")
        if not (self.sigma_px > 0 and self.sigma_rel > 0 and self.sigma_normal_deg > 0
                and self.sigma_point > 0):
            raise InvalidInput("plane adjustment: the sigmas must be positive")


@dataclass
class AdjustmentResult:
    """Output of :func:`adjust`.

    Attributes
    ----------
    R, t : numpy.ndarray
        (V, 3, 3), (V, 3) refined poses (view 0 unchanged).
    scales : numpy.ndarray
        (V,) factor to apply to each view's depth (1 for view 0).
    planes : numpy.ndarray
        (G, 4) refined planes, unit normals.
    points : numpy.ndarray
        (M, 3) refined points.
    before, after : dict
        Summaries of the initial and of the returned state (see :func:`residual_summary`),
        each with ``cost``, the solver's robust objective, and ``cost_terms``, its share per
        residual kind. ``after`` equals ``before`` when the solution was rejected.
    success : bool
        The solver's own convergence flag.
    message : str
        The solver's message.
    accepted : bool
        False when the solver's solution raised the objective (or made it non-finite) and
        the initial state was returned instead.
    reason : str
        Why the solution was rejected; empty when accepted.
    rejected : dict
        Summary of the rejected solution (same keys as ``after``); empty when accepted.
    """

    R: np.ndarray
    t: np.ndarray
    scales: np.ndarray
    planes: np.ndarray
    points: np.ndarray
    before: dict = field(default_factory=dict)
    after: dict = field(default_factory=dict)
    success: bool = True
    message: str = ""
    accepted: bool = True
    reason: str = ""
    rejected: dict = field(default_factory=dict)


class _Layout:
    """Index bookkeeping of the parameter vector."""

    def __init__(self, n_views: int, n_planes: int, n_points: int) -> None:
        self.v, self.g, self.m = n_views, n_planes, n_points
        self.pose = 0                                  # 6 per view 1..V-1
        self.scale = self.pose + 6 * (n_views - 1)     # 1 per view 1..V-1
        self.plane = self.scale + (n_views - 1)        # 3 per plane
        self.point = self.plane + 3 * n_planes         # 3 per point
        self.size = self.point + 3 * n_points

    def pose_cols(self, views: np.ndarray) -> np.ndarray:
        """(K, 6) columns of each view's pose (-1 for view 0, which is fixed)."""
        base = self.pose + 6 * (views - 1)
        cols = base[:, None] + np.arange(6)[None, :]
        cols[views == 0] = -1
        return cols

    def scale_cols(self, views: np.ndarray) -> np.ndarray:
        """(K, 1) column of each view's log-scale (-1 for view 0)."""
        cols = (self.scale + views - 1)[:, None]
        cols[views == 0] = -1
        return cols


def _unpack(x: np.ndarray, lay: _Layout, prob: AdjustmentProblem, bases: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Parameter vector -> (R (V,3,3), t (V,3), scales (V,), planes (G,4), points (M,3))."""
    R, t = prob.R.copy(), prob.t.copy()
    scales = np.ones(lay.v)
    if lay.v > 1:
        from scipy.spatial.transform import Rotation

        pose = x[lay.pose:lay.scale].reshape(-1, 6)
        R[1:] = Rotation.from_rotvec(pose[:, :3]).as_matrix() @ prob.R[1:]
        t[1:] = pose[:, 3:]
        scales[1:] = np.exp(x[lay.scale:lay.plane])
    pl = x[lay.plane:lay.point].reshape(-1, 3)
    n = prob.planes[:, :3] + np.einsum("gij,gj->gi", bases, pl[:, :2])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    planes = np.concatenate([n, pl[:, 2:3]], axis=1)
    points = x[lay.point:].reshape(-1, 3) if lay.m else prob.points
    return R, t, scales, planes, points


def _prior(x: np.ndarray, lay: _Layout, prob: AdjustmentProblem) -> np.ndarray:
    """(V - 1, 6) pose-prior residuals in σ units (empty without a prior)."""
    if prob.prior_t is None or lay.v < 2:
        return np.zeros((0, 6))
    pose = x[lay.pose:lay.scale].reshape(-1, 6)
    rot = pose[:, :3] / np.radians(prob.prior_rot_deg)
    trans = (pose[:, 3:] - prob.t[1:]) / np.asarray(prob.prior_t)[1:, None]
    return np.concatenate([rot, trans], axis=1)


def _residuals(x: np.ndarray, lay: _Layout, prob: AdjustmentProblem, bases: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(reprojection (O, 2), point-to-plane (S,), normal (L, 3), SfM point on plane (Q,)),
    all in σ units."""
    R, t, scales, planes, points = _unpack(x, lay, prob, bases)
    v, p = prob.obs_view, prob.obs_point
    xc = np.einsum("oij,oj->oi", R[v], points[p]) + t[v]
    uvw = np.einsum("oij,oj->oi", prob.K[v], xc)
    z = np.where(np.abs(uvw[:, 2]) > 1e-12, uvw[:, 2], 1e-12)
    reproj = (uvw[:, :2] / z[:, None] - prob.obs_uv) / prob.sigma_px
    sv, sg = prob.samp_view, prob.samp_plane
    s = scales[sv]
    xw = np.einsum("sji,sj->si", R[sv], s[:, None] * prob.samp_x - t[sv])  # Rᵀ (s x − t)
    dist = np.einsum("si,si->s", planes[sg, :3], xw) + planes[sg, 3]
    # Fixed weights (the initial depth), so that no scale can lower its residuals by growing.
    plane = dist / (prob.sigma_rel * prob.samp_x[:, 2])
    lv, lg = prob.norm_view, prob.norm_plane
    m_world = np.einsum("lji,lj->li", R[lv], prob.norm_m)
    normal = (m_world - planes[lg, :3]) / np.radians(prob.sigma_normal_deg)
    qp, qg = prob.pp_point, prob.pp_plane
    onplane = (np.einsum("qi,qi->q", planes[qg, :3], points[qp]) + planes[qg, 3]) / (
        prob.sigma_point * prob.pp_depth)
    return reproj, plane, normal, onplane


#: The residual kinds, in the order of the residual vector (and of the Jacobian's rows).
TERMS = ("reprojection", "plane_samples", "normals", "sfm_points_on_planes", "pose_prior")
#: The figures a refinement reports before and after (:func:`residual_summary` keys), none of
#: which an accepted solution may raise: each with its name and the rise too small to matter
#: whatever its start (from an exact start every figure can only rise a little): 0.005 px,
#: 0.05 degrees, 10⁻⁵ of the depth.
FIGURES: dict[str, tuple[str, float]] = {
    "reprojection_rms_px": ("the RMS reprojection error (px)", 5e-3),
    "plane_rms_rel": ("the RMS plane-pixel distance (share of depth)", 1e-5),
    "normal_rms_deg": ("the RMS view-plane normal angle (deg)", 5e-2),
    "sfm_point_plane_median_rel": ("the median SfM point-to-plane distance (share of depth)",
                                   1e-5),
}


def _terms(x: np.ndarray, lay: _Layout, prob: AdjustmentProblem, bases: np.ndarray
           ) -> list[np.ndarray]:
    """The residual blocks of :data:`TERMS`, in σ units: (O, 2), (S,), (L, 3), (Q,), (V - 1, 6)
    (the last empty without a pose prior)."""
    return [*_residuals(x, lay, prob, bases), _prior(x, lay, prob)]


def residual_summary(reproj: np.ndarray, plane: np.ndarray, normal: np.ndarray,
                     onplane: np.ndarray, prob: AdjustmentProblem) -> dict[str, float]:
    """RMS reprojection error (pixels), RMS / median relative point-to-plane distance, RMS
    view-to-global normal angle (degrees) and median relative SfM point-to-plane distance.

    Parameters
    ----------
    reproj, plane, normal, onplane : numpy.ndarray
        (O, 2), (S,), (L, 3), (Q,) residuals in σ units, as the solver sees them.
    prob : AdjustmentProblem
        The problem (its sigmas turn the residuals back into pixels, depth ratios, degrees).

    Returns
    -------
    dict
        ``reprojection_rms_px``, ``reprojection_median_px``, ``plane_rms_rel``,
        ``plane_median_rel`` (point-to-plane distance over the sample's depth),
        ``normal_rms_deg``, ``sfm_point_plane_median_rel`` (over the point's depth), and the
        counts ``sfm_points_on_planes``, ``observations``, ``plane_samples``.
    """
    ang = np.linalg.norm(normal, axis=1) * prob.sigma_normal_deg
    px = np.linalg.norm(reproj, axis=1) * prob.sigma_px if len(reproj) else np.zeros(0)
    rel = np.abs(plane) * prob.sigma_rel
    return {
        "reprojection_rms_px": float(np.sqrt(np.mean(px**2))) if len(px) else 0.0,
        "reprojection_median_px": float(np.median(px)) if len(px) else 0.0,
        "plane_rms_rel": float(np.sqrt(np.mean(rel**2))) if len(rel) else 0.0,
        "plane_median_rel": float(np.median(rel)) if len(rel) else 0.0,
        "normal_rms_deg": float(np.sqrt(np.mean(ang**2))) if len(ang) else 0.0,
        "sfm_point_plane_median_rel": float(np.median(np.abs(onplane)) * prob.sigma_point)
        if len(onplane) else 0.0,
        "sfm_points_on_planes": int(len(onplane)),
        "observations": int(len(reproj)),
        "plane_samples": int(len(plane)),
    }


def refinement_summary(adj: dict[str, Any]) -> str:
    """One line on a ``plane-ba`` adjuster report (what ``monoplane multiview`` prints): the
    objective before -> after, then the figures of :func:`residual_summary`.

    The headline is the objective, the only figure the adjuster promises not to raise; each
    component is measured on the same residuals, points and planes before and after, and may
    rise where the solve trades it for another (plane pixels from monocular depth against the
    triangulated SfM points).

    Parameters
    ----------
    adj : dict
        The adjuster's report (``MultiviewResult.adjustment``): ``accepted`` (and ``reason``
        when False), ``before`` and ``after`` (:func:`residual_summary` plus ``cost``); empty
        when no adjuster ran.

    Returns
    -------
    str
        The line, or "" when there is nothing to report.
    """
    if not adj.get("accepted", True):
        return f"refinement rejected, scene as fused: {adj.get('reason', '')}"
    b, a = adj.get("before"), adj.get("after")
    if not b or not a:
        return ""
    parts = []
    if b["sfm_points_on_planes"]:
        parts.append(f"SfM points to their planes {100 * b['sfm_point_plane_median_rel']:.2f}% "
                     f"-> {100 * a['sfm_point_plane_median_rel']:.2f}% of depth (median, "
                     f"{b['sfm_points_on_planes']} points)")
    if b["plane_samples"]:
        parts.append(f"plane pixels to their planes {100 * b['plane_rms_rel']:.2f}% -> "
                     f"{100 * a['plane_rms_rel']:.2f}% of depth (RMS)")
        parts.append(f"view-plane normals {b['normal_rms_deg']:.2f} -> "
                     f"{a['normal_rms_deg']:.2f} deg (RMS)")
    if b["observations"]:
        parts.append(f"reprojection {b['reprojection_rms_px']:.2f} -> "
                     f"{a['reprojection_rms_px']:.2f} px (RMS)")
    return (f"refinement: objective {b['cost']:.4g} -> {a['cost']:.4g} (robust cost); "
            + ", ".join(parts))


def _sparsity(lay: _Layout, prob: AdjustmentProblem) -> coo_matrix:
    """Which parameters each residual depends on."""
    from scipy.sparse import coo_matrix  # imported with scipy.optimize, see adjust()

    o, s = len(prob.obs_view), len(prob.samp_view)
    rows, cols = [], []
    # Reprojection rows 2k, 2k+1: the view's pose and the point.
    obs_cols = lay.pose_cols(prob.obs_view)
    if lay.m:
        obs_cols = np.concatenate([obs_cols, lay.point + 3 * prob.obs_point[:, None]
                                   + np.arange(3)], axis=1)
    for r in range(2):
        rr = np.repeat(2 * np.arange(o) + r, obs_cols.shape[1])
        rows.append(rr)
        cols.append(obs_cols.reshape(-1))
    # Plane rows: the view's pose and scale, and the plane.
    samp_cols = np.concatenate([lay.pose_cols(prob.samp_view), lay.scale_cols(prob.samp_view),
                                lay.plane + 3 * prob.samp_plane[:, None] + np.arange(3)],
                               axis=1)
    rows.append(np.repeat(2 * o + np.arange(s), samp_cols.shape[1]))
    cols.append(samp_cols.reshape(-1))
    # Normal rows 3k..3k+2: the view's rotation (pose) and the plane's normal.
    n_l = len(prob.norm_view)
    norm_cols = np.concatenate([lay.pose_cols(prob.norm_view),
                                lay.plane + 3 * prob.norm_plane[:, None] + np.arange(3)],
                               axis=1)
    for r in range(3):
        rows.append(np.repeat(2 * o + s + 3 * np.arange(n_l) + r, norm_cols.shape[1]))
        cols.append(norm_cols.reshape(-1))
    n_rows = 2 * o + s + 3 * n_l
    # SfM point-on-plane rows: the point and the plane.
    q = len(prob.pp_point)
    pp_cols = lay.plane + 3 * prob.pp_plane[:, None] + np.arange(3)
    if lay.m:
        pp_cols = np.concatenate([pp_cols, lay.point + 3 * prob.pp_point[:, None]
                                  + np.arange(3)], axis=1)
    rows.append(np.repeat(n_rows + np.arange(q), pp_cols.shape[1]))
    cols.append(pp_cols.reshape(-1))
    n_rows += q
    if prob.prior_t is not None and lay.v > 1:
        # Prior rows: 6 per view 1..V-1, each on one pose parameter.
        rows.append(n_rows + np.arange(6 * (lay.v - 1)))
        cols.append(lay.pose + np.arange(6 * (lay.v - 1)))
        n_rows += 6 * (lay.v - 1)
    r, c = np.concatenate(rows), np.concatenate(cols)
    keep = c >= 0
    return coo_matrix((np.ones(int(keep.sum())), (r[keep], c[keep])),
                      shape=(n_rows, lay.size))


#: ρ(z) of scipy's robust losses, z the squared residual (f_scale 1).
_LOSSES = {
    "linear": lambda z: z,
    "soft_l1": lambda z: 2.0 * (np.sqrt(1.0 + z) - 1.0),
    "huber": lambda z: np.where(z <= 1.0, z, 2.0 * np.sqrt(z) - 1.0),
    "cauchy": np.log1p,
    "arctan": np.arctan,
}


def _robust_cost(f: np.ndarray, loss: str) -> float:
    """The solver's objective ``½ Σ ρ(f²)`` (what it lowers), for the before/after report."""
    return float(0.5 * np.sum(_LOSSES[loss](f * f)))


def _summary(x: np.ndarray, lay: _Layout, prob: AdjustmentProblem, bases: np.ndarray,
             loss: str) -> dict:
    """:func:`residual_summary` of state ``x``, plus ``cost`` (the solver's objective, on the
    whole residual vector) and ``cost_terms`` (its part from each of :data:`TERMS`)."""
    terms = _terms(x, lay, prob, bases)
    reproj, plane, normal, onplane, _ = terms
    out: dict = residual_summary(reproj, plane, normal, onplane, prob)
    flat = [b.reshape(-1) for b in terms]
    out["cost"] = _robust_cost(np.concatenate(flat), loss)
    out["cost_terms"] = {name: _robust_cost(b, loss) for name, b in zip(TERMS, flat,
                                                                         strict=True)}
    return out


def adjust(prob: AdjustmentProblem, max_evaluations: int = 100, loss: str = "soft_l1",
           refine_points: bool = True, figure_tolerance: float = np.inf) -> AdjustmentResult:
    """Solve the joint plane–camera refinement.

    Parameters
    ----------
    prob : AdjustmentProblem
        Cameras, points, observations, planes and plane-pixel samples.
    max_evaluations : int
        Cap on the solver's function evaluations.
    refine_points : bool
        Refine the SfM points too; False holds them fixed (COLMAP has already adjusted them
        with these cameras), which leaves a problem of a few dozen unknowns.
    loss : str
        Robust loss of :func:`scipy.optimize.least_squares` on the unitless residuals (one
        of ``linear``, ``soft_l1``, ``huber``, ``cauchy``, ``arctan``).
    figure_tolerance : float
        Relative rise of a reported figure (:data:`FIGURES`) that still counts as no rise,
        e.g. 0.05 for 5 %; ``inf`` judges the solution by its objective alone.

    Returns
    -------
    AdjustmentResult
        The solution if its robust cost is not above the initial one and none of the reported
        figures rises, else the initial state with ``accepted = False`` and the reason.
    """
    if loss not in _LOSSES:
        raise InvalidInput(f"unknown loss {loss!r}; choose one of {', '.join(_LOSSES)}")
    lay = _Layout(len(prob.R), len(prob.planes), len(prob.points) if refine_points else 0)
    bases = np.stack([np.stack(plane_basis(n), axis=1) for n in prob.planes[:, :3]]) \
        if len(prob.planes) else np.zeros((0, 3, 2))
    x0 = np.zeros(lay.size)
    if lay.v > 1:
        x0[lay.pose:lay.scale].reshape(-1, 6)[:, 3:] = prob.t[1:]
    x0[lay.plane:lay.point].reshape(-1, 3)[:, 2] = prob.planes[:, 3]
    if lay.m:
        x0[lay.point:] = prob.points.reshape(-1)

    def fun(x: np.ndarray) -> np.ndarray:
        return np.concatenate([b.reshape(-1) for b in _terms(x, lay, prob, bases)])

    before = _summary(x0, lay, prob, bases, loss)
    if lay.size == 0 or (len(prob.obs_view) + len(prob.samp_view)) == 0:
        return AdjustmentResult(prob.R.copy(), prob.t.copy(), np.ones(lay.v),
                                prob.planes.copy(), prob.points.copy(), before, before,
                                True, "nothing to adjust")
    # Imported here: scipy.optimize and scipy.sparse cost about 0.25 s to import, which the
    # single-view commands (and every batch driver) would otherwise pay for nothing.
    from scipy.optimize import least_squares

    sol = least_squares(fun, x0, jac_sparsity=_sparsity(lay, prob), method="trf", loss=loss,
                        f_scale=1.0, x_scale="jac", max_nfev=max_evaluations)
    after = _summary(sol.x, lay, prob, bases, loss)
    # Both costs come from the same residual function and loss, so they compare exactly.
    # The trust-region solver only takes steps that lower it; this guards against anything
    # that breaks that (non-finite residuals, another solver) instead of trusting it. Written
    # as "not <=" so that a NaN cost is rejected too.
    reason = ""
    if not after["cost"] <= before["cost"]:
        reason = (f"the solution raised the robust cost from {before['cost']:.6g} to "
                  f"{after['cost']:.6g}")
    elif np.isfinite(figure_tolerance):
        # A lower objective can still trade one reported figure for the others (reprojection
        # for plane fit, say); a refinement must not make any figure it reports worse.
        for key, (label, negligible) in FIGURES.items():
            if not after[key] <= before[key] * (1.0 + figure_tolerance) + negligible:
                reason = (f"the solution raised {label} from {before[key]:.4g} to "
                          f"{after[key]:.4g}")
                break
    if reason:
        return AdjustmentResult(
            prob.R.copy(), prob.t.copy(), np.ones(lay.v), prob.planes.copy(),
            prob.points.copy(), before, before, bool(sol.success), str(sol.message),
            accepted=False, rejected=after, reason=f"{reason}; the initial state is kept")
    R, t, scales, planes, points = _unpack(sol.x, lay, prob, bases)
    return AdjustmentResult(R, t, scales, planes, points, before, after,
                            bool(sol.success), str(sol.message))
