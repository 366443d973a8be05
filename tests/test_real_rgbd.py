"""The pipeline on real RGB-D: the living room (../shared/data/rgbd-livingroom) as an RGB-D
frame and as a depth-only range image, and one frame each of TUM, SUN RGB-D and NYU v2
(../shared/data/rgbd-real-frames) scored per surface against hand-drawn polygons."""

from pathlib import Path

import numpy as np
import pytest

from monoplane import Pipeline, load_frame
from monoplane.io.frames import read_depth

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rgbd-livingroom"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"real RGB-D frames not found at {DATA}")
INTRINSICS = "525,525,319.5,239.5"


def check_planes_explain_depth(rec):
    depth = rec.frame.depth
    labelled = (rec.labels > 0) & (depth > 0)
    # Indoor scenes are mostly planar: walls, floor, furniture faces.
    assert labelled.sum() > 0.5 * (depth > 0).sum()
    rel = np.abs(rec.planar_depth()[labelled] - depth[labelled]) / depth[labelled]
    assert np.median(rel) < 0.01, "planes must agree with the sensor depth on their pixels"
    big = np.argsort(rec.area_px)[::-1][:3]
    assert np.all(rec.rmse[big] < 0.03), "the largest planes fit to a few centimetres (metres)"
    assert np.all(rec.planes[:, 3] > 0), "normals face the camera"


@pytest.fixture(scope="module")
def pipe():
    return Pipeline.from_preset("monoplane")


def test_rgbd_frame(pipe):
    frame = load_frame(DATA / "color_00000.jpg", depth=DATA / "depth_00000.png",
                       depth_scale=1000.0, intrinsics=INTRINSICS)
    rec = pipe.run(frame)
    assert rec.frame.depth_units == "m" and 3 <= rec.num_planes <= 30
    check_planes_explain_depth(rec)


def test_depth_only_range_image(pipe):
    frame = load_frame(depth=DATA / "depth_00000.png", depth_scale=1000.0,
                       intrinsics=INTRINSICS)
    assert frame.rgb is None
    rec = pipe.run(frame)
    assert 3 <= rec.num_planes <= 30
    check_planes_explain_depth(rec)


# --- Three real sensors (../shared/data/rgbd-real-frames): TUM (Kinect), SUN RGB-D, NYU v2 ---
#
# Ground truth made by hand: each obvious surface is a polygon in pixel coordinates (640x480);
# its truth is the polygon's pixels within a Kinect-like band (1 cm + 0.6 cm × z², metres) of
# the plane fitted robustly to their sensor depth, so the objects in front of a surface drop
# out. The globe is curved: its polygon's valid pixels should stay non-planar.

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "rgbd-real-frames"
PLANE, CURVED = "plane", "curved"
SURFACES = {
    "TUM": {
        "desk top": (PLANE, [(30, 246), (100, 199), (315, 199), (318, 177), (555, 173),
                             (628, 248), (330, 252)]),
        "globe": (CURVED, [(62, 40), (80, 18), (110, 10), (140, 18), (155, 40), (155, 75),
                           (140, 98), (110, 106), (80, 98), (62, 75)]),
        "partition": (PLANE, [(160, 8), (585, 15), (585, 170), (322, 175), (322, 90),
                              (160, 92)]),
        "cabinet front": (PLANE, [(90, 110), (310, 95), (312, 192), (100, 194)]),
        "floor": (PLANE, [(200, 400), (630, 300), (635, 475), (200, 475)]),
    },
    "SUN": {
        "floor": (PLANE, [(120, 470), (250, 250), (330, 250), (400, 400), (470, 470)]),
        "left wall": (PLANE, [(125, 80), (170, 120), (170, 380), (125, 390)]),
        "cabinet side": (PLANE, [(372, 120), (400, 110), (400, 390), (372, 380)]),
    },
    "NYU": {
        "floor": (PLANE, [(160, 380), (630, 380), (630, 470), (160, 470)]),
        "wardrobe front": (PLANE, [(200, 240), (310, 240), (310, 340), (200, 340)]),
    },
}


def real_depth(name: str) -> np.ndarray:
    """(480, 640) float32 metres of one shared frame, 0 = invalid, read by the product's own
    decoder of the frame's encoding (formats: its README)."""
    file, encoding = REAL_DEPTH[name]
    return read_depth(REAL / file, depth_encoding=encoding)


