"""Built-in registrars: place the views structure from motion left out (see docs/multiview.md).

``plane-aware`` places each left-over view against the already placed view it agrees with best.
For every such pair it gathers pose hypotheses from every source it is allowed
(``registrar.methods``), checks each one densely against both views' depth and normals, refines
the best by ICP and accepts it only if the verified overlap is large enough and the views do not
contradict each other (:mod:`monoplane.geometry.view_registration`). Views are placed greedily,
best-verified pair first, so a view placed early can serve as the reference of the next.

``none`` leaves them out (the views SfM registered are reconstructed alone).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from monoplane.contracts import Registrar, Stage, param
from monoplane.datamodel import Camera, Reconstruction, SfmResult
from monoplane.errors import ConfigError
from monoplane.geometry.alignment import ScaleAlignment
from monoplane.geometry.epipolar import depth_disagreement, refine_epipolar
from monoplane.geometry.open3d_registration import fpfh_hypothesis, refine_icp
from monoplane.geometry.pose_hypotheses import (
    feature_hypotheses,
    rotation_deg,
    rotation_hypotheses,
    translation_from_matches,
    translation_from_planes,
)
from monoplane.geometry.relative_pose import (
    Features,
    essential_pose,
    guided_matches,
    match_features,
    pnp_pose,
    sift_features,
)
from monoplane.geometry.view_agreement import (
    Agreement,
    Hypothesis,
    ViewGeometry,
    agreement,
    view_geometry,
)
from monoplane.hookspecs import hookimpl

#: Relative depth: how many of the densely best hypotheses are refined epipolarly.
_RELATIVE_STARTS = 8

#: Relative depth: the robust essential-matrix fits tried, (estimator, threshold in pixels);
#: on a near-planar wide pair each lands on another pose of the same epipolar support.
_ESSENTIAL_FITS: tuple[tuple[str, float], ...] = (
    ("magsac", 0.5), ("magsac", 1.0), ("accurate", 1.0), ("accurate", 2.0), ("ransac", 0.5),
    ("ransac", 1.0), ("ransac", 2.0))

#: Hypothesis sources, in the order they are tried; what ``cameras.json`` names them.
METHODS: dict[str, str] = {
    "features": "3D feature matches (keypoints lifted with both depths), rigid or similarity "
                "RANSAC",
    "essential": "essential matrix of the keypoint matches (OpenCV USAC MAGSAC++), baseline "
                 "and scale from the depth; PnP on short baselines",
    "planes": "rotation from pairs of non-parallel planes (dominant directions); translation "
              "and scale from feature matches or, without them, from the plane offsets",
    "fpfh": "Open3D FPFH features + RANSAC global registration (metric depth only)",
}


@dataclass
class _Candidate:
    """The best verified hypothesis of one (reference, view) pair."""

    hyp: Hypothesis
    check: Agreement
    matches: int
    refined: bool
    accepted: bool


class PlaneAwareRegistrar(Registrar):
    """Places left-over views from planes, normals, depth and the feature matches there are."""

    name = "plane-aware"

    @dataclass
    class Config:
        methods: list[str] = param(
            ["features", "essential", "planes", "fpfh"],
            f"hypothesis sources to try: {', '.join(METHODS)} (docs/multiview.md)")
        min_overlap: float = param(
            0.08, "smallest verified overlap accepted: the share of both views' sampled points "
                  "that land on the other view's surface under the pose")
        min_colour: float = param(
            0.4, "smallest correlation of the grey levels of the two views at the agreeing "
                 "points (a place of the same shape elsewhere, or another room, correlates "
                 "near 0)")
        max_violation: float = param(
            0.25, "largest share of free-space violations (points landing in front of the "
                  "surface the other view sees) per agreeing point")
        tolerance_metric: float = param(
            0.04, "relative depth tolerance of the dense check when both depths are metric")
        tolerance_relative: float = param(
            0.10, "relative depth tolerance of the dense check on relative (monocular) depth, "
                  "which warps")
        match_tolerance: float = param(
            0.06, "relative 3D tolerance of a feature match inlier (metric depth; twice this "
                  "on relative depth)")
        verify_sfm_below: int = param(
            200, "check an SfM placement densely when its view observes fewer model points "
                 "than this, and replace it when a hypothesis of the registrar's verifies "
                 "better (a two-view model on a few dozen points can be degrees off)")
        guided_radius: float = param(
            0.03, "relative depth: search radius of guided matching, a share of the image "
                  "width")
        guided_max_change_deg: float = param(
            10.0, "relative depth: largest rotation change the guided essential matrix may "
                  "make to the hypothesis it started from")
        epipolar_threshold_px: float = param(
            2.0, "relative depth: Sampson distance (px) within which a match supports a pose's "
                 "epipolar geometry")
        support_share: float = param(
            0.85, "relative depth: poses supported by at least this share of the best "
                  "epipolar support compete on how well their triangulated depths agree with "
                  "the views' own")
        sfm_margin: float = param(
            1.25, "relative depth: an SfM pose under check is replaced only by a candidate whose "
                 "depth disagreement is this many times lower (or when it explains too few "
                 "matches)")
        min_epipolar_support: int = param(
            20, "relative depth: fewest supporting matches for the pose to be chosen by its "
                "epipolar support (rotation and direction from the matches, which do not "
                "warp); below it, by the dense agreement of the depths")
        rotations: int = param(12, "plane-pair rotations tried per view pair (heaviest first)")
        icp: bool = param(True, "refine the best hypothesis by ICP (Open3D) when both depths "
                                "are metric")
        grid: int = param(96, "sample points across the image width for the dense check")
        seed: int = param(0, "random seed of the RANSAC samplers")

        def __post_init__(self) -> None:
            unknown = [m for m in self.methods if m not in METHODS]
            if unknown or not self.methods:
                raise ConfigError(f"methods: unknown {', '.join(unknown) or '(none)'}"
                                  f"; valid choices: {', '.join(METHODS)}")

    def register(self, views: list[Reconstruction], sfm: SfmResult,
                 alignments: list[ScaleAlignment | None]
                 ) -> tuple[SfmResult, list[ScaleAlignment | None]]:
        registration = [dict(r) for r in sfm.registration] or [{"method": "sfm"} for _ in views]
        cameras = list(sfm.cameras)
        aligns = list(alignments)
        placed = [v for v, r in enumerate(registration) if r["method"] != "none"]
        todo = [v for v, r in enumerate(registration) if r["method"] == "none"]
        features: dict[int, Features] = {}
        raw_cache: dict[int, ViewGeometry] = {}
        scaled: dict[int, ViewGeometry] = {}
        best: dict[tuple[int, int], _Candidate | None] = {}

        def raw(v: int) -> ViewGeometry:
            if v not in raw_cache:
                raw_cache[v] = self._geometry(views[v], 1.0)
            return raw_cache[v]

        def scaled_view(r: int) -> ViewGeometry:
            if r not in scaled:
                scaled[r] = self._geometry(views[r], aligns[r].scale)
            return scaled[r]

        def place(v: int, r: int, c: _Candidate) -> None:
            cam_r, hyp = cameras[r], c.hyp
            # s X_v = R X_r + t and X_r = R_r X_w + t_r  =>  X_v' = R R_r X_w + (R t_r + t),
            # X_v' in world units; the view's depth times its scale is in world units too.
            cameras[v] = replace(cameras[v], R=hyp.R @ cam_r.R, t=hyp.R @ cam_r.t + hyp.t)
            aligns[v] = ScaleAlignment(scale=hyp.s, num_points=c.check.visible,
                                       num_inliers=c.check.agree, residual=float("nan"),
                                       relative_residual=float("nan"))
            registration[v] = {
                "method": hyp.source.removesuffix("+guided"),
                "description": METHODS[hyp.source.split("+")[0]],
                "guided": hyp.source.endswith("+guided"),
                "reference": views[r].frame.name, "matches": c.matches,
                "support": hyp.support, "icp": c.refined,
                "verified_overlap": round(c.check.overlap, 4),
                "agreeing_points": c.check.agree, "violations": c.check.violate,
                "colour_correlation": round(c.check.colour, 4),
                "depth_scale": hyp.s,
            }

        self._verify_sfm(views, sfm, features, raw, scaled_view, cameras, aligns,
                         registration, place)
        while todo:
            for v in todo:
                for r in placed:
                    if (r, v) not in best:
                        best[(r, v)] = self._pair(views, sfm, features, scaled_view(r), raw(v),
                                                  r, v, aligns[r].scale)
            options = [(c.check.score, r, v) for (r, v), c in best.items()
                       if c is not None and c.accepted and v in todo and r in placed]
            if not options:
                break
            _, r, v = max(options)
            place(v, r, best[(r, v)])
            todo.remove(v)
            placed.append(v)
        for v in todo:
            tried = [c for (r, u), c in best.items() if u == v and c is not None]
            registration[v] = {"method": "none", "reason": self._why(tried)}
        # A replaced SfM pose's keypoints no longer observe the model's points (which were
        # triangulated with the pose the dense check rejected).
        point_ids = [np.full_like(ids, -1) if registration[v].get("replaced") == "sfm" else ids
                     for v, ids in enumerate(sfm.point_ids)]
        return replace(sfm, cameras=cameras, registration=registration,
                       point_ids=point_ids), aligns

    # ------------------------------------------------------------------------------------------

    def _verify_sfm(self, views: list[Reconstruction], sfm: SfmResult,
                    features: dict[int, Features], raw: Callable[[int], ViewGeometry],
                    scaled_view: Callable[[int], ViewGeometry], cameras: list[Camera],
                    aligns: list[ScaleAlignment | None], registration: list[dict],
                    place: Callable[[int, int, _Candidate], None]) -> None:
        """Check the weakly supported SfM placements densely; replace those a hypothesis of the
        registrar's verifies better.

        The reference is the SfM view observing the most model points; every other SfM view
        observing fewer than ``verify_sfm_below`` points has its SfM pose relative to it scored
        by :func:`agreement` and compared with the registrar's best hypothesis for the pair.
        """
        cfg = self.config
        in_sfm = [v for v, r in enumerate(registration) if r["method"] == "sfm"]
        if len(in_sfm) < 2:
            return
        r = max(in_sfm, key=lambda v: registration[v].get("observations", 0))
        for v in in_sfm:
            if v == r or registration[v].get("observations", 0) >= cfg.verify_sfm_below:
                continue
            metric = self._metric(views, r, v)
            tol = cfg.tolerance_metric if metric else cfg.tolerance_relative
            R = cameras[v].R @ cameras[r].R.T
            own = Hypothesis(R, cameras[v].t - R @ cameras[r].t, aligns[v].scale, "sfm")
            check = agreement(scaled_view(r), raw(v), own, tol)
            # On relative depth the SfM pose competes among the registrar's candidates on
            # the same epipolar and depth evidence, and is replaced when another wins.
            found = self._pair(views, sfm, features, scaled_view(r), raw(v), r, v,
                               aligns[r].scale, extra=None if metric else own)
            better = found is not None and found.accepted and (
                found.check.score > check.score if metric
                else found.refined and found.hyp.source != "sfm")
            if better:
                observations = registration[v].get("observations", 0)
                place(v, r, found)
                registration[v].update(replaced="sfm", sfm_observations=observations,
                                       sfm_verified_overlap=round(check.overlap, 4))
            else:
                registration[v]["verified_overlap"] = round(check.overlap, 4)

    @staticmethod
    def _metric(views: list[Reconstruction], r: int, v: int) -> bool:
        """Whether both views' depths are measured, metric and in the same units (then they
        share a scale and their shapes can be trusted); a network's metric depth is not."""
        fr, fv = views[r].frame, views[v].frame
        return (fr.depth_kind == "metric" and fv.depth_kind == "metric"
                and fr.depth_units == fv.depth_units
                and not (fr.depth_predicted or fv.depth_predicted))

    def _geometry(self, rec: Reconstruction, scale: float) -> ViewGeometry:
        f = rec.frame
        return view_geometry(f.K, f.depth * scale, f.normals, f.rgb, rec.planes,
                             rec.area_px, f.depth_kind == "metric", self.config.grid)

    def _why(self, tried: list[_Candidate]) -> str:
        if not tried:
            return "no pose hypothesis from any method (no feature matches, too few planes)"
        c = max(tried, key=lambda c: c.check.score)
        cfg = self.config
        return (f"best pose verified on {c.check.overlap:.1%} of the points, colour "
                f"correlation {c.check.colour:.2f}, {c.check.violation:.0%} free-space "
                f"violations (needs {cfg.min_overlap:.0%}, {cfg.min_colour:.2f} and at most "
                f"{cfg.max_violation:.0%})")

    def _matches(self, views: list[Reconstruction], sfm: SfmResult,
                 features: dict[int, Features], r: int, v: int
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Keypoint matches of the pair: the matcher's verified ones or the features stage's
        (``sfm.correspondences``), whichever are more (a learned feature's hundreds against
        the few SIFT matches SfM verified), else SIFT's."""
        key, flip = ((r, v), False) if r < v else ((v, r), True)
        given = sfm.matches.get(key)
        found = (sfm.correspondences.pixels(r, v) if sfm.correspondences is not None
                 else None)
        if given is not None and len(given) and (found is None or len(given) >= len(found[0])):
            a, b = (1, 0) if flip else (0, 1)
            return (sfm.keypoints[r][given[:, a]], sfm.keypoints[v][given[:, b]])
        if found is not None:
            return found
        return match_features(self._features(views, sfm, features, r),
                              self._features(views, sfm, features, v))

    @staticmethod
    def _features(views: list[Reconstruction], sfm: SfmResult, features: dict[int, Features],
                  u: int) -> Features:
        """View ``u``'s keypoints and descriptors: the features stage's when it describes
        each image, else SIFT's (computed once)."""
        if u not in features:
            own = sfm.correspondences.keypoints(u) if sfm.correspondences is not None else None
            if own is not None and own.descriptors is not None:
                features[u] = Features(own.pixels, own.descriptors)
            else:
                features[u] = sift_features(views[u].frame.rgb)
        return features[u]

    def _guided(self, views: list[Reconstruction], sfm: SfmResult,
                features: dict[int, Features],
                ref: ViewGeometry, other: ViewGeometry, r: int, v: int, hyp: Hypothesis,
                fixed: float | None
                ) -> tuple[Hypothesis | None, tuple[np.ndarray, np.ndarray]]:
        """Essential-matrix pose of the matches found near where ``hyp`` predicts them, and
        those matches ((m, 2) pixels in ``r`` and in ``v``)."""
        fr = self._features(views, sfm, features, r)
        fv = self._features(views, sfm, features, v)
        x = _lift(fr.pixels, ref)
        q = x @ hyp.R.T + hyp.t
        with np.errstate(divide="ignore", invalid="ignore"):
            pred = np.c_[other.K[0, 0] * q[:, 0] / q[:, 2] + other.K[0, 2],
                         other.K[1, 1] * q[:, 1] / q[:, 2] + other.K[1, 2]]
        pred[(x[:, 2] <= 0) | (q[:, 2] <= 0)] = np.nan
        radius = self.config.guided_radius * other.shape[1]
        pr, pv = guided_matches(fr, fv, pred, radius)
        if len(pr) < 15:
            return None, (pr, pv)
        found = essential_pose(pr, pv, ref.K, ref.depth, other.K, other.depth, 15)
        if found is None:
            return None, (pr, pv)
        return Hypothesis(found.R, found.t, fixed if fixed is not None else found.depth_scale_j,
                          hyp.source + "+guided", found.inliers), (pr, pv)

    def _pair(self, views: list[Reconstruction], sfm: SfmResult, features: dict[int, Features],
              ref: ViewGeometry, other: ViewGeometry, r: int, v: int, scale_r: float,
              extra: Hypothesis | None = None) -> _Candidate | None:
        cfg = self.config
        metric = self._metric(views, r, v)
        fixed = scale_r if metric else None
        tol = cfg.tolerance_metric if metric else cfg.tolerance_relative
        match_tol = cfg.match_tolerance * (1.0 if metric else 2.0)
        pr, pv = self._matches(views, sfm, features, r, v)
        xr, xv = _lift(pr, ref), _lift(pv, other)
        ok = (xr[:, 2] > 0) & (xv[:, 2] > 0)
        xr, xv = xr[ok], xv[ok]
        hyps: list[Hypothesis] = []
        if "features" in cfg.methods:
            hyps += feature_hypotheses(xr, xv, fixed, match_tol, seed=cfg.seed)
        if "essential" in cfg.methods and len(pr) >= 8:
            hyps += _essential(pr, pv, ref, other, fixed)
        if "planes" in cfg.methods:
            for R, _ in rotation_hypotheses(ref, other)[:cfg.rotations]:
                found = translation_from_matches(R, xr, xv, fixed, match_tol)
                if found is not None:
                    hyps.append(Hypothesis(R, found[0], found[1], "planes+features", found[2]))
                for t, s, n in translation_from_planes(R, ref, other, fixed, keep=3):
                    hyps.append(Hypothesis(R, t, s, "planes", n))
        if "fpfh" in cfg.methods and metric:
            found = fpfh_hypothesis(ref, other, scale_r, seed=cfg.seed)
            if found is not None:
                hyps.append(found)
        if not hyps and extra is None:
            return None
        checked = sorted(((agreement(ref, other, h, tol), h) for h in hyps),
                         key=lambda e: -e[0].score)
        check, hyp = checked[0]
        refined = False
        if metric and cfg.icp:
            # Metric depth: ICP on the dense clouds from the two best distinct starts (a wrong
            # top hypothesis often sits next to a right second one). ICP minimises its own
            # point-to-plane cost, not the agreement count, so its result is kept unless it
            # loses more than a little of the verified overlap.
            for _, hyp0 in checked[:2]:
                better = refine_icp(ref, other, hyp0, metric)
                after = agreement(ref, other, better, tol)
                if after.agree >= 0.98 * check.agree and (not refined or after.score > check.score):
                    check, hyp, refined = after, better, True
        elif "essential" in cfg.methods:
            check, hyp, refined = self._relative_pose(views, sfm, features, ref, other, r, v,
                                                      checked, pr, pv, tol, extra)
        return _Candidate(hyp, check, len(pr), refined, _accepted(check, cfg))

    def _relative_pose(self, views: list[Reconstruction], sfm: SfmResult,
                       features: dict[int, Features], ref: ViewGeometry, other: ViewGeometry,
                       r: int, v: int, checked: list[tuple[Agreement, Hypothesis]],
                       pr: np.ndarray, pv: np.ndarray, tol: float,
                       extra: Hypothesis | None = None
                       ) -> tuple[Agreement, Hypothesis, bool]:
        """The pose of a pair with relative depth: rotation and direction from the matches.

        Relative depth warps (several percent), so every pose fitted on lifted points or on
        normals inherits degrees of error (ICP made it worse, docs/multiview.md); the
        epipolar geometry of the matches does not warp. Candidates are the sources'
        hypotheses, essential matrices of the matches from several robust estimators and
        thresholds, and the one of the matches found near where the densely best hypothesis
        predicts them (guided matching); each is refined on the Sampson distances of its
        epipolar inliers. Of those the dense check accepts and that explain nearly as many
        matches as the best (``support_share``), the one whose triangulated depths agree
        best with the views' own (:func:`depth_disagreement`) wins: near-planar scenes let a
        pose trade degrees of rotation against its translation at almost the same epipolar
        support, but not at the same depths. With fewer than ``min_epipolar_support``
        supporting matches (low texture), the densely best verified hypothesis is kept.
        ``extra`` (an SfM pose being checked) competes as one more candidate.
        """
        cfg = self.config
        check, hyp = checked[0] if checked else (None, None)
        # The densely best few, and every essential matrix however it ranks densely.
        candidates = [h for k, (_, h) in enumerate(checked)
                      if k < _RELATIVE_STARTS or h.source == "essential"]
        if extra is not None:
            candidates.append(extra)
        if hyp is not None:
            guided, (gr, gv) = self._guided(views, sfm, features, ref, other, r, v, hyp, None)
            if guided is not None and rotation_deg(guided.R, hyp.R) < cfg.guided_max_change_deg:
                candidates.append(guided)
            # Guided matching finds correct matches the unguided search missed (a few of them
            # twice): every hypothesis is judged on both.
            pr, pv = np.concatenate([pr, gr]), np.concatenate([pv, gv])
        if len(pr) >= cfg.min_epipolar_support:
            for estimator, threshold in _ESSENTIAL_FITS:
                fit = essential_pose(pr, pv, ref.K, ref.depth, other.K, other.depth, 8,
                                     threshold, estimator)
                if fit is not None:
                    candidates.append(Hypothesis(fit.R, fit.t, fit.depth_scale_j, "essential",
                                                 fit.inliers))
        thr = cfg.epipolar_threshold_px
        refined: list[tuple[int, Agreement, Hypothesis]] = []
        for start in candidates:
            moved_and_support = refine_epipolar(start, pr, pv, ref.K, other.K, thr)
            if moved_and_support is None:
                continue
            moved, support = moved_and_support
            after = agreement(ref, other, moved, tol)
            if _accepted(after, cfg):
                refined.append((support, after, moved))
        most = max((c[0] for c in refined), default=0)
        if most < cfg.min_epipolar_support:
            if check is not None and hyp is not None:
                return check, hyp, False
            assert extra is not None  # _pair returns before this with neither
            return agreement(ref, other, extra, tol), extra, False
        close = [(depth_disagreement(c[2], pr, pv, ref, other, thr), c) for c in refined
                 if c[0] >= cfg.support_share * most]
        spread, best = min(close, key=lambda e: e[0])
        # An SfM pose was fitted by bundle adjustment on its verified matches: it stays unless
        # another candidate's depths agree clearly better, not by a hair.
        own = [e for e in close if e[1][2].source == "sfm"]
        if own and best[2].source != "sfm" and spread * cfg.sfm_margin >= own[0][0]:
            best = own[0][1]
        return best[1], best[2], True


def _accepted(check: Agreement, cfg: PlaneAwareRegistrar.Config) -> bool:
    return (check.overlap >= cfg.min_overlap and check.violation <= cfg.max_violation
            and check.colour >= cfg.min_colour)


def _lift(pixels: np.ndarray, g: ViewGeometry) -> np.ndarray:
    """(m, 3) points of keypoints lifted with the view's depth; z = 0 where the depth is
    invalid or the keypoint sits on a depth edge (its 3×3 neighbourhood spans more than 5 %)."""
    h, w = g.shape
    out = np.zeros((len(pixels), 3))
    if not len(pixels):
        return out
    ui = np.clip(np.rint(pixels[:, 0]).astype(np.int64), 1, w - 2)
    vi = np.clip(np.rint(pixels[:, 1]).astype(np.int64), 1, h - 2)
    win = np.stack([g.depth[vi + dv, ui + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)])
    lo, hi = win.min(axis=0), win.max(axis=0)
    z = g.depth[vi, ui].astype(np.float64)
    good = (lo > 0) & (hi < 1.05 * lo)
    rays = np.linalg.solve(g.K, np.c_[pixels, np.ones(len(pixels))].T).T
    out[good] = rays[good] * z[good, None]
    return out


def _essential(pr: np.ndarray, pv: np.ndarray, ref: ViewGeometry, other: ViewGeometry,
               fixed: float | None) -> list[Hypothesis]:
    found = essential_pose(pr, pv, ref.K, ref.depth, other.K, other.depth, 8)
    if found is None:
        found = pnp_pose(pr, pv, ref.K, ref.depth, other.K, other.depth, 8)
    if found is None:
        return []
    return [Hypothesis(found.R, found.t, fixed if fixed is not None else found.depth_scale_j,
                       "essential", found.inliers)]


class NoRegistrar(Registrar):
    """Leaves the views the matcher could not register out of the scene."""

    name = "none"

    @dataclass
    class Config:
        pass

    def register(self, views: list[Reconstruction], sfm: SfmResult,
                 alignments: list[ScaleAlignment | None]
                 ) -> tuple[SfmResult, list[ScaleAlignment | None]]:
        registration = [dict(r) if r["method"] != "none" else
                        {**r, "reason": r.get("reason", "the matcher could not register it and "
                                                        "[registrar] plugin is 'none'")}
                        for r in sfm.registration]
        return replace(sfm, registration=registration), list(alignments)


@hookimpl
def monoplane_register_registrars() -> list[type[Stage]]:
    """Register the built-in registrars."""
    return [PlaneAwareRegistrar, NoRegistrar]
