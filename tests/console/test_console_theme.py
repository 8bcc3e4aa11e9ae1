"""The console's look comes from static/theme.toml: the file is checked, and a built console
uses exactly its colours and label."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from console.app import ConsoleApp
from console.scene.theme import THEME_FILE, load_theme
from core.robots import load

REPO = Path(__file__).resolve().parents[2]

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]



def test_the_theme_is_the_static_file():
    assert THEME_FILE == REPO / "static" / "theme.toml"
    raw = tomllib.loads(THEME_FILE.read_text(encoding="utf-8"))
    theme = load_theme()
    assert theme.brand_color == tuple(raw["gui"]["brand_color"])
    assert theme.table_color == tuple(raw["table"]["color"])
    assert theme.ground_color == tuple(raw["lights"]["ground_color"])
    # The label the console always had, now from the file.
    assert theme.label_for("soft-arm") == "Arm console · soft-arm"


def _write(tmp_path: Path, **changes: str) -> Path:
    text = THEME_FILE.read_text(encoding="utf-8")
    for old, new in changes.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "theme.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("old,new,entry", [
    ("brand_color = [38, 110, 150]", "brand_color = [38, 110, 300]", "[gui] brand_color"),
    ("color = [226, 222, 214]", "color = [226, 222]", "[table] color"),
    ('control_width = "medium"', 'control_width = "huge"', "[gui] control_width"),
    ("sky_color = [255, 255, 255]", "sky_color = [1.5, 255, 255]", "[lights] sky_color"),
])
def test_a_bad_theme_is_refused_with_the_entry_named(tmp_path, old, new, entry):
    with pytest.raises(ValueError, match=entry.replace("[", r"\[").replace("]", r"\]")):
        load_theme(_write(tmp_path, **{old: new}))


def test_unreadable_theme_says_so(tmp_path):
    with pytest.raises(ValueError, match="cannot read the console theme"):
        load_theme(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[gui\n")
    with pytest.raises(ValueError, match="cannot read the console theme"):
        load_theme(bad)


def test_the_console_draws_with_the_theme(server):
    theme = load_theme()
    app = ConsoleApp(load("soft-arm"), server)
    try:
        assert app.theme == theme
        assert tuple(np.asarray(app.table.color).tolist()) == theme.table_color
        assert tuple(np.asarray(app.grid.cell_color).tolist()) == theme.grid_cell_color
        assert tuple(np.asarray(app.grid.section_color).tolist()) == theme.grid_section_color
    finally:
        app.stop()
