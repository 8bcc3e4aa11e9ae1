"""A design study's self-contained HTML report: inline SVG plots of each metric, no CDN, no JS library.

Each metric is plotted over the variants (one bar per variant, in study order); hovering a bar
shows its variant and value (SVG ``<title>``); the best variant per metric is named.
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any, Sequence

W, H, PAD = 560, 220, 40


def _bars(rows: Sequence[dict[str, Any]], metric: str) -> str:
    vals = [float(r.get(metric, math.nan)) if not r.get("error") else math.nan for r in rows]
    finite = [v for v in vals if math.isfinite(v)]
    top = max(finite) if finite and max(finite) > 0 else 1.0
    bw = (W - 2 * PAD) / max(len(rows), 1)
    parts = [f'<svg width="{W}" height="{H}" xmlns="http://www.w3.org/2000/svg">',
             f'<line x1="{PAD}" y1="{H - PAD}" x2="{W - PAD}" y2="{H - PAD}" stroke="#444"/>']
    for i, (row, v) in enumerate(zip(rows, vals)):
        x = PAD + i * bw + 2
        name = html.escape(str(row["variant"]))
        if math.isfinite(v):
            h = (H - 2 * PAD) * max(v, 0.0) / top
            parts.append(f'<rect x="{x:.1f}" y="{H - PAD - h:.1f}" width="{bw - 4:.1f}" '
                         f'height="{h:.1f}" fill="#3b7dd8"><title>{name}: {v:.6g}</title></rect>')
        else:
            reason = html.escape(str(row.get("error") or "not computed"))
            parts.append(f'<text x="{x:.1f}" y="{H - PAD - 4}" font-size="10" fill="#c00">'
                         f'✗<title>{name}: {reason}</title></text>')
        parts.append(f'<text x="{x + bw / 2 - 2:.1f}" y="{H - PAD + 14}" font-size="10" '
                     f'text-anchor="middle">{i + 1}</text>')
    parts.append(f'<text x="{PAD}" y="{PAD - 10}" font-size="11">max {top:.4g}</text></svg>')
    return "".join(parts)


def write_html(rows: Sequence[dict[str, Any]], metrics: Sequence[str],
               best: dict[str, str], path: Path) -> None:
    """Write the report: the table (one row per variant), then one plot per metric."""
    cols: list[str] = []
    for row in rows:
        cols += [c for c in row if c not in cols]
    head = "".join(f"<th>{html.escape(c)}</th>" for c in ["#", *cols])
    body = "".join(
        "<tr>" + f"<td>{i}</td>" + "".join(f"<td>{html.escape(str(r.get(c, '')))}</td>"
                                           for c in cols) + "</tr>"
        for i, r in enumerate(rows, 1))
    plots = "".join(
        f"<h2>{html.escape(m)}</h2><p>best: {html.escape(best.get(m, 'none'))}</p>{_bars(rows, m)}"
        for m in metrics if any(m in r for r in rows))
    path.write_text("<!doctype html><meta charset='utf-8'><title>Design study</title>"
                    "<style>body{font-family:sans-serif}td,th{border:1px solid #ccc;"
                    "padding:2px 6px;font-size:12px}</style><h1>Design study</h1>"
                    f"<table><tr>{head}</tr>{body}</table>{plots}")
