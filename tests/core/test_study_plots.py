"""core.study's PNG plots, read back by a PNG decoder written here (zlib and the PNG spec only).

matplotlib writes the files (through Pillow); this reader shares no code with either, so what it
finds (the image's size, where the markers of each line are) is an independent reading of what
a person sees.
"""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from core.study import StudySpec, run_study
from core.study.plots import DPI, HEIGHT_IN, LINE_COLOURS, WIDTH_IN, series, write_pngs

BLUE = LINE_COLOURS[0]


def read_png(path: Path) -> np.ndarray:
    """(height, width, channels) uint8 of an 8-bit, non-interlaced RGB or RGBA PNG."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, ihdr = 8, b"", b""
    while pos < len(data):
        (length,), kind = struct.unpack(">I", data[pos:pos + 4]), data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        assert zlib.crc32(kind + body) == crc, kind
        if kind == b"IHDR":
            ihdr = body
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", ihdr)
    assert depth == 8 and colour in (2, 6) and interlace == 0
    bpp = 3 if colour == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * bpp
    assert len(raw) == height * (stride + 1)
    out = np.zeros((height, stride), dtype=np.int64)
    prev = np.zeros(stride, dtype=np.int64)
    for y in range(height):
        f = raw[y * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int64)
        if f == 0:
            cur = line
        elif f == 2:
            cur = (line + prev) & 0xFF
        else:  # Sub, Average, Paeth depend on the pixel to the left: byte by byte
            cur = np.zeros(stride, dtype=np.int64)
            for i in range(stride):
                a = int(cur[i - bpp]) if i >= bpp else 0
                b, c = int(prev[i]), int(prev[i - bpp]) if i >= bpp else 0
                if f == 1:
                    pred = a
                elif f == 3:
                    pred = (a + b) // 2
                else:
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[i] = (int(line[i]) + pred) & 0xFF
        out[y] = cur
        prev = cur
    return out.reshape(height, width, bpp).astype(np.uint8)


def pixels_of(img: np.ndarray, colour: str) -> np.ndarray:
    """(row, column) of every pixel of exactly ``colour`` (#rrggbb): the solid markers' insides
    (the lines between them are lighter, antialiased edges are blends)."""
    rgb = [int(colour[i:i + 2], 16) for i in (1, 3, 5)]
    return np.argwhere((img[..., :3] == rgb).all(axis=-1))


def red_pixels(img: np.ndarray) -> np.ndarray:
    """(row, column) of strongly red pixels."""
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return np.argwhere((r > 170) & (g < 90) & (b < 90))


def blobs(points: np.ndarray) -> list[tuple[float, float]]:
    """Mean (row, column) of groups of points split where columns jump by > 10 pixels."""
    order = points[np.argsort(points[:, 1])]
    cuts = np.where(np.diff(order[:, 1]) > 10)[0] + 1
    return [(float(g[:, 0].mean()), float(g[:, 1].mean())) for g in np.split(order, cuts)]


def test_a_metric_over_two_keys_one_line_per_other_value_and_a_failed_variant(tmp_path: Path) -> None:
    rows = [{"variant": f"v{i}", "a.x": x, "a.y": y, "m": v, "error": e}
            for i, (x, y, v, e) in enumerate([(1, 10, 1.0, ""), (2, 10, 3.0, ""), (3, 10, 2.0, ""),
                                              (1, 20, 2.5, ""), (2, 20, math.nan, "boom"),
                                              (3, 20, 0.5, "")])]
    xk, lines = series(rows, ["a.y", "a.x"], "m")
    assert xk == "a.x" and list(lines) == ["a.y=10", "a.y=20"]
    assert lines["a.y=10"] == [(1.0, 1.0), (2.0, 3.0), (3.0, 2.0)]
    [path] = write_pngs(rows, ["a.y", "a.x"], ["m", "absent"], {"m": "v1"}, tmp_path / "plots")
    assert path == tmp_path / "plots" / "m.png"
    img = read_png(path)
    assert img.shape[:2] == (round(HEIGHT_IN * DPI), round(WIDTH_IN * DPI))
    # The blue line's three markers, left to right: 1, 3, 2 (a higher value is nearer the top).
    blue = blobs(pixels_of(img, BLUE))
    assert len(blue) == 3
    (r1, c1), (r3, c3), (r2, c2) = blue
    assert c1 < c3 < c2 and r3 < r2 < r1
    # Evenly spaced x values, evenly spaced columns; the values' rows in proportion.
    assert c3 - c1 == pytest.approx(c2 - c3, abs=2)
    assert (r1 - r2) / (r1 - r3) == pytest.approx((2.0 - 1.0) / (3.0 - 1.0), abs=0.03)
    # The other line's middle variant failed: a red cross on the x axis at x = 2, below
    # every marker.
    red = red_pixels(img)
    assert len(red) > 20
    assert abs(red[:, 1].mean() - c3) < 4
    assert red[:, 0].min() > max(r for r, _ in blue)
    assert not (tmp_path / "plots" / "absent.png").exists()


def test_a_study_writes_one_png_per_metric_it_computed(tmp_path: Path) -> None:
    spec = StudySpec(objects=0, ik_grid=0, slip_points=0)
    run_study("extensible", {"segments.rack_max": [0.3, 0.41]}, tmp_path / "s", spec)
    pngs = sorted(p.name for p in (tmp_path / "s" / "plots").glob("*.png"))
    assert pngs == ["workspace_volume_m3.png"]
    img = read_png(tmp_path / "s" / "plots" / "workspace_volume_m3.png")
    (r_short, c_short), (r_long, c_long) = blobs(pixels_of(img, BLUE))
    assert c_short < c_long and r_long < r_short  # longer racks, larger volume, higher up
    assert len(red_pixels(img)) == 0  # nothing failed


def test_without_matplotlib_the_tables_stand_and_the_reason_is_raised(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import builtins

    from core.study.plots import PlotsUnavailable

    real_import = builtins.__import__

    def no_matplotlib(name: str, *args: object, **kwargs: object) -> object:
        if name.startswith("matplotlib"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    spec = StudySpec(objects=0, ik_grid=0, slip_points=0)
    with pytest.raises(PlotsUnavailable, match=r"pip install '\.\[study\]'"):
        run_study("extensible", {"segments.rack_max": [0.3]}, tmp_path / "s", spec)
    assert (tmp_path / "s" / "results.parquet").exists() and (tmp_path / "s" / "report.html").exists()
    assert not (tmp_path / "s" / "plots").exists()
