"""2D figures drawn with OpenCV and numpy: label overlays with plane ids, depth comparisons.

Every function returns an RGB uint8 image; nothing here needs OpenGL, so these figures are
always available, including when 3D rendering is not. Small inputs are enlarged (nearest
neighbour for labels) so that text and boundaries stay legible in the report.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from monoplane.report.colors import (
    colorize_depth,
    colormap,
    depth_range,
    label_colors,
)

#: Figures narrower than this are enlarged by an integer factor.
MIN_WIDTH = 480
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_WHITE = (255, 255, 255)
_BLACK = (0, 0, 0)


def save_png(path: Path, rgb: np.ndarray) -> Path:
    """Write an RGB uint8 image as PNG and return its path."""
    path = Path(path)
    params = [cv2.IMWRITE_PNG_COMPRESSION, 6]
    if not cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1]), params):
        raise OSError(f"could not write {path}")
    return path


def load_png(path: Path) -> np.ndarray:
    """Read a PNG written by :func:`save_png` back as RGB uint8."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise OSError(f"could not read {path}")
    return bgr[..., ::-1].copy()


def display_scale(width: int) -> int:
    """Integer enlargement that brings an image of this width to at least :data:`MIN_WIDTH`."""
    return max(1, int(np.ceil(MIN_WIDTH / max(width, 1))))


def enlarge(img: np.ndarray, factor: int, nearest: bool = False) -> np.ndarray:
    """Enlarge an image by an integer factor (nearest neighbour for label-like data)."""
    if factor == 1:
        return img
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.resize(img, None, fx=factor, fy=factor, interpolation=interp)


def grey_image(shape: tuple[int, int]) -> np.ndarray:
    """A mid-grey (H, W, 3) uint8 stand-in for frames without colour."""
    return np.full((*shape, 3), 128, dtype=np.uint8)