REAL_DEPTH = {"TUM": ("TUM_depth.png", "tum"), "SUN": ("SUN_depth.png", "sun-rotated"),
              "NYU": ("NYU_depth.pgm", "kinect-disparity")}


def polygon_mask(polygon: list[tuple[int, int]], shape: tuple[int, int]) -> np.ndarray:
    import cv2

    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.array(polygon, np.int32)], 1)
    return mask.astype(bool)


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    centre = points.mean(axis=0)
    normal = np.linalg.svd(points - centre, full_matrices=False)[2][-1]
    return normal, -float(normal @ centre)


def surface_truth(points: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The polygon's pixels near the plane RANSAC-fitted to them, and that plane's normal."""
    pts = points[mask]
    band = 0.01 + 0.006 * pts[:, 2] ** 2
    rng = np.random.default_rng(0)
    best = max((fit_plane(pts[rng.choice(len(pts), 3, replace=False)]) for _ in range(300)),
               key=lambda p: int((np.abs(pts @ p[0] + p[1]) < band).sum()))
    normal, offset = best
    for _ in range(3):
        normal, offset = fit_plane(pts[np.abs(pts @ normal + offset) < band])
    truth = np.zeros_like(mask)
    truth[mask] = np.abs(pts @ normal + offset) < band
    return truth, normal


def test_fit_plane_recovers_a_tilted_plane():
    xy = np.random.default_rng(1).uniform(-1, 1, (50, 2))
    pts = np.c_[xy, 2 + 0.5 * xy[:, 0]]
    normal, offset = fit_plane(pts)
    assert abs(abs(normal @ np.array([0.5, 0, -1]) / np.sqrt(1.25)) - 1) < 1e-9
    assert np.allclose(pts @ normal + offset, 0, atol=1e-9)


real = pytest.mark.skipif(not REAL.is_dir(), reason=f"real RGB-D frames not found at {REAL}")
COLOURS = {"TUM": "TUM_color.png", "SUN": "SUN_color.jpg", "NYU": "NYU_color.ppm"}
#: Seeds of the sweep that counts, per sampling, how many seeds pass every check.
SWEEP_SEEDS = range(12)


def real_frames(folder: Path) -> dict:
    """The three frames, loaded through a metric ``.npy`` depth written to ``folder``."""
    frames = {}
    for name, colour in COLOURS.items():
        np.save(folder / f"{name}.npy", real_depth(name))
        frames[name] = load_frame(REAL / colour, depth=folder / f"{name}.npy",
                                  intrinsics=INTRINSICS)
    return frames


def surface_truths(frame, name: str) -> dict[str, tuple[str, np.ndarray, np.ndarray | None]]:
    """Per surface of ``name``: (kind, truth mask, truth normal or None), from the depth only."""
    points = frame.points()
    valid = frame.depth > 0
    out = {}
    for surface, (kind, polygon) in SURFACES[name].items():
        mask = polygon_mask(polygon, valid.shape) & valid
        if kind == CURVED:
            out[surface] = (kind, mask, None)
        else:
            out[surface] = (kind, *surface_truth(points, mask))
    return out


def coverage(rec, truths: dict) -> dict[str, tuple[float, float]]:
    """Per surface: (fraction covered by its best plane, that plane's angle in degrees) for a
    plane, (fraction labelled planar, 0) for a curved surface."""
    out = {}
    for surface, (kind, truth, normal) in truths.items():
        if kind == CURVED:
            out[surface] = (float((rec.labels[truth] > 0).mean()), 0.0)
            continue
        counts = np.bincount(rec.labels[truth], minlength=rec.num_planes + 1)[1:]
        best = int(np.argmax(counts))
        cos = abs(rec.planes[best, :3] @ normal)
        out[surface] = (counts[best] / truth.sum(), float(np.degrees(np.arccos(min(cos, 1.0)))))
    return out


def failed_checks(name: str, got: dict[str, tuple[float, float]]) -> list[str]:
    """The checks of frame ``name`` that ``got`` (:func:`coverage`) fails, as messages.

    TUM: desk top >= 70 % within 10 degrees, globe <= 15 % planar, partition within 10 degrees,
    cabinet front and floor >= 80 % within 5 degrees; SUN and NYU: every surface >= 80 % within
    5 degrees."""
    failed = []
    for surface, (cover, angle) in got.items():
        if name == "TUM" and surface == "desk top":
            ok = cover >= 0.7 and angle <= 10
        elif surface == "globe":
            ok = cover <= 0.15
        elif name == "TUM" and surface == "partition":
            ok = angle <= 10
        else:
            ok = cover >= 0.8 and angle <= 5
        if not ok:
            failed.append(f"{name} {surface}: {cover:.0%} at {angle:.1f} deg")
    return failed


def seed_sweep(frames: dict, truths: dict, overrides: list[str], seeds=SWEEP_SEEDS
               ) -> dict[int, dict[str, dict[str, tuple[float, float]]]]:
    """:func:`coverage` of each frame under the ``rgbd`` preset with ``overrides``
    (``--set`` strings ``table.key=value``), per ``ransac.seed``."""
    out = {}
    for seed in seeds:
        pipe = Pipeline.from_preset("rgbd", overrides=[*overrides, f"ransac.seed={seed}"])
        out[seed] = {name: coverage(pipe.run(frame), truths[name])
                     for name, frame in frames.items()}
    return out


def passing_seeds(sweep: dict) -> list[int]:
    """The seeds of a :func:`seed_sweep` at which every check of every frame holds."""
    return [seed for seed, got in sweep.items()
            if not any(failed_checks(name, g) for name, g in got.items())]


@pytest.fixture(scope="module")
def real_truths(tmp_path_factory):
    frames = real_frames(tmp_path_factory.mktemp("real"))
    return frames, {name: surface_truths(frame, name) for name, frame in frames.items()}


@pytest.fixture(scope="module")
def real_runs(real_truths):
    frames, _ = real_truths
    pipe = Pipeline.from_preset("rgbd")
    return {name: pipe.run(frame) for name, frame in frames.items()}


def test_failed_checks_name_what_fails():
    good = {"desk top": (0.9, 2.0), "globe": (0.05, 0.0), "partition": (0.5, 3.0),
            "cabinet front": (0.85, 4.0), "floor": (0.95, 1.0)}
    assert failed_checks("TUM", good) == []
    bad = {**good, "globe": (0.55, 0.0), "floor": (0.95, 6.0)}
    assert failed_checks("TUM", bad) == ["TUM globe: 55% at 0.0 deg", "TUM floor: 95% at 6.0 deg"]
    assert failed_checks("NYU", {"floor": (0.75, 1.0)}) == ["NYU floor: 75% at 1.0 deg"]


@real
def test_tum_desk_globe_and_partition(real_runs, real_truths):
    got = coverage(real_runs["TUM"], real_truths[1]["TUM"])
    assert failed_checks("TUM", got) == [], got


@real
@pytest.mark.parametrize("name", ["SUN", "NYU"])
def test_sun_and_nyu_surfaces(real_runs, real_truths, name):
    got = coverage(real_runs[name], real_truths[1][name])
    assert failed_checks(name, got) == [], got


#: Per ``ransac.sampling`` of the ``rgbd`` preset, at least: the seeds of :data:`SWEEP_SEEDS`
#: that pass every check, and the checks passed over all of them (10 surfaces a seed). Measured:
#: docs/evaluation.md, "The normal gate, eighth round" (the gate took random sampling from 1
#: all-pass seed and 97 checks to 5 and 111, the lattice from 0 and 101 to 4 and 111).
SWEEP_FLOOR = {"random": (5, 111), "grid": (4, 111)}


@real
@pytest.mark.slow
@pytest.mark.parametrize("sampling", sorted(SWEEP_FLOOR))
def test_real_frames_pass_at_enough_seeds(real_truths, sampling):
    # One seed decides the fast tests above; the sampling is judged over twelve.
    frames, truths = real_truths
    sweep = seed_sweep(frames, truths, [f"ransac.sampling={sampling}"])
    fails = {seed: [m for name, g in got.items() for m in failed_checks(name, g)]
             for seed, got in sweep.items()}
    passed = sum(len(g) - len(failed_checks(name, g))
                 for got in sweep.values() for name, g in got.items())
    seeds_floor, checks_floor = SWEEP_FLOOR[sampling]
    assert len(passing_seeds(sweep)) >= seeds_floor and passed >= checks_floor, (passed, fails)
