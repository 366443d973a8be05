"""A posed RGB-D sequence on disk, and its frames as the product sees them in each mode.

The layout (a Redwood-format RGB-D capture, e.g. the ICL-NUIM living room) and the modes are
those of :mod:`monoplane.evaluation.posed_sequences`: ``rgbd`` gives a view its metric depth,
``mono`` / ``mono-depth`` a monocular-like corruption of it (with / without the network's
normals), ``network`` the image alone.

Frames: cameras world-to-camera ``x_cam = R x_world + t`` (OpenCV axes), metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput
from monoplane.geometry.normals import normals_from_depth
from monoplane.io.depth_encodings import check_depth_encoding
from monoplane.io.frames import load_frame, read_depth, read_intrinsics, read_redwood_log
from monoplane.synth.corrupt import LEVEL_PARAMS, corrupt_depth, corrupt_normals

#: What each view gets (:mod:`monoplane.evaluation.posed_sequences`, step 3).
MODES: tuple[str, ...] = ("rgbd", "mono", "mono-depth", "network")
#: ``--mode`` values that run several modes; ``both`` is the deprecated name of rgbd + mono.
MODE_GROUPS: dict[str, tuple[str, ...]] = {"all": ("rgbd", "mono", "mono-depth"),
                                           "both": ("rgbd", "mono")}
#: Corruption levels of the monocular modes (:data:`monoplane.synth.corrupt.LEVEL_PARAMS`).
LEVELS: tuple[str, ...] = ("mild", "strong")
#: Modes whose depth is the corrupted sensor depth.
MONOCULAR_MODES: tuple[str, ...] = ("mono", "mono-depth")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
DEPTH_SUFFIXES = (".png", ".npy")


@dataclass
class PosedSequence:
    """A posed RGB-D sequence on disk.

    Attributes
    ----------
    root : Path
        The folder.
    ids : numpy.ndarray
        (N,) int64 frame ids of the trajectory, in its order.
    images, depths : list of Path
        Per trajectory entry, its colour image and depth file.
    R : numpy.ndarray
        (N, 3, 3) float64 world-to-camera rotations (``x_cam = R x_world + t``, OpenCV axes).
    t : numpy.ndarray
        (N, 3) float64 world-to-camera translations, metres.
    K : numpy.ndarray
        (3, 3) float64 intrinsics in pixels, shared by all frames.
    depth_scale : float
        Divisor of the depth files' values (1000 for millimetre PNGs) in the ``scaled``
        encoding.
    depth_encoding : str
        How the depth files hold depth (:func:`monoplane.io.frames.read_depth`).
    """

    root: Path
    ids: np.ndarray
    images: list[Path]
    depths: list[Path]
    R: np.ndarray
    t: np.ndarray
    K: np.ndarray
    depth_scale: float
    depth_encoding: str = "scaled"

    def __len__(self) -> int:
        return len(self.ids)

    def position(self, frame_id: int) -> int:
        """Index into the trajectory of ``frame_id``."""
        hits = np.flatnonzero(self.ids == frame_id)
        if not hits.size:
            raise InvalidInput(f"frame {frame_id} is not in {self.root / 'trajectory.log'}")
        return int(hits[0])

    def depth(self, k: int) -> np.ndarray:
        """(H, W) float32 metric depth of trajectory entry ``k``, 0 = no measurement."""
        scaled = self.depth_encoding == "scaled"
        return read_depth(self.depths[k], self.depth_scale if scaled else None,
                          depth_encoding=self.depth_encoding)


def sequence_intrinsics(data_dir: str | Path, intrinsics: str | Path | np.ndarray | None
                        ) -> np.ndarray:
    """(3, 3) intrinsics: ``intrinsics`` (``"fx,fy,cx,cy"``, a JSON file or a matrix), else
    ``data_dir/intrinsics.json``.

    Raises
    ------
    InvalidInput
        When neither is there.
    """
    if intrinsics is None:
        fallback = Path(data_dir) / "intrinsics.json"
        if not fallback.is_file():
            raise InvalidInput(f"--data {data_dir} has no intrinsics.json; pass --intrinsics "
                               "fx,fy,cx,cy or a K.json")
        return read_intrinsics(fallback)
    if isinstance(intrinsics, np.ndarray):
        K = np.asarray(intrinsics, dtype=np.float64)
        if K.shape != (3, 3):
            raise InvalidInput(f"intrinsics must be a 3x3 matrix, got shape {K.shape}")
        return K
    return read_intrinsics(intrinsics)


def _listing(folder: Path, suffixes: tuple[str, ...], what: str) -> list[Path]:
    if not folder.is_dir():
        raise InvalidInput(f"{folder} is missing: a posed sequence keeps its {what} there")
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in suffixes)
    if not files:
        raise InvalidInput(f"{folder} holds no {what} ({', '.join(suffixes)})")
    return files


def load_posed_sequence(data_dir: str | Path, intrinsics: str | Path | np.ndarray | None = None,
                        depth_scale: float = 1000.0,
                        depth_encoding: str = "scaled") -> PosedSequence:
    """Read a sequence's layout and trajectory (images and depth are read when needed).

    Parameters
    ----------
    data_dir : str or Path
        Folder with ``image/``, ``depth/`` and ``trajectory.log`` (module docstring).
    intrinsics : str, Path or numpy.ndarray, optional
        See :func:`sequence_intrinsics`.
    depth_scale : float
        Divisor of the depth values (1000 for millimetres) in the ``scaled`` encoding.
    depth_encoding : str
        ``"scaled"`` or a dataset's own encoding (``"tum"``, ``"sun-rotated"``,
        ``"kinect-disparity"``; :mod:`monoplane.io.depth_encodings`).

    Raises
    ------
    InvalidInput
        Naming the missing or inconsistent file or folder.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise InvalidInput(f"--data {root} is not a folder")
    if not depth_scale > 0:
        raise InvalidInput(f"--depth-scale must be positive, got {depth_scale}")
    check_depth_encoding(depth_encoding, None, "--depth-encoding")
    K = sequence_intrinsics(root, intrinsics)
    images = _listing(root / "image", IMAGE_SUFFIXES, "colour images")
    depths = _listing(root / "depth", DEPTH_SUFFIXES, "depth maps")
    if len(images) != len(depths):
        raise InvalidInput(f"{root}: {len(images)} images but {len(depths)} depth maps")
    ids, c2w = read_redwood_log(root / "trajectory.log")
    out = ids[(ids < 0) | (ids >= len(images))]
    if out.size:
        raise InvalidInput(f"{root / 'trajectory.log'}: frame {out[0]} has no image "
                           f"({len(images)} in {root / 'image'})")
    R = np.transpose(c2w[:, :3, :3], (0, 2, 1))
    t = -np.einsum("nij,nj->ni", R, c2w[:, :3, 3])
    return PosedSequence(root=root, ids=ids, images=[images[i] for i in ids],
                         depths=[depths[i] for i in ids], R=R, t=t, K=K,
                         depth_scale=float(depth_scale), depth_encoding=depth_encoding)


