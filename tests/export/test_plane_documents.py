"""planes.json and scene.json: one builder, told the result's kind by the result model."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.datamodel import Camera, CloudResult, Reconstruction, Scene
from monoplane.errors import InvalidInput
from monoplane.export.labels import planes_document
from monoplane.testing import CORNER_PLANES, box_frame


def corner() -> Reconstruction:
    frame, labels = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    return Reconstruction(frame=frame, labels=labels, planes=CORNER_PLANES,
                          rmse=np.full(len(CORNER_PLANES), 0.5), timings={"ransac": 0.123456})


def test_a_frame_document_lists_each_plane_with_its_label_value_and_statistics() -> None:
    rec = corner()
    doc = planes_document(rec)
    assert [p["id"] for p in doc["planes"]] == [1, 2, 3]
    for p, plane, area in zip(doc["planes"], rec.planes, rec.area_px, strict=True):
        assert list(p) == ["id", "normal", "offset", "area_px", "rmse", "support", "color"]
        assert p["normal"] == plane[:3].tolist() and p["offset"] == plane[3]
        assert p["area_px"] == p["support"] == area and p["rmse"] == 0.5
    assert doc["timings_s"] == {"ransac": 0.1235}
    assert doc["intrinsics"]["width"] == 64 and doc["depth_kind"] == "metric"


def test_a_cloud_document_counts_points_and_names_its_source() -> None:
    points = np.array([[0, 0, 1.0], [1, 0, 1], [0, 1, 1], [5, 5, 5]])
    cloud = CloudResult(points, [1, 1, 1, 0], [[0, 0, 1, -1.0]], [0.0],
                        centroids=[[1 / 3, 1 / 3, 1]], source="scan.ply")
    doc = planes_document(cloud)
    assert list(doc)[:3] == ["source", "num_points", "num_planes"]
    assert doc["source"] == "scan.ply" and doc["num_points"] == 4
    assert doc["planes"] == [{"id": 1, "normal": [0.0, 0.0, 1.0], "offset": -1.0,
                              "num_points": 3, "rmse": 0.0, "centroid": [1 / 3, 1 / 3, 1.0]}]
    cloud.source = ""
    assert "source" not in planes_document(cloud)


def test_a_bare_scene_or_any_other_object_has_no_plane_document() -> None:
    rec = corner()
    cam = Camera(K=rec.frame.K, R=np.eye(3), t=np.zeros(3), width=64, height=48)
    scene = Scene(cameras=[cam], views=[rec], planes=rec.planes, links=[{1: 0, 2: 1, 3: 2}])
    with pytest.raises(InvalidInput, match="kind 'scene'"):
        planes_document(scene)
    with pytest.raises(InvalidInput, match="no plane document for a dict"):
        planes_document({"planes": []})
