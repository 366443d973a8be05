"""Point cloud readers on arbitrary files: a checked cloud or one line naming the file, with
nothing printed by any library (captured at the file descriptors) and no numpy warning.

Files are drawn as random bytes, or as well-formed files of every format and variant (written by
Open3D from drawn points, NaN, inf and huge values included) that are then cut short, have a
byte changed, or have their header's first count replaced.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from monoplane.errors import InvalidInput
from monoplane.host.detect import detect_planes
from monoplane.io.checks import MAX_MAGNITUDE
from monoplane.io.clouds import SUFFIXES, _lzf_decompress, read_point_cloud

#: (suffix, keyword arguments of open3d.io.write_point_cloud) of every variant written.
_VARIANTS = [(".ply", {}), (".ply", {"write_ascii": True}), (".pcd", {}),
             (".pcd", {"write_ascii": True}), (".pcd", {"compressed": True}), (".xyz", {}),
             (".xyzn", {}), (".xyzrgb", {}), (".pts", {})]

_COORDS = st.one_of(st.floats(-10, 10), st.sampled_from([np.nan, np.inf, -np.inf, 1e300,
                                                          -3e38, 1e-300, 0.0]))


@st.composite
def cloud_files(draw: st.DrawFn, folder: Path) -> Path:
    """A damaged or intact cloud file in ``folder``."""
    if draw(st.integers(0, 4)) == 0:
        path = folder / f"random{draw(st.sampled_from(SUFFIXES))}"
        path.write_bytes(draw(st.binary(max_size=300)))
        return path
    suffix, kwargs = draw(st.sampled_from(_VARIANTS))
    n = draw(st.integers(0, 30))
    points = draw(hnp.arrays(np.float64, (n, 3), elements=_COORDS))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if draw(st.booleans()):
        pcd.normals = o3d.utility.Vector3dVector(draw(hnp.arrays(np.float64, (n, 3),
                                                                 elements=_COORDS)))
    if draw(st.booleans()):
        pcd.colors = o3d.utility.Vector3dVector(draw(hnp.arrays(np.float64, (n, 3),
                                                                elements=st.floats(0, 1))))
    path = folder / f"cloud{suffix}"
    path.unlink(missing_ok=True)
    # Open3D writes no file for an empty cloud in some formats: then the file is empty.
    data = path.read_bytes() if o3d.io.write_point_cloud(str(path), pcd, **kwargs) else b""
    damage = draw(st.sampled_from(["none", "cut", "byte", "count"]))
    if damage == "cut" and data:
        data = data[:draw(st.integers(0, len(data) - 1))]
    elif damage == "byte" and data:
        at = draw(st.integers(0, len(data) - 1))
        data = data[:at] + bytes([draw(st.integers(0, 255))]) + data[at + 1:]
    elif damage == "count":
        data = re.sub(rb"\d+", str(draw(st.integers(0, 10**6))).encode(), data, count=1)
    path.write_bytes(data)
    return path


def test_cloud_readers(fuzz, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    @fuzz
    @given(st.data())
    def check(data: st.DataObject) -> None:
        path = data.draw(cloud_files(tmp_path))
        capfd.readouterr()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                cloud = read_point_cloud(path)
            except InvalidInput as exc:
                msg = str(exc)
                assert msg.startswith(f"point cloud {path}") and "\n" not in msg, msg
                cloud = None
        assert capfd.readouterr() == ("", "")
        if cloud is None:
            return
        n = len(cloud.points)
        assert cloud.points.shape == (n, 3) and cloud.points.dtype == np.float64
        finite = np.isfinite(cloud.points).all(axis=1)
        assert finite.sum() >= 3 and np.abs(cloud.points[finite]).max() <= MAX_MAGNITUDE
        for extra in (cloud.normals, cloud.colors):
            assert extra is None or extra.shape == (n, 3)

    check()


def test_lzf_decoder_on_any_bytes(fuzz) -> None:
    @fuzz
    @given(st.binary(max_size=200), st.integers(0, 400))
    def check(src: bytes, size: int) -> None:
        out = _lzf_decompress(src, size)
        assert out is None or len(out) == size

    check()


def test_detect_planes_on_any_values(fuzz, capfd: pytest.CaptureFixture[str]) -> None:
    """What a file may hold reaches detect_planes: a result or one line, never a warning."""
    @fuzz
    @given(hnp.arrays(np.float64, st.tuples(st.integers(0, 40), st.just(3)), elements=_COORDS),
           st.booleans())
    def check(points: np.ndarray, with_normals: bool) -> None:
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        if with_normals:
            pcd.normals = o3d.utility.Vector3dVector(points[::-1].copy())
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                res = detect_planes(pcd)
            except InvalidInput as exc:
                assert "\n" not in str(exc)
                return
        assert res.labels.shape == (len(points),)
        assert np.isfinite(res.planes).all()

    check()
    assert capfd.readouterr() == ("", "")
