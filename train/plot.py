"""Training curves as a PNG, drawn with OpenCV: training loss (log scale) and held-out errors against steps."""

import json
from pathlib import Path

import cv2
import numpy as np

from smplx_jax.atomic_files import atomic_path

WIDTH, HEIGHT, MARGIN = 560, 360, 60
COLOURS = [(200, 90, 30), (40, 140, 40), (30, 60, 200), (140, 40, 140)]  # BGR


def curves(log: Path, out: Path, baseline: dict[str, float] | None = None) -> Path:
    """Two panels from ``metrics.jsonl``: ``train/total`` and ``eval/*_mm`` (with the constant baseline dashed)."""
    rows = [json.loads(line) for line in Path(log).read_text().splitlines() if line]
    train = [(r["step"], r["train/total"]) for r in rows if "train/total" in r]
    evals = {k: [(r["step"], r[k]) for r in rows if np.isfinite(r.get(k, np.nan))]
             for k in ("eval/mpjpe_mm", "eval/pa_mpjpe_mm", "eval/error_2d_px")}
    left = _panel("training loss (log10)", {"total": [(s, np.log10(max(v, 1e-12))) for s, v in train]})
    lines = {k.removeprefix("eval/"): v for k, v in evals.items() if v}
    dashed = {f"constant {k}": v for k, v in (baseline or {}).items()}
    right = _panel("held-out error", lines, dashed)
    image = np.concatenate([left, right], axis=1)
    with atomic_path(out) as tmp:
        if not cv2.imwrite(str(tmp), image):
            raise OSError(f"{out}: cannot write the plot")
    return Path(out)


def _panel(title: str, series: dict[str, list], levels: dict[str, float] | None = None) -> np.ndarray:
    image = np.full((HEIGHT, WIDTH, 3), 255, np.uint8)
    levels = levels or {}
    points = [p for s in series.values() for p in s]
    cv2.putText(image, title, (MARGIN, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    if not points:
        return image
    steps = np.array([p[0] for p in points], float)
    values = np.array([p[1] for p in points] + list(levels.values()), float)
    x0, x1 = 0.0, max(steps.max(), 1.0)
    y0, y1 = values.min(), values.max()
    y0, y1 = (y0 - 0.5, y1 + 0.5) if y1 - y0 < 1e-9 else (y0 - 0.05 * (y1 - y0), y1 + 0.05 * (y1 - y0))

    def to_pixel(x, y):
        u = MARGIN + (x - x0) / (x1 - x0) * (WIDTH - 1.5 * MARGIN)
        v = HEIGHT - MARGIN + (y - y0) / (y1 - y0) * (1.5 * MARGIN - HEIGHT)
        return int(round(u)), int(round(v))

    cv2.rectangle(image, to_pixel(x0, y0), to_pixel(x1, y1), (0, 0, 0), 1)
    for t in np.linspace(0, 1, 5):
        x, y = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
        u, v = to_pixel(x, y0)
        cv2.putText(image, f"{x:.0f}", (u - 12, v + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
        u, v = to_pixel(x0, y)
        cv2.putText(image, f"{y:.3g}", (4, v + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(image, "step", (WIDTH // 2, HEIGHT - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    for i, (name, pts) in enumerate(series.items()):
        colour = COLOURS[i % len(COLOURS)]
        polyline = np.array([to_pixel(x, y) for x, y in pts], np.int32)
        cv2.polylines(image, [polyline], False, colour, 2, cv2.LINE_AA)
        _legend(image, i, name, colour)
    for j, (name, level) in enumerate(levels.items(), start=len(series)):
        colour = COLOURS[j % len(COLOURS)]
        for x in np.arange(x0, x1, (x1 - x0) / 40)[::2]:
            cv2.line(image, to_pixel(x, level), to_pixel(x + (x1 - x0) / 40, level), colour, 1, cv2.LINE_AA)
        _legend(image, j, name, colour)
    return image


def _legend(image, row: int, name: str, colour) -> None:
    y = 45 + 18 * row
    cv2.line(image, (WIDTH - 200, y - 4), (WIDTH - 180, y - 4), colour, 2)
    cv2.putText(image, name, (WIDTH - 175, y), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
