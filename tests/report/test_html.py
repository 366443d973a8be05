"""The HTML writer escapes text and references figures relatively."""

from __future__ import annotations

from pathlib import Path

from monoplane.report import html


def test_page_escapes_and_links(tmp_path: Path) -> None:
    body = html.section("<Planes>", html.figure_grid([html.Figure("a.png", "x < y")], 2)
                        + html.table(["id", "v"], [["<b>", 1]]))
    path = html.write_page(tmp_path / "r.html", "t & t", "sub", [body])
    text = path.read_text()
    assert "<title>t &amp; t</title>" in text
    assert "&lt;Planes&gt;" in text and "&lt;b&gt;" in text and "<b>" not in text
    assert 'src="a.png"' in text and "x &lt; y" in text
    assert "http" not in text  # nothing loaded from the network


def test_raw_table_keeps_markup() -> None:
    out = html.table(["id"], [[html.swatch((1, 2, 3)) + "1"]], raw=True)
    assert "rgb(1,2,3)" in out
