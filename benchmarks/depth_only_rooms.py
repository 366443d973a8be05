"""Score presets on depth-only sensor frames of synthetic rooms.

``monoplane eval`` scores the synthetic rooms with their monocular-like cues (depth and normals
as a network would give them). A depth sensor gives neither colour nor normals but metric depth
with its own noise, so this renders each room's exact depth, adds a Kinect-like noise (σ =
0.0015 z² metres) and millimetre steps, and runs each preset on that depth alone (normals
estimated from it), as on a robot. Prints VOI, RI and SC against the rooms' ground-truth planes
and the wall time a frame, means over the rooms. Usage::

    python3 benchmarks/depth_only_rooms.py --preset rgbd-fast --preset monoplane-nocrf \\
        --size 640x480 --n 8 [--set labeler.normal_gate_deg=20]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from monoplane import Pipeline
from monoplane.evaluation.segmentation import segmentation_scores

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_rgbd_fast import sensor_frame  # noqa: E402  (the test module is not a package)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", action="append", required=True, help="repeatable")
    parser.add_argument("--size", default="320x240", help="WIDTHxHEIGHT (default 320x240)")
    parser.add_argument("--n", type=int, default=4, help="rooms 0 .. N-1 (default 4)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="config override of every preset (repeatable)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    # The CLI's --set strings, read as it reads them (TOML: 20 is an int, grid a string).
    pipes = {name: Pipeline.from_preset(name, overrides=args.set) for name in args.preset}
    rows: dict[str, list[tuple[float, float, float, float]]] = {name: [] for name in pipes}
    for seed in range(args.n):
        frame, truth = sensor_frame(seed, width, height)
        for name, pipe in pipes.items():
            start = time.perf_counter()
            labels = pipe.run(frame).labels
            seconds = time.perf_counter() - start
            s = segmentation_scores(labels, truth)
            rows[name].append((s.voi, s.ri, s.sc, seconds * 1000.0))
    print(f"{args.n} rooms, {width}x{height}, depth only (Kinect-like noise, mm steps)")
    print(f"{'preset':18s} {'VOI':>6s} {'RI':>6s} {'SC':>6s} {'ms':>7s}  VOI per room")
    for name, values in rows.items():
        a = np.array(values)
        voi, ri, sc, ms = a.mean(0)
        per_room = " ".join(f"{v:.2f}" for v in a[:, 0])
        print(f"{name:18s} {voi:6.3f} {ri:6.3f} {sc:6.3f} {ms:7.1f}  {per_room}")


if __name__ == "__main__":
    main()