def mode_list(mode: str) -> list[str]:
    """The modes ``--mode`` runs: one of :data:`MODES` or a group of :data:`MODE_GROUPS`.

    Raises
    ------
    InvalidInput
        On an unknown name, listing the valid ones.
    """
    if mode in MODE_GROUPS:
        return list(MODE_GROUPS[mode])
    if mode not in MODES:
        raise InvalidInput(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}, all")
    return [mode]


def check_level(level: str) -> None:
    """Raise :class:`InvalidInput` unless ``level`` is one of :data:`LEVELS`."""
    if level not in LEVELS:
        raise InvalidInput(f"unknown corruption level {level!r} for a posed sequence; choose "
                           f"one of {', '.join(LEVELS)} (the sensor depth itself is --mode rgbd)")


def monocular_cues(depth: np.ndarray, K: np.ndarray, level: str, rng: np.random.Generator,
                   with_normals: bool) -> tuple[np.ndarray, np.ndarray | None, float]:
    """Cues as a monocular network might give them, from a view's sensor depth.

    The depth goes through :func:`monoplane.synth.corrupt.corrupt_depth` at ``level``. With
    ``with_normals`` the network's normals are the project's estimator
    (:func:`~monoplane.geometry.normals.normals_from_depth`, default window) on the *true*
    depth, then :func:`~monoplane.synth.corrupt.corrupt_normals`: a network's normals do not
    inherit its depth's warp, but are blurred across creases, a few degrees off and noisy.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) metric z-depth, 0 = no measurement (stays 0, and has no normal).
    K : numpy.ndarray
        (3, 3) intrinsics in pixels.
    level : {"mild", "strong"}
        Corruption level (:data:`monoplane.synth.corrupt.LEVEL_PARAMS`).
    rng : numpy.random.Generator
        Source of every draw: the depth's first, then the normals', so a frame's depth is the
        same with and without normals.
    with_normals : bool
        Also return the network's normals.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray or None, float)
        (H, W) float32 relative depth, (H, W, 3) float32 unit normals in the camera frame
        (OpenCV axes, facing the camera, zero where there is none) or None, and the unknown
        scale drawn.
    """
    check_level(level)
    params = LEVEL_PARAMS[level]
    corrupted, scale = corrupt_depth(depth, params, rng)
    if not with_normals:
        return corrupted, None, scale
    # Stands in for a network's normals, so the gated fit on purpose (not the cue stage's
    # "auto", which would pick box on this metric depth): the tables were measured with it.
    clean = normals_from_depth(depth, K)
    normals = corrupt_normals(np.where((depth > 0)[..., None], clean, 0.0), K, params, rng)
    return corrupted, normals, scale


