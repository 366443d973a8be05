"""Write synthetic views and scenes to disk in the CLI's input layout plus ground truth.

Each view folder holds the CLI's inputs (``rgb.png``, ``depth.npy``, ``normals.npy``,
``intrinsics.json``) and ground truth (``gt_labels.png``, ``gt_planes.json``, ``gt_depth.npy``).
A multi-view scene adds ``cameras.json`` with the ground-truth cameras, world planes and
view-to-global plane links.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from monoplane.errors import InvalidInput
from monoplane.synth.generator import SynthScene, SynthView


def _intrinsics(K: np.ndarray) -> dict[str, float]:
    return {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]),
            "cy": float(K[1, 2])}


def write_sample(view: SynthView, out_dir: Path) -> None:
    """Write one view's cues and ground truth.

    Files: ``rgb.png`` (8-bit RGB), ``depth.npy`` ((H, W) float32 corrupted depth),
    ``normals.npy`` ((H, W, 3) float16 corrupted unit normals, camera frame; half precision
    keeps the files small and is far below the corruption noise), ``intrinsics.json``
    (``{"fx", "fy", "cx", "cy"}``), ``gt_labels.png`` ((H, W) uint16, 0 = non-planar),
    ``gt_planes.json`` (camera-frame planes in metres, facing the camera, ``id`` = label) and
    ``gt_depth.npy`` ((H, W) float32 metres).

    Parameters
    ----------
    view : SynthView
    out_dir : pathlib.Path
        Created if missing; existing files of the same names are overwritten.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frame = view.frame
    if frame.rgb is None or frame.depth is None or frame.normals is None:
        raise InvalidInput(f"{frame.name}: a sample needs rgb, depth and normals")
    cv2.imwrite(str(out / "rgb.png"), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR),
                [cv2.IMWRITE_PNG_COMPRESSION, 9])
    np.save(out / "depth.npy", frame.depth.astype(np.float32))
    np.save(out / "normals.npy", frame.normals.astype(np.float16))
    np.save(out / "gt_depth.npy", view.gt_depth.astype(np.float32))
    cv2.imwrite(str(out / "gt_labels.png"), view.gt_labels.astype(np.uint16),
                [cv2.IMWRITE_PNG_COMPRESSION, 9])
    (out / "intrinsics.json").write_text(json.dumps(_intrinsics(frame.K), indent=2) + "\n")
    area = np.bincount(view.gt_labels.ravel(), minlength=len(view.gt_params) + 1)[1:]
    planes = [
        {"id": i + 1, "normal": [float(x) for x in p[:3]], "offset": float(p[3]),
         "area_px": int(a)}
        for i, (p, a) in enumerate(zip(view.gt_params, area, strict=True))
    ]
    gt = {
        "planes": planes,
        "intrinsics": _intrinsics(frame.K),
        "depth_units": "m",
        "cue_depth_kind": frame.depth_kind,
        "cue_depth_scale": view.scale,
        "notes": frame.notes,
    }
    (out / "gt_planes.json").write_text(json.dumps(gt, indent=2) + "\n")


def write_scene(scene: SynthScene, out_dir: Path) -> None:
    """Write every view of a scene to ``out_dir/view<i>`` and, for several views,
    ``out_dir/cameras.json``: ``{"views": [{"name", "width", "height", "K", "R", "t"}],
    "gt_planes_world", "view_to_global"}`` (world-to-camera ``x_cam = R x_world + t``, metres;
    ``view_to_global[v]`` maps a view's label, as a string key, to a row of the world planes).
    A single-view scene is written flat into ``out_dir``.
    """
    out = Path(out_dir)
    if len(scene.views) == 1:
        write_sample(scene.views[0], out)
        return
    cams = []
    for v, view in enumerate(scene.views):
        write_sample(view, out / f"view{v}")
        cams.append({"name": f"view{v}", "width": view.frame.width,
                     "height": view.frame.height, "K": view.frame.K.tolist(),
                     "R": view.R.tolist(), "t": view.t.tolist()})
    meta = {
        "seed": scene.seed,
        "level": scene.level,
        "views": cams,
        "gt_planes_world": scene.gt_planes_world.tolist(),
        "view_to_global": [{str(k): g for k, g in links.items()}
                           for links in scene.view_to_global],
    }
    (out / "cameras.json").write_text(json.dumps(meta, indent=2) + "\n")
