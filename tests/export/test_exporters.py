"""The exporter registry: one save() for every result, formats registered through the hook."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monoplane.cli import main
from monoplane.datamodel import Camera, Reconstruction, Scene
from monoplane.errors import ConfigError, InvalidInput, PluginError
from monoplane.export import Exporter, get_exporters, output_files, save
from monoplane.hookspecs import hookimpl
from monoplane.host.detect import detect_planes
from monoplane.host.registry import AUTOLOAD_ENV, get_plugin_manager
from monoplane.testing import CORNER_PLANES, box_frame

HERE = Path(__file__).resolve().parent

#: What ``monoplane run`` wrote for a frame before the formats became plugins.
FRAME_FILES = ("labels.png", "planes.json", "planes.ply", "planes.glb", "depth_planar.npy",
               "config.toml")


def corner() -> Reconstruction:
    frame, labels = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    return Reconstruction(frame=frame, labels=labels, planes=CORNER_PLANES)


def pm_with(*exporters: Exporter, name: str = "extra"):
    class Plugin:
        @hookimpl
        def monoplane_register_exporters(self) -> list[Exporter]:
            return list(exporters)

    pm = get_plugin_manager(autoload=False)
    pm.register(Plugin(), name=name)
    return pm


def files_in(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def test_the_shipped_formats_register_through_the_hook() -> None:
    infos = get_exporters(get_plugin_manager(autoload=False))
    assert [i.exporter.name for i in infos] == ["config", "depth", "gltf", "labels", "ply",
                                                "rerun"]
    assert {i.provider for i in infos} == {"monoplane"}
    assert sorted(output_files("frame")) == sorted(FRAME_FILES)
    assert sorted(output_files("cloud")) == ["config.toml", "labelled.ply", "labels.npy",
                                             "planes.glb", "planes.json", "planes.ply"]
    assert "view_*/depth_planar.npy" in output_files("multiview")
    assert output_files("frame", formats=["rerun"]) == ("recording.rrd",)


def test_save_writes_exactly_the_files_the_formats_state(tmp_path: Path) -> None:
    out = save(corner(), tmp_path / "frame")
    assert files_in(out) == sorted(FRAME_FILES)
    cloud = detect_planes(box_frame(64, 48)[0].points().reshape(-1, 3),
                          overrides=["ransac.max_points=2000"])
    out = save(cloud, tmp_path / "cloud")
    assert files_in(out) == sorted(output_files("cloud"))
    assert json.loads((out / "planes.json").read_text())["num_planes"] == cloud.num_planes
    assert np.array_equal(np.load(out / "labels.npy"), cloud.labels)


def test_formats_are_chosen_by_name_and_checked(tmp_path: Path) -> None:
    rec = corner()
    assert files_in(save(rec, tmp_path / "a", formats=["labels"])) == ["labels.png",
                                                                        "planes.json"]
    with pytest.raises(ConfigError, match="unknown output format 'pdf'; valid formats: config, "
                                          "depth, gltf, labels, ply, rerun"):
        save(rec, tmp_path / "b", formats=["pdf"])
    cloud = detect_planes(box_frame(64, 48)[0].points().reshape(-1, 3))
    with pytest.raises(ConfigError, match="'depth' does not write cloud results"):
        save(cloud, tmp_path / "c", formats=["depth"])
    cam = Camera(K=rec.frame.K, R=np.eye(3), t=np.zeros(3), width=64, height=48)
    scene = Scene(cameras=[cam], views=[rec], planes=rec.planes, links=[{1: 0, 2: 1, 3: 2}])
    for bad in (scene, {"planes": []}):
        with pytest.raises(InvalidInput, match="save: cannot write a"):
            save(bad, tmp_path / "d")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]


def test_a_failing_format_leaves_no_folder_behind(tmp_path: Path) -> None:
    def fail(result, folder, shared) -> None:
        (folder / "half.txt").write_text("half")
        raise RuntimeError("disk full")

    pm = pm_with(Exporter("broken", {"frame": ("half.txt",)}, fail))
    with pytest.raises(RuntimeError, match="disk full"):
        save(corner(), tmp_path / "out", pm=pm)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("exporter, message", [
    ("not an exporter", "is not a monoplane.plugin.Exporter"),
    (Exporter("Bad Name", {"frame": ("x",)}, print), "lower-case words"),
    (Exporter("x", {"scene": ("x",)}, print), "unknown kinds: scene"),
    (Exporter("x", {}, print), "must state the files"),
    (Exporter("x", {"frame": "x.txt"}, print), "non-empty tuple of relative paths"),
    (Exporter("x", {"frame": ("x",)}, None), "no callable write"),  # type: ignore[arg-type]
    (Exporter("ply", {"frame": ("x",)}, print), "'ply' is registered twice"),
])
def test_a_malformed_exporter_is_refused_naming_the_plugin(exporter: object,
                                                           message: str) -> None:
    with pytest.raises(PluginError, match=message):
        get_exporters(pm_with(exporter))  # type: ignore[arg-type]


def test_the_former_writers_still_write_the_same_folder(tmp_path: Path) -> None:
    from monoplane.io.frames import save_reconstruction

    rec = corner()
    with pytest.warns(DeprecationWarning, match="use monoplane.export.save"):
        old = save_reconstruction(rec, tmp_path / "old")
    new = save(rec, tmp_path / "new")
    assert files_in(old) == files_in(new)
    for name in files_in(new):
        assert (old / name).read_bytes() == (new / name).read_bytes(), name
    with pytest.warns(DeprecationWarning, match="monoplane.export.files.check_output_dir"):
        from monoplane.io.frames import check_output_dir  # noqa: F401


@pytest.fixture
def csv_plugin_installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The test plugin installed as a distribution with a ``monoplane`` entry point."""
    site = tmp_path / "site"
    info = site / "monoplane_test_csv-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: monoplane-test-csv\n"
                                   "Version: 0.1\n")
    (info / "entry_points.txt").write_text("[monoplane]\nplanes_csv = csv_exporter_plugin\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.delenv(AUTOLOAD_ENV, raising=False)


def test_a_plugin_format_is_listed_and_written_by_monoplane_run(
        csv_plugin_installed: None, sample_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plugins", "--kind", "exporter"]) == 0
    listing = capsys.readouterr().out
    for name in ("labels", "ply", "gltf", "depth", "rerun"):
        assert f"exporter {name} " in listing
    assert "exporter planes-csv             monoplane-test-csv 0.1" in listing
    out = sample_dir / "out"
    assert main(["run", str(sample_dir / "rgb.png"), "--depth", str(sample_dir / "depth.npy"),
                 "--intrinsics", str(sample_dir / "intrinsics.json"), "--out", str(out),
                 "--quiet"]) == 0
    assert files_in(out) == sorted((*FRAME_FILES, "planes.csv"))
    planes = json.loads((out / "planes.json").read_text())["planes"]
    rows = (out / "planes.csv").read_text().splitlines()
    assert rows[0] == "id,nx,ny,nz,offset,support" and len(rows) == len(planes) + 1
    for row, plane in zip(rows[1:], planes, strict=True):
        values = row.split(",")
        assert int(values[0]) == plane["id"] and int(values[5]) == plane["support"]
        np.testing.assert_allclose([float(v) for v in values[1:5]],
                                   [*plane["normal"], plane["offset"]], atol=1e-6)
    # batch counts a frame done only when the plugin's file is there too
    from monoplane.batch.frame import frame_output_files, is_complete

    frame_output_files.cache_clear()
    try:
        assert "planes.csv" in frame_output_files() and is_complete(out)
        (out / "planes.csv").unlink()
        assert not is_complete(out)
    finally:
        frame_output_files.cache_clear()