def sequence_frame(seq: PosedSequence, k: int, mode: str, seed: int = 0,
                   level: str = "mild") -> Frame:
    """Trajectory entry ``k`` as the ``monoplane multiview`` command line would load it.

    ``rgbd``: its metric depth; ``mono`` / ``mono-depth``: :func:`monocular_cues` at
    ``level`` with / without the network's normals, drawn from the generator seeded by
    ``(seed, frame id)`` (so a frame looks the same in every set, and has the same depth in
    both modes), marked relative; ``network``: the image alone. Normals not given are left to
    the cue provider.
    """
    if mode not in MODES:
        raise InvalidInput(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    # As --intrinsics text; repr() of a float reads back to the same float.
    spec = ",".join(repr(float(x)) for x in (seq.K[0, 0], seq.K[1, 1], seq.K[0, 2], seq.K[1, 2]))
    if mode == "network":
        return load_frame(seq.images[k], intrinsics=spec)
    monocular = mode in MONOCULAR_MODES
    frame = load_frame(seq.images[k], depth=seq.depths[k], intrinsics=spec,
                       depth_scale=seq.depth_scale,
                       depth_kind="relative" if monocular else "metric")
    if not monocular:
        return frame
    rng = np.random.default_rng([seed, int(seq.ids[k])])
    depth, normals, scale = monocular_cues(frame.depth, frame.K, level,  # type: ignore[arg-type]
                                           rng, with_normals=mode == "mono")
    p = LEVEL_PARAMS[level]
    notes = [*frame.notes, f"evaluation: {level} monocular-like depth (unknown scale "
                           f"{scale:.3g}, warp up to {100 * p.warp:.0f} % in log-depth, edges "
                           f"blurred, {100 * p.depth_noise:.1f} % noise)"]
    if normals is not None:
        notes.append(f"evaluation: {level} network-like normals (from the true depth, blurred, "
                     f"turned by up to {p.normal_rotation_deg:g} deg, noisy)")
    return frame.with_(depth=depth, normals=normals, notes=notes)
