"""Accuracy and time of the two methods of ``normals_from_depth`` ("gated" and "box").

Accuracy: synthetic scenes (``monoplane.synth.generate(seed, "clean")``) give exact z-depth and
normals; the depth gets sensor-like noise (Gaussian, sigma 0.0015 z² metres) and millimetre
quantisation, then each method's normals are compared with the exact ones (angle in degrees)
on every valid pixel, on the pixels within the window radius of another face (depth edges and
creases) and on the rest of the planar faces.

Time: with ``--depth-dir``, a folder of 16-bit PNG depth maps in millimetres (fx = fy = 525,
cx = 319.5, cy = 239.5, e.g. a Redwood-style sequence's ``depth/``), both methods run on
every ``--every``-th frame, alternated in one process; medians of wall and process CPU time.
Usage::

    python3 benchmarks/normals_from_depth.py --scenes 10 --depth-dir livingroom/depth
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from monoplane.datamodel import intrinsics_matrix
from monoplane.geometry.normals import NORMALS_METHODS, normals_from_depth
from monoplane.synth import generate


def accuracy(scenes: int, width: int, height: int) -> None:
    """Print each method's angular error against the exact normals of noisy synthetic depth."""
    errors: dict[str, dict[str, list[np.ndarray]]] = {
        m: {"all": [], "near another face": [], "face interior": []} for m in NORMALS_METHODS}
    for seed in range(scenes):
        view = generate(seed=seed, level="clean", width=width, height=height).views[0]
        z = view.gt_depth.astype(np.float64)
        noise = np.random.default_rng(seed).normal(0.0, 1.0, z.shape) * 0.0015 * z ** 2
        depth = np.where(z > 0, np.round((z + noise) * 1000) / 1000, 0).astype(np.float32)
        valid = (z > 0) & (np.abs(view.gt_normals).sum(-1) > 0)
        # Another face within the window: the Chebyshev neighbourhood of radius 6.
        faces = view.gt_faces.astype(np.float32)
        window = np.ones((13, 13), np.uint8)
        mixed = cv2.dilate(faces, window) != cv2.erode(faces, window)
        masks = {"all": valid, "near another face": valid & mixed & (faces > 0),
                 "face interior": valid & ~mixed & (faces > 0)}
        for method in NORMALS_METHODS:
            normals = normals_from_depth(depth, view.frame.K, method=method)
            has = np.abs(normals).sum(-1) > 0
            cos = np.clip(np.sum(normals * view.gt_normals, axis=-1), -1.0, 1.0)
            angle = np.degrees(np.arccos(cos))
            for name, mask in masks.items():
                errors[method][name].append(angle[mask & has])
    print(f"angular error (degrees), {scenes} scenes at {width}x{height}, mean / median / p90")
    for method, parts in errors.items():
        cells = []
        for name, values in parts.items():
            a = np.concatenate(values)
            cells.append(f"{name} {a.mean():.2f} / {np.median(a):.2f} / "
                         f"{np.percentile(a, 90):.2f}")
        print(f"  {method:6s} " + " | ".join(cells))


def timing(folder: Path, every: int, rounds: int) -> None:
    """Print each method's median wall and CPU time per frame of ``folder``'s depth maps."""
    K = intrinsics_matrix(525.0, 525.0, 319.5, 239.5)
    frames = [cv2.imread(str(p), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
              for p in sorted(folder.glob("*.png"))[::every]]
    for method in NORMALS_METHODS:  # compile or load the kernels outside the timing
        normals_from_depth(frames[0], K, method=method)
    wall: dict[str, list[float]] = {m: [] for m in NORMALS_METHODS}
    cpu: dict[str, list[float]] = {m: [] for m in NORMALS_METHODS}
    for _ in range(rounds):
        for depth in frames:
            for method in NORMALS_METHODS:
                t, c = time.perf_counter(), time.process_time()
                normals_from_depth(depth, K, method=method)
                wall[method].append(time.perf_counter() - t)
                cpu[method].append(time.process_time() - c)
    print(f"time per frame, {len(frames)} frames x {rounds} rounds, median ms")
    for method in NORMALS_METHODS:
        print(f"  {method:6s} wall {np.median(wall[method]) * 1e3:6.1f}  "
              f"CPU {np.median(cpu[method]) * 1e3:6.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=10, help="synthetic scenes (0: none)")
    parser.add_argument("--size", default="640x480", help="synthetic image size WxH")
    parser.add_argument("--depth-dir", type=Path, help="folder of uint16 millimetre depth PNGs")
    parser.add_argument("--every", type=int, default=15, help="time every N-th depth map")
    parser.add_argument("--rounds", type=int, default=5, help="timing rounds")
    args = parser.parse_args()
    if args.scenes:
        width, height = (int(x) for x in args.size.split("x"))
        accuracy(args.scenes, width, height)
    if args.depth_dir is not None:
        timing(args.depth_dir, args.every, args.rounds)


if __name__ == "__main__":
    main()
