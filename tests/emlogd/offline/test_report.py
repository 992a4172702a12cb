"""Report figures (needs matplotlib, part of the test extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from emlogd.offline.jobs import load_captures
from emlogd.pipeline.settings import UutSettings

pytest.importorskip("matplotlib")

from emlogd.offline import report as report_module
from emlogd.offline.report import _cell_text, report


def _layout(fig: Any) -> dict[str, Any]:
    """What the checks need from a drawn figure: axes, legends, texts and their boxes."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    axes = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
    out: dict[str, Any] = {"axes": [], "titles": []}
    for ax in axes:
        labels = [
            t.get_window_extent(r)
            for t in ax.get_xticklabels() + ax.get_yticklabels()
            if t.get_visible() and t.get_text()
        ]
        legend = ax.get_legend()
        out["axes"].append(
            {
                "box": ax.get_window_extent(r),
                "labels": labels,
                "legend": legend.get_window_extent(r) if legend is not None else None,
                "texts": [(t, t.get_window_extent(r)) for t in ax.texts],
                "image": bool(ax.images),
            }
        )
        out["titles"].append(ax.get_title())
    return out


def test_report_writes_legible_figures(
    trial_files: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every figure is written; no legend covers its axes, no tick labels of two heat maps
    overlap, every heat-map number is ≥ 8 pt and inside its cell, speed plots name their window."""
    layouts: dict[str, dict[str, Any]] = {}
    save = report_module._save

    def checked_save(fig: Any, path: Path, plt: Any) -> Path:
        layouts[path.name] = _layout(fig)
        return save(fig, path, plt)

    monkeypatch.setattr(report_module, "_save", checked_save)
    settings = UutSettings(port="emlog1", reference_port="dvl")
    recs = load_captures([trial_files["figure-8"], trial_files["straight"]], settings)
    paths = report(recs, settings, tmp_path / "fig", lag=3.3, workers=1)
    names = sorted(p.name for p in paths)
    assert names == sorted(
        [
            "speed_2-figure8.png",
            "speed_3-straight.png",
            "convergence.png",
            "nis.png",
            "trajectory.png",
            "crossval.png",
        ]
    )
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert p.stat().st_size > 10_000
    for name, lay in layouts.items():
        for ax in lay["axes"]:
            if ax["legend"] is not None:
                assert not ax["legend"].overlaps(ax["box"]), f"{name}: a legend covers the data"
    for name in ("speed_2-figure8.png", "speed_3-straight.png"):
        assert (
            "whole capture" in layouts[name]["titles"][0] or "window" in layouts[name]["titles"][0]
        )
    heat = [ax for ax in layouts["crossval.png"]["axes"] if ax["image"]]
    assert len(heat) == 8
    for i, a in enumerate(heat):
        for b in heat[i + 1 :]:
            for la in a["labels"]:
                assert not any(la.overlaps(lb) for lb in b["labels"] + [b["box"]])
        n = round(len(a["texts"]) ** 0.5)
        assert n * n == len(a["texts"]) == 4
        cell_w, cell_h = a["box"].width / n, a["box"].height / n
        for text, box in a["texts"]:
            assert text.get_fontsize() >= 8
            assert box.width < cell_w and box.height < cell_h, text.get_text()
            j, k = text.get_position()
            cx = a["box"].x0 + (j + 0.5) * cell_w
            cy = a["box"].y1 - (k + 0.5) * cell_h
            assert abs((box.x0 + box.x1) / 2 - cx) < 0.5 * cell_w - box.width / 2 + 1
            assert abs((box.y0 + box.y1) / 2 - cy) < 0.5 * cell_h - box.height / 2 + 1


def test_cell_text_fits_five_characters() -> None:
    """A heat-map number is at most five characters, large losses in thousands."""
    assert [_cell_text(v) for v in (81.4, -29.0, -1327.0, -41014.0, float("nan"))] == [
        "81", "-29", "-1.3k", "-41k", "n/a",
    ]  # fmt: skip
