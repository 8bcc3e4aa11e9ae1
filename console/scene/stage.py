"""The console's stage, set before any panel: theme, table, lights, first camera, no share tunnel.

What every console draws the same way whatever its panels: the theme (``static/theme.toml``:
brand colour, panel label; no share button or logo), the table (the z = 0 plane around the
arm's workspace, with a subtle grid), cheap lights for software-rendered WebGL, and the first of
the robot's camera presets. :class:`console.app.ConsoleApp` builds it in this order; its
``arm_reach`` and ``table_rectangle`` are :func:`console.core.table_area.arm_span` and
:func:`console.core.table_area.table_extent` of its robot (pure geometry, shared with the grasp
session).
"""

from __future__ import annotations

from typing import Any

import viser

from console.scene.camera import CameraPose
from console.scene.camera import apply as apply_camera
from console.scene.camera import presets as camera_presets
from console.scene.theme import ConsoleTheme, load_theme
from console.core.table_area import arm_span, table_extent  # noqa: F401 (the app's stage)
from console.web.phone_sheet import phone_sheet_css
from console.web.share_tunnel import disable_share_tunnel
from core.robots import Robot


PHONE_CSS_ORDER = 99.0  # the style sheet's place in the control panel: last, after the tabs


def setup_theme(server: viser.ViserServer, robot_name: str) -> ConsoleTheme:
    """Close the share tunnel, apply ``static/theme.toml`` (colours, the panel's width and dock)
    and the panel label, and add the phone sheet's style; the theme."""
    gui = server.gui
    disable_share_tunnel(server)
    theme = load_theme()  # static/theme.toml: colours and the panel label
    gui.configure_theme(show_share_button=False, show_logo=False,
                        brand_color=theme.brand_color, control_width=theme.control_width)
    # Docked, the panel takes its own strip of the window and the 3D view the rest, so the
    # arm (framed in the middle of the view) is never behind the panel, at any width down to
    # viser's phone layout (a bottom sheet below 576 px). Floating, it covers the view's right.
    if theme.control_dock == "right":
        gui.main_panel.dock_right()
    elif theme.control_dock == "left":
        gui.main_panel.dock_left()
    # Phones get viser's bottom sheet instead: narrower and shorter, the arm beside and above
    # it (console.web.phone_sheet; a style sheet only, after the header and the tabs).
    gui.add_html(phone_sheet_css(), order=PHONE_CSS_ORDER)
    gui.set_panel_label(theme.label_for(robot_name))
    return theme


def add_table(scene: viser.SceneApi, theme: ConsoleTheme,
              extent: tuple[float, float, float, float]) -> tuple[Any, Any]:
    """The table top and its grid over ``extent`` (x0, x1, y0, y1); hides the world axes."""
    x0, x1, y0, y1 = extent
    w, h = x1 - x0, y1 - y0
    centre = ((x0 + x1) / 2, (y0 + y1) / 2)
    thickness = 0.02
    table = scene.add_box("/table/top", color=theme.table_color,
                          dimensions=(w, h, thickness),
                          position=(centre[0], centre[1], -thickness / 2),
                          cast_shadow=False, receive_shadow=True)
    grid = scene.add_grid("/table/grid", width=w, height=h, plane="xy",
                          cell_size=0.05, cell_color=theme.grid_cell_color,
                          section_size=0.25, section_color=theme.grid_section_color,
                          position=(centre[0], centre[1], 0.0005), shadow_opacity=0.15)
    scene.world_axes.visible = False
    return table, grid


def add_lights(scene: viser.SceneApi, theme: ConsoleTheme) -> None:
    """Cheap lighting for software-rendered WebGL."""
    # Cheap lighting for software-rendered WebGL (lab PCs without a GPU, CI). Measured here
    # in headless Chromium/SwiftShader: with viser's HDR environment map and shadow maps a
    # slider step took ~0.4-0.6 s to process, without them ~0.1-0.2 s. A hemisphere light
    # plus shadowless default lights looks much the same.
    scene.configure_environment_map(None)
    scene.configure_default_lights(enabled=True, cast_shadow=False)
    scene.add_light_hemisphere("/lights/hemisphere", sky_color=theme.sky_color,
                               ground_color=theme.ground_color, intensity=1.3)


def setup_camera(server: viser.ViserServer, robot: Robot, kind: str) -> tuple[CameraPose, ...]:
    """The robot's camera presets; the first is applied to the initial camera."""
    # The first of the robot's camera presets (console.scene.camera, also the View panel's
    # "Reset view"): framed for a wide window with the control panel docked on the right.
    presets = camera_presets(kind, arm_span(robot, kind), table_extent(robot, kind))
    apply_camera(server.initial_camera, presets[0])
    return presets