def input_image(rgb: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """A frame's (H, W, 3) uint8 colour image, or :func:`grey_image` when it has none
    (``shape`` is ``(H, W)``), enlarged by :func:`display_scale` for a report."""
    image = grey_image(shape) if rgb is None else rgb
    return enlarge(image, display_scale(shape[1]))


def label_anchors(labels: np.ndarray) -> dict[int, tuple[int, int]]:
    """A point deep inside each labelled region, where its id can be written.

    The anchor is the pixel farthest from the region's boundary (maximum of the distance
    transform), which lies inside even for L-shaped or holed regions.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) integer labels, 0 = unlabelled.

    Returns
    -------
    dict
        ``{label: (u, v)}`` pixel column and row, for every label > 0 present.
    """
    out: dict[int, tuple[int, int]] = {}
    padded = np.pad(labels, 1)
    for lab in np.unique(labels):
        if lab <= 0:
            continue
        mask = (padded == lab).astype(np.uint8)
        dist = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
        v, u = np.unravel_index(int(np.argmax(dist)), dist.shape)
        out[int(lab)] = (int(u) - 1, int(v) - 1)
    return out


def draw_text(
    img: np.ndarray, text: str, org: tuple[int, int], scale: float, center: bool = False
) -> None:
    """Write white text with a black outline (readable on any colour), in place.

    ``org`` is the text's bottom-left corner, or its centre when ``center`` is true.
    """
    thick = max(1, int(round(2 * scale)))
    (tw, th), _ = cv2.getTextSize(text, _FONT, scale, thick)
    x, y = org
    if center:
        x, y = x - tw // 2, y + th // 2
    cv2.putText(img, text, (x, y), _FONT, scale, _BLACK, thick + 2 * max(1, thick), cv2.LINE_AA)
    cv2.putText(img, text, (x, y), _FONT, scale, _WHITE, thick, cv2.LINE_AA)


def overlay_labels(
    rgb: np.ndarray | None,
    labels: np.ndarray,
    alpha: float = 0.55,
    ids: bool = True,
    n_planes: int | None = None,
    id_names: dict[int, str] | None = None,
) -> np.ndarray:
    """Plane labels blended over the image, with region outlines and plane ids.

    Parameters
    ----------
    rgb : numpy.ndarray or None
        (H, W, 3) uint8 image; grey when None.
    labels : numpy.ndarray
        (H, W) integer labels, 0 = non-planar (left as the plain image).
    alpha : float
        Weight of the plane colour in the blend.
    ids : bool
        Write each plane's id at a point inside it.
    n_planes : int, optional
        Palette size, so that colours match other figures of the same reconstruction.
    id_names : dict, optional
        Text to write for a label instead of the label itself (e.g. a global plane id).

    Returns
    -------
    numpy.ndarray
        (h, w, 3) uint8 RGB, enlarged by :func:`display_scale`.
    """
    base = grey_image(labels.shape) if rgb is None else rgb
    colours = label_colors(labels, n_planes)
    planar = labels > 0
    out = base.astype(np.float32)
    out[planar] = (1 - alpha) * out[planar] + alpha * colours[planar].astype(np.float32)
    out = out.astype(np.uint8)
    k = display_scale(labels.shape[1])
    out = enlarge(out, k)
    lab = enlarge(labels.astype(np.int32), k, nearest=True)
    edge = np.zeros(lab.shape, dtype=bool)
    edge[:, 1:] |= lab[:, 1:] != lab[:, :-1]
    edge[1:, :] |= lab[1:, :] != lab[:-1, :]
    edge = cv2.dilate(edge.astype(np.uint8), np.ones((2, 2), np.uint8)).astype(bool)
    out[edge] = (out[edge] * 0.3).astype(np.uint8)
    if ids:
        scale = max(0.5, out.shape[1] / 600.0)
        for lab_id, (u, v) in label_anchors(lab).items():
            name = id_names.get(lab_id, lab_id) if id_names else lab_id
            draw_text(out, str(name), (u, v), scale, center=True)
    return out


def label_map(labels: np.ndarray, n_planes: int | None = None) -> np.ndarray:
    """The label map alone in plane colours (non-planar dark), enlarged like the overlays."""
    k = display_scale(labels.shape[1])
    return enlarge(label_colors(labels, n_planes), k, nearest=True)


def colorbar(height: int, vmin: float, vmax: float, units: str, width: int = 90) -> np.ndarray:
    """A vertical turbo colour bar with tick labels (near at the bottom, far at the top).

    Returns
    -------
    numpy.ndarray
        (height, width, 3) uint8 RGB on white.
    """
    bar = np.full((height, width, 3), 255, dtype=np.uint8)
    margin = 22
    ramp = np.linspace(1.0, 0.0, height - 2 * margin)[:, None].repeat(16, axis=1)
    bar[margin : height - margin, 6:22] = colormap(ramp)
    scale = 0.4
    for frac in np.linspace(0.0, 1.0, 5):
        value = vmin + frac * (vmax - vmin)
        y = int(round(height - margin - frac * (height - 2 * margin - 1)))
        cv2.line(bar, (22, y), (27, y), _BLACK, 1)
        cv2.putText(bar, f"{value:.3g}", (30, y + 4), _FONT, scale, _BLACK, 1, cv2.LINE_AA)
    cv2.putText(bar, f"[{units}]", (4, 12), _FONT, scale, _BLACK, 1, cv2.LINE_AA)
    return bar


def titled(img: np.ndarray, title: str) -> np.ndarray:
    """Put a caption strip above an image."""
    strip = np.full((28, img.shape[1], 3), 255, dtype=np.uint8)
    cv2.putText(strip, title, (6, 20), _FONT, 0.55, _BLACK, 1, cv2.LINE_AA)
    return np.vstack([strip, img])


def hstack(images: list[np.ndarray], gap: int = 8) -> np.ndarray:
    """Place images side by side on white, top-aligned, with a gap between them."""
    h = max(im.shape[0] for im in images)
    parts: list[np.ndarray] = []
    for i, im in enumerate(images):
        if i:
            parts.append(np.full((h, gap, 3), 255, dtype=np.uint8))
        pad = np.full((h - im.shape[0], im.shape[1], 3), 255, dtype=np.uint8)
        parts.append(np.vstack([im, pad]))
    return np.hstack(parts)


def depth_comparison(
    depth_in: np.ndarray, depth_planar: np.ndarray, units: str
) -> np.ndarray:
    """Input depth next to planar depth, on one colour scale with a shared colour bar.

    Parameters
    ----------
    depth_in, depth_planar : numpy.ndarray
        (H, W) z-depth in the same units, 0 = invalid / non-planar (drawn black).
    units : str
        Depth unit for the colour bar label.

    Returns
    -------
    numpy.ndarray
        RGB uint8 figure.
    """
    vmin, vmax = depth_range(depth_in, depth_planar)
    k = display_scale(depth_in.shape[1])
    left = enlarge(colorize_depth(depth_in, vmin, vmax), k, nearest=True)
    right = enlarge(colorize_depth(depth_planar, vmin, vmax), k, nearest=True)
    bar = colorbar(left.shape[0], vmin, vmax, units)
    return hstack([titled(left, "input depth"), titled(right, "planar depth"),
                   np.vstack([np.full((28, bar.shape[1], 3), 255, np.uint8), bar])])


def colorized_depth_figure(depth: np.ndarray, units: str) -> np.ndarray:
    """A single depth map in turbo colours with its colour bar."""
    vmin, vmax = depth_range(depth)
    img = enlarge(colorize_depth(depth, vmin, vmax), display_scale(depth.shape[1]), nearest=True)
    return hstack([img, colorbar(img.shape[0], vmin, vmax, units)])


def comparison_row(
    rgb: np.ndarray | None, gt_labels: np.ndarray, pred_labels: np.ndarray, title: str
) -> np.ndarray:
    """An evaluation thumbnail: image, ground-truth labels and predicted labels side by side.

    Each label map is coloured independently (plane ids of prediction and ground truth are not
    matched), with outlines, so over- and under-segmentation are visible at a glance.
    """
    base = grey_image(gt_labels.shape) if rgb is None else rgb
    k = display_scale(gt_labels.shape[1])
    panels = [
        titled(enlarge(base, k), title),
        titled(overlay_labels(rgb, gt_labels, ids=False), "ground truth"),
        titled(overlay_labels(rgb, pred_labels, ids=False), "prediction"),
    ]
    return hstack(panels)


def contact_sheet(panels: list[tuple[np.ndarray, str]], columns: int = 3,
                  width: int = 420) -> np.ndarray:
    """Captioned panels of equal width in a grid: one picture that summarises a report.

    Parameters
    ----------
    panels : list of (image, caption)
        RGB uint8 images of any size; each is scaled to ``width`` pixels wide.
    columns : int
        Panels per row.
    width : int
        Panel width in pixels.

    Returns
    -------
    numpy.ndarray
        RGB uint8 sheet on white.
    """
    cells = []
    for img, caption in panels:
        h = max(1, int(round(img.shape[0] * width / img.shape[1])))
        cells.append(titled(cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA), caption))
    rows = [hstack(cells[i : i + columns]) for i in range(0, len(cells), columns)]
    full = max(r.shape[1] for r in rows)
    gap = np.full((8, full, 3), 255, dtype=np.uint8)
    padded = [np.hstack([r, np.full((r.shape[0], full - r.shape[1], 3), 255, np.uint8)])
              for r in rows]
    out: list[np.ndarray] = []
    for i, r in enumerate(padded):
        out += [gap, r] if i else [r]
    return np.vstack(out)
