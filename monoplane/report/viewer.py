"""The interactive 3D view of a report: ``planes.glb`` in the vendored ``<model-viewer>``.

Reports are opened from ``file://``, where browsers refuse ``fetch`` of local files and ES
modules. So the page embeds the ``.glb`` bytes as a base64 ``data:`` URI, and loads the viewer
as one classic script, a copy of ``vendor/model-viewer-umd.min.js`` (see ``vendor/README.md``)
beside the page, by relative path. Nothing is fetched from the network.

A small script of ours reports the outcome in the page itself: the element with id
:data:`STATUS_ID` gets ``data-status="ready"`` (and ``data-canvas="WxH"``) once the model is
shown in the viewer's canvas, or ``data-status="error"`` with the reason (viewer script
missing, model not loaded, script error). The browser test reads that marker.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import tempfile
from pathlib import Path

from monoplane.report import html

VENDOR = Path(__file__).resolve().parent / "vendor"
#: The vendored viewer script, and the name of its copy beside a report.
VIEWER_SCRIPT = "model-viewer-umd.min.js"
#: Folder of a report that holds the viewer's copy (and its licences).
VIEWER_DIR = "viewer"
#: Licence files copied along with the viewer.
LICENCE_FILES = ("LICENSE-model-viewer", "THIRD_PARTY_LICENSES.txt")
#: Anchor of the 3D section (the batch index links to ``report.html#view3d``).
SECTION_ID = "view3d"
#: Id of the element that carries the viewer's status.
STATUS_ID = "monoplane-3d-status"

_STATUS_SCRIPT = """
(function () {
  var viewer = document.getElementById("monoplane-3d");
  var status = document.getElementById("%(status)s");
  function set(state, text) { status.dataset.status = state; status.textContent = text; }
  window.addEventListener("error", function (e) { set("error", "3D view failed: " + e.message); });
  window.addEventListener("unhandledrejection", function (e) {
    set("error", "3D view failed: " + (e.reason && e.reason.message || e.reason));
  });
  if (!window.customElements || !customElements.get("model-viewer")) {
    set("error", %(missing)s);
    return;
  }
  viewer.addEventListener("error", function (e) {
    set("error", "3D view failed: " + (e.detail && e.detail.type || "unknown error"));
  });
  viewer.addEventListener("load", function () {
    var canvas = viewer.shadowRoot && viewer.shadowRoot.querySelector("canvas");
    if (!canvas) { set("error", "3D view failed: the viewer made no canvas"); return; }
    status.dataset.canvas = canvas.width + "x" + canvas.height;
    set("ready", "Drag to turn, scroll or pinch to zoom, right-drag or two fingers to pan.");
  });
})();
"""


def install_viewer(folder: Path) -> str:
    """Copy the viewer script and its licences into ``folder/viewer/`` (if not already there).

    Copies go through a temporary file and a rename, so that processes installing into one
    shared folder at once (batch workers) never expose a partial script.

    Parameters
    ----------
    folder : pathlib.Path
        The report's folder, or a folder shared by several reports.

    Returns
    -------
    str
        The script's path relative to ``folder``, for a page in ``folder``.
    """
    target = Path(folder) / VIEWER_DIR
    target.mkdir(parents=True, exist_ok=True)
    for name in (VIEWER_SCRIPT, *LICENCE_FILES):
        dest = target / name
        if dest.is_file() and dest.stat().st_size == (VENDOR / name).stat().st_size:
            continue
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=target)
        os.close(fd)
        try:
            shutil.copyfile(VENDOR / name, tmp)
            os.chmod(tmp, 0o644)  # mkstemp makes it private; the report is meant to be shared
            os.replace(tmp, dest)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return f"{VIEWER_DIR}/{VIEWER_SCRIPT}"


def viewer_section(glb: bytes, glb_name: str, script_src: str, what: str,
                   orbit: tuple[float, float] | None = None) -> str:
    """The report section with the interactive 3D view (markup).

    Parameters
    ----------
    glb : bytes
        The ``.glb`` file to show (embedded in the page).
    glb_name : str
        Its file name beside the report (``planes.glb`` or ``scene.glb``), for the link.
    script_src : str
        Relative URL of the viewer script (from :func:`install_viewer`).
    what : str
        One sentence on what the scene shows, for the caption.
    orbit : (float, float), optional
        Where the view starts: azimuth about glTF's y axis from +z and polar angle from +y,
        radians (model-viewer's ``camera-orbit``); default: model-viewer's, from +z and 15°
        above the horizon, which for a single view is about where the camera stood.
    """
    uri = "data:model/gltf-binary;base64," + base64.b64encode(glb).decode("ascii")
    start = "" if orbit is None else f'camera-orbit="{orbit[0]:.4f}rad {orbit[1]:.4f}rad auto" '

    missing = (f"The 3D viewer ({script_src}) did not load; open {glb_name} in any glTF "
               "viewer.")
    # A JSON string is a JavaScript string literal; "</" is escaped so that it cannot end
    # the script element.
    script = _STATUS_SCRIPT % {"status": STATUS_ID,
                               "missing": json.dumps(missing).replace("</", "<\\/")}
    body = (
        f'<model-viewer id="monoplane-3d" src="{uri}" alt="{html.esc(what)}" {start}'
        'camera-controls '
        # eager: load at once, not when scrolled into view, so the status is known early
        'loading="eager" interaction-prompt="none" shadow-intensity="0" '
        'style="width: 100%; height: 560px; background: #f4f4f4; border: 1px solid #ddd">'
        '<div slot="progress-bar"></div></model-viewer>'
        f'<p class="subtitle" id="{STATUS_ID}" data-status="loading">Loading the 3D view '
        "(it needs JavaScript and WebGL)…</p>"
        + html.paragraph(f"{what} The scene is {glb_name} beside this page (glTF, y up), for "
                         "Blender, three.js or any glTF viewer.")
        + f'<script src="{html.esc(script_src)}"></script><script>{script}</script>'
    )
    return f'<section id="{SECTION_ID}"><h2>Interactive 3D view</h2>{body}</section>'
