"""The console's look as data (``static/theme.toml``), so colours and labels change without code.

:func:`load_theme` reads and checks the file (default: the repository's ``static/theme.toml``)
into a frozen :class:`ConsoleTheme`; :class:`console.app.ConsoleApp` reads it when it is built.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any, Literal

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

STATIC_DIR = Path(__file__).resolve().parents[2] / "static"
THEME_FILE = STATIC_DIR / "theme.toml"

RGB = tuple[int, int, int]
ControlWidth = Literal["small", "medium", "large"]
ControlDock = Literal["right", "left", "float"]
DOCKS: tuple[str, ...] = ("right", "left", "float")


@dataclasses.dataclass(frozen=True)
class ConsoleTheme:
    """Colours (RGB 0-255) and labels of the console (see ``static/theme.toml``)."""

    brand_color: RGB
    control_width: ControlWidth
    panel_label: str
    table_color: RGB
    grid_cell_color: RGB
    grid_section_color: RGB
    sky_color: RGB
    ground_color: RGB
    control_dock: ControlDock = "right"  # docked: the 3D view is the window beside the panel

    def label_for(self, robot_name: str) -> str:
        """The control panel's title for a robot."""
        return self.panel_label.replace("{robot}", robot_name)


def _rgb(table: dict[str, Any], section: str, key: str, path: Path) -> RGB:
    value = table.get(section, {}).get(key)
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255
                       for c in value)):
        raise ValueError(f"{path}: [{section}] {key} must be three integers 0-255, got {value!r}")
    return (value[0], value[1], value[2])


def load_theme(path: str | Path = THEME_FILE) -> ConsoleTheme:
    """Read and check a theme file; a bad file raises ValueError naming the entry."""
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the console theme: {exc}") from exc
    gui = table.get("gui", {})
    width = gui.get("control_width")
    if width not in ("small", "medium", "large"):
        raise ValueError(f"{path}: [gui] control_width must be small, medium or large, "
                         f"got {width!r}")
    dock = gui.get("control_dock", "right")
    if dock not in DOCKS:
        raise ValueError(f"{path}: [gui] control_dock must be right, left or float, "
                         f"got {dock!r}")
    label = gui.get("panel_label")
    if not isinstance(label, str) or not label.strip():
        raise ValueError(f"{path}: [gui] panel_label must be a non-empty string")
    return ConsoleTheme(
        brand_color=_rgb(table, "gui", "brand_color", path), control_width=width,
        panel_label=label, table_color=_rgb(table, "table", "color", path),
        grid_cell_color=_rgb(table, "table", "grid_cell_color", path),
        grid_section_color=_rgb(table, "table", "grid_section_color", path),
        sky_color=_rgb(table, "lights", "sky_color", path),
        ground_color=_rgb(table, "lights", "ground_color", path), control_dock=dock)
