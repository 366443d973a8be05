"""The point cloud readers on files a damaged disk or a fuzzer makes."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.io.clouds import read_point_cloud

#: A float32 signalling NaN: exponent all ones, quiet bit clear, payload non-zero.
SIGNALLING_NAN = np.array([0x7FA00000], dtype=np.uint32).view(np.float32)[0]


def _binary_pcd(path: Path, xyz: np.ndarray) -> Path:
    header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
              f"WIDTH {len(xyz)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(xyz)}\n"
              "DATA binary\n")
    path.write_bytes(header.encode() + xyz.astype("<f4").tobytes())
    return path


def test_signalling_nans_are_dropped_like_any_non_finite_point(tmp_path: Path) -> None:
    xyz = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1], [0, 0, 0]], np.float32)
    xyz[4] = SIGNALLING_NAN
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NumPy reports casting a signalling NaN as invalid
        cloud = read_point_cloud(_binary_pcd(tmp_path / "snan.pcd", xyz))
    assert cloud.points.shape == (5, 3) and cloud.points.dtype == np.float64
    np.testing.assert_array_equal(cloud.points[:4], xyz[:4])
    assert np.isnan(cloud.points[4]).all()


def test_a_cloud_of_signalling_nans_is_a_one_line_error(tmp_path: Path) -> None:
    xyz = np.full((4, 3), SIGNALLING_NAN, np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InvalidInput, match=r"snan\.pcd: it holds 0 finite point\(s\) of 4"):
            read_point_cloud(_binary_pcd(tmp_path / "snan.pcd", xyz))
