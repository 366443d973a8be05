"""Procedural surface textures (albedo) evaluated at metric texture coordinates.

Every surface gets a random pattern (checker, stripes, tiles, dots, wood grain or marble) in two
or three colours, overlaid with fine value noise. Patterns live in surface coordinates (metres),
so the same surface point has the same albedo in every view, which is what SIFT matching across
views relies on; the fine noise gives corners at several scales on every surface.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

PATTERNS: tuple[str, ...] = ("checker", "stripes", "tiles", "dots", "grain", "marble")
_ROLE_PATTERNS: dict[str, tuple[str, ...]] = {
    "floor": ("checker", "tiles", "grain", "marble"),
    "ceiling": ("tiles", "marble", "dots"),
    "wall": ("stripes", "dots", "tiles", "marble", "grain"),
    "panel": PATTERNS,
    "object": PATTERNS,
}
# Pattern period range (m) per role: room surfaces are large, objects small.
_ROLE_SCALE: dict[str, tuple[float, float]] = {
    "floor": (0.25, 0.6), "ceiling": (0.3, 0.7), "wall": (0.15, 0.45),
    "panel": (0.06, 0.2), "object": (0.04, 0.15),
}
_LATTICE = 64


@dataclass
class Material:
    """A procedural albedo.

    Attributes
    ----------
    pattern : str
        One of :data:`PATTERNS`.
    colors : numpy.ndarray
        (3, 3) float64 RGB colours in [0, 1]: two pattern colours and an accent (grout, dots).
    scale : float
        Pattern period in metres.
    angle : float
        Rotation of the pattern in its surface, radians.
    detail : float
        Relative amplitude of the fine noise overlay.
    lattice : numpy.ndarray
        (64, 64) float64 uniform [0, 1] values: the value-noise lattice (wrapped) and per-tile
        colour jitter.
    """

    pattern: str
    colors: np.ndarray
    scale: float
    angle: float
    detail: float
    lattice: np.ndarray

    def albedo(self, uv: np.ndarray) -> np.ndarray:
        """Albedo at texture coordinates.

        Parameters
        ----------
        uv : numpy.ndarray
            (N, 2) float64 surface coordinates in metres.

        Returns
        -------
        numpy.ndarray
            (N, 3) float64 RGB in [0, 1].
        """
        ca, sa = np.cos(self.angle), np.sin(self.angle)
        u = (ca * uv[:, 0] - sa * uv[:, 1]) / self.scale
        v = (sa * uv[:, 0] + ca * uv[:, 1]) / self.scale
        c0, c1, c2 = self.colors
        lat = self.lattice
        if self.pattern == "checker":
            t = np.mod(np.floor(u) + np.floor(v), 2.0)
            col = _mix(c0, c1, t)
        elif self.pattern == "stripes":
            t = (np.mod(u, 1.0) < 0.35).astype(np.float64)
            thin = (np.abs(np.mod(u, 1.0) - 0.7) < 0.04).astype(np.float64)
            col = _mix(_mix(c0, c1, t), c2, thin)
        elif self.pattern == "tiles":
            iu, iv = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
            jitter = lat[iu % _LATTICE, iv % _LATTICE]
            grout = ((np.mod(u, 1.0) < 0.05) | (np.mod(v, 1.0) < 0.05)).astype(np.float64)
            col = _mix(_mix(c0, c1, jitter), c2, grout)
        elif self.pattern == "dots":
            iu, iv = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
            ju = lat[iu % _LATTICE, iv % _LATTICE] - 0.5
            jv = lat[(iu + 17) % _LATTICE, (iv + 31) % _LATTICE] - 0.5
            du = np.mod(u, 1.0) - 0.5 - 0.4 * ju
            dv = np.mod(v, 1.0) - 0.5 - 0.4 * jv
            radius = 0.12 + 0.15 * lat[(iu + 5) % _LATTICE, (iv + 11) % _LATTICE]
            dot = (np.hypot(du, dv) < radius).astype(np.float64)
            col = _mix(_mix(c0, c1, _fbm(lat, u, v, 2)), c2, dot)
        elif self.pattern == "grain":
            warp = _fbm(lat, 0.5 * u, 3.0 * v, 3)
            t = 0.5 + 0.5 * np.sin(2 * np.pi * (1.5 * u + 3.0 * warp))
            col = _mix(c0, c1, t)
        else:  # marble
            t = np.clip((_fbm(lat, u, v, 4) - 0.5) * 3.0 + 0.5, 0.0, 1.0)
            vein = (np.abs(np.sin(2 * np.pi * (u + 3.0 * _fbm(lat, 0.7 * u, 0.7 * v, 3))))
                    < 0.08).astype(np.float64)
            col = _mix(_mix(c0, c1, t), c2, vein)
        fine = _fbm(lat, 9.0 * u + 7.3, 9.0 * v + 1.9, 2) - 0.5
        return np.clip(col * (1.0 + 2.0 * self.detail * fine)[:, None], 0.0, 1.0)


def _mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 3) colours ``(1 - t) a + t b`` for per-point weights ``t`` (N,)."""
    t = np.asarray(t, dtype=np.float64)[:, None]
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return a * (1.0 - t) + b * t


