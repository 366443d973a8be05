"""Self-contained HTML reports with PNG figures, headless 3D renders and an interactive 3D view.

>>> from monoplane.report import write_frame_report
>>> write_frame_report(rec, Path("out"))             # doctest: +SKIP

See ``docs/reports.md`` for the contents of each report and for headless rendering.
"""

from monoplane.report.cloud import write_cloud_report
from monoplane.report.evaluation import write_eval_report
from monoplane.report.frame import write_frame_report
from monoplane.report.scene import write_scene_report

__all__ = ["write_cloud_report", "write_eval_report", "write_frame_report", "write_scene_report"]
