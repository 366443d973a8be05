"""The reports' interactive 3D view in a real browser: headless Chromium opens ``report.html``
from a ``file://`` URL with the network cut off, and the viewer must show the embedded ``.glb``
in its canvas without a console message.

The page's own script writes the outcome into the DOM (``data-status`` of the status line, see
monoplane/report/viewer.py), which ``--dump-dom`` prints once the scripts have run; Chromium's
``--enable-logging=stderr`` prints every console message of the page, which must be none.

CI installs Chromium (Debian package ``chromium``, see setup.sh); on a machine without it these
tests skip, and under CI they fail instead.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from report_fixtures import make_scene

from monoplane.report import write_frame_report, write_scene_report
from monoplane.report.viewer import STATUS_ID, VIEWER_DIR, VIEWER_SCRIPT

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

#: Console lines that come from the test harness, not from the page: SwiftShader's notes on
#: WebGL performance, and model-viewer's warning that two animation frames did not come within
#: 500 ms, which happens when --virtual-time-budget jumps the clock ahead of the compositor.
BENIGN_CONSOLE = re.compile(r"GL Driver Message \(OpenGL, Performance|"
                            r'"rAF timed out in updateSource"')


@pytest.fixture(scope="module")
def chromium() -> str:
    if CHROMIUM is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is missing: setup.sh installs the Debian package 'chromium'")
        pytest.skip("chromium is not installed (apt-get install chromium; setup.sh does)")
    return CHROMIUM


def open_in_chromium(chromium: str, page: Path, profile: Path) -> tuple[str, list[str]]:
    """Load ``page`` from file:// and return the DOM after its scripts ran, and the page's
    console messages."""
    cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu",
           # software WebGL (SwiftShader), asked for explicitly: Chromium no longer falls back
           # to it silently, and this machine has no GPU
           "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
           # no network: a page that tried to fetch anything would fail and say so
           "--host-resolver-rules=MAP * ~NOTFOUND",
           f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0",
           "--virtual-time-budget=20000", "--dump-dom", page.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr[-2000:]
    console = [line for line in proc.stderr.splitlines()
               if ":CONSOLE" in line and not BENIGN_CONSOLE.search(line)]
    return proc.stdout, console


def viewer_status(dom: str) -> dict[str, str]:
    """The attributes and text of the viewer's status line."""
    match = re.search(rf'<p [^>]*id="{STATUS_ID}"([^>]*)>([^<]*)</p>', dom)
    assert match, "the page has no 3D viewer status line"
    attrs = dict(re.findall(r'data-(\w+)="([^"]*)"', match.group(1)))
    attrs["text"] = match.group(2)
    return attrs


def _assert_viewer_ready(chromium: str, page: Path, tmp_path: Path) -> None:
    dom, console = open_in_chromium(chromium, page, tmp_path / "profile")
    status = viewer_status(dom)
    assert status["status"] == "ready", status
    width, height = (int(v) for v in status["canvas"].split("x"))
    assert width > 100 and height > 100
    assert console == []


def test_frame_report_3d_view_renders(chromium: str, room, tmp_path: Path) -> None:
    page = write_frame_report(room, tmp_path / "rep", render_3d=False)
    _assert_viewer_ready(chromium, page, tmp_path)


def test_scene_report_3d_view_renders(chromium: str, tmp_path: Path) -> None:
    page = write_scene_report(make_scene(2), tmp_path / "rep", render_3d=False)
    _assert_viewer_ready(chromium, page, tmp_path)


def test_cloud_report_3d_view_renders(chromium: str, tmp_path: Path) -> None:
    from monoplane.host.detect import detect_planes
    from monoplane.report.cloud import write_cloud_report
    from monoplane.testing import box_frame

    frame, _ = box_frame(64, 48)
    result = detect_planes(frame.points().reshape(-1, 3))
    page = write_cloud_report(result, tmp_path / "rep", render_3d=False)
    _assert_viewer_ready(chromium, page, tmp_path)


def test_a_missing_viewer_script_is_reported_in_the_page(chromium: str, room,
                                                         tmp_path: Path) -> None:
    page = write_frame_report(room, tmp_path / "rep", render_3d=False)
    (page.parent / VIEWER_DIR / VIEWER_SCRIPT).unlink()
    dom, _ = open_in_chromium(chromium, page, tmp_path / "profile")
    status = viewer_status(dom)
    assert status["status"] == "error" and "did not load" in status["text"]


def test_the_console_check_sees_page_errors(chromium: str, tmp_path: Path) -> None:
    page = tmp_path / "broken.html"
    page.write_text("<!DOCTYPE html><html><body><script>"
                    "setTimeout(function () { undefinedFunction(); }, 10);</script></body></html>")
    _, console = open_in_chromium(chromium, page, tmp_path / "profile")
    assert any("undefinedFunction is not defined" in line for line in console), console