def _value_noise(lat: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Smoothly interpolated lattice noise in [0, 1], periodic with the lattice size."""
    xi, yi = np.floor(x), np.floor(y)
    fx, fy = x - xi, y - yi
    fx = fx * fx * (3.0 - 2.0 * fx)
    fy = fy * fy * (3.0 - 2.0 * fy)
    x0 = xi.astype(np.int64) % _LATTICE
    y0 = yi.astype(np.int64) % _LATTICE
    x1 = (x0 + 1) % _LATTICE
    y1 = (y0 + 1) % _LATTICE
    top = lat[x0, y0] * (1 - fx) + lat[x1, y0] * fx
    bot = lat[x0, y1] * (1 - fx) + lat[x1, y1] * fx
    return top * (1 - fy) + bot * fy


def _fbm(lat: np.ndarray, x: np.ndarray, y: np.ndarray, octaves: int) -> np.ndarray:
    """Fractal sum of value noise, normalised to [0, 1]."""
    total = np.zeros_like(x)
    amp, norm = 1.0, 0.0
    for k in range(octaves):
        f = 2.0**k
        total += amp * _value_noise(lat, f * x + 13.7 * k, f * y - 5.1 * k)
        norm += amp
        amp *= 0.5
    return total / norm


def _random_color(rng: np.random.Generator, value: tuple[float, float]) -> np.ndarray:
    h = rng.uniform()
    s = rng.uniform(0.1, 0.6)
    v = rng.uniform(*value)
    return np.array(colorsys.hsv_to_rgb(h, s, v))


def random_material(rng: np.random.Generator, role: str) -> Material:
    """Draw a material suited to a surface role.

    Parameters
    ----------
    rng : numpy.random.Generator
    role : {"floor", "ceiling", "wall", "panel", "object"}

    Returns
    -------
    Material
    """
    patterns = _ROLE_PATTERNS[role]
    pattern = patterns[int(rng.integers(len(patterns)))]
    light_first = rng.uniform() < 0.5
    bright, dark = (0.6, 0.95), (0.25, 0.55)
    c0 = _random_color(rng, bright if light_first else dark)
    c1 = _random_color(rng, dark if light_first else bright)
    c2 = _random_color(rng, (0.1, 0.95))
    return Material(
        pattern=pattern,
        colors=np.stack([c0, c1, c2]),
        scale=float(rng.uniform(*_ROLE_SCALE[role])),
        angle=float(rng.uniform(0, np.pi)),
        detail=float(rng.uniform(0.12, 0.3)),
        lattice=rng.uniform(size=(_LATTICE, _LATTICE)),
    )
