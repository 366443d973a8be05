"""Open3D's registration on two views' grid clouds: FPFH + RANSAC global registration for two
metric views, and ICP refinement of a pose hypothesis (Open3D is imported on first use).

Frames: OpenCV camera axes; poses ``s·X_v = R·X_r + t``
(:class:`~monoplane.geometry.view_agreement.Hypothesis`).
"""

from __future__ import annotations

import numpy as np

from monoplane.geometry.view_agreement import Hypothesis, ViewGeometry


def _o3d_cloud(g: ViewGeometry, scale: float = 1.0):
    import open3d as o3d

    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(g.points * scale)
    pc.normals = o3d.utility.Vector3dVector(g.point_normals)
    pc.colors = o3d.utility.Vector3dVector(g.colors.astype(np.float64))
    return pc


def _median_depth(g: ViewGeometry) -> float:
    return float(np.median(g.points[:, 2])) if len(g.points) else 1.0


def fpfh_hypothesis(ref: ViewGeometry, other: ViewGeometry, scale: float,
                    seed: int = 0) -> Hypothesis | None:
    """Open3D's FPFH + RANSAC global registration, for two views of one metric scale.

    ``scale`` brings ``other``'s depth into ``ref``'s units. The voxel size is 2 % of the
    reference view's median depth.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    voxel = 0.02 * _median_depth(ref)
    clouds = []
    for g, s in ((ref, 1.0), (other, scale)):
        pc = _o3d_cloud(g, s).voxel_down_sample(voxel)
        feat = reg.compute_fpfh_feature(
            pc, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
        clouds.append((pc, feat))
    (src, fs), (dst, fd) = clouds
    if len(src.points) < 10 or len(dst.points) < 10:
        return None
    o3d.utility.random.seed(seed)
    result = reg.registration_ransac_based_on_feature_matching(
        src, dst, fs, fd, True, 1.5 * voxel,
        reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
         reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
        reg.RANSACConvergenceCriteria(100000, 0.999))
    if len(result.correspondence_set) < 3:
        return None
    T = np.asarray(result.transformation)
    # T maps ref points onto other·scale: scale X_o = R X_r + t.
    return Hypothesis(R=T[:3, :3].copy(), t=T[:3, 3].copy(), s=float(scale), source="fpfh",
                      support=int(len(result.correspondence_set)))


def refine_icp(ref: ViewGeometry, other: ViewGeometry, hyp: Hypothesis, metric: bool,
               iterations: int = 30) -> Hypothesis:
    """Refine a hypothesis by ICP on the two views' grid clouds (Open3D).

    Metric depth: point-to-plane ICP at the known scale. Relative depth: point-to-point ICP
    with a scale (Umeyama), since the other view's scale is one of the unknowns. The
    correspondence distance is 5 % of the reference view's median depth.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = _o3d_cloud(ref)
    dst = _o3d_cloud(other, hyp.s)
    init = np.eye(4)
    init[:3, :3], init[:3, 3] = hyp.R, hyp.t
    dist = 0.05 * _median_depth(ref)
    est = (reg.TransformationEstimationPointToPlane() if metric
           else reg.TransformationEstimationPointToPoint(with_scaling=True))
    result = reg.registration_icp(src, dst, dist, init, est,
                                  reg.ICPConvergenceCriteria(max_iteration=iterations))
    T = np.asarray(result.transformation)
    A = T[:3, :3]
    c = float(np.cbrt(np.linalg.det(A)))
    if not c > 0:
        return hyp
    # T maps ref onto s·other with an extra factor c: c R X_r + t = s X_o, so
    # R X_r + t/c = (s/c) X_o.
    return Hypothesis(R=A / c, t=T[:3, 3] / c, s=hyp.s / c, source=hyp.source,
                      support=hyp.support)
