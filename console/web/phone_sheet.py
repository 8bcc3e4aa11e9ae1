"""On phones the control sheet and the 3D view share the window, the view above, so the arm is
never behind the sheet.

Below viser's phone breakpoint (Mantine's ``xs``, 36 em = 576 px) viser 1.1.1 shows the control
panel as a bottom sheet 20 em wide and up to 60 % of the window high, on the right, over a 3D
view that fills the whole window: on a 390 × 844 phone it covers two thirds of the width and the
lower 60 % of the view, where the arm stands. :func:`phone_sheet_css` is a style sheet that, on
phones only, makes the sheet span the window's width and at most :data:`SHEET_MAX_HEIGHT_PCT` %
of its height, and gives the 3D view the rest above it: the view's canvas (and so the camera's
aspect, which the console frames the arm for: ``console.scene.window_fit``) is only the part
nobody covers. The sheet's content scrolls inside it, STOP and the phase at its top. The
selectors name viser's own inline styles (viser's DOM: an internal, hence here); on another
viser they match nothing and the phone layout stays as viser draws it. Desktop and tablet widths
are untouched (there the panel is docked beside the 3D view, ``console.scene.stage.setup_theme``).
"""

from __future__ import annotations

PHONE_MAX_WIDTH_EM = 36.0  # viser's mobile layout: (max-width: theme.breakpoints.xs)
SHEET_MAX_HEIGHT_PCT = 50.0
VISER_SHEET_WIDTH_EM = 20.0  # viser 1.1.1's BottomPanel: width 20em, max-height 60%
VISER_SHEET_MAX_HEIGHT_PCT = 60

_SHEET = (f'.mantine-Paper-root[style*="position: fixed"]'
          f'[style*="max-height: {VISER_SHEET_MAX_HEIGHT_PCT}%"]')
# The box holding the 3D canvas (App.tsx: flex-grow 1, height 100%, beside the panel).
_VIEW = 'div[style*="flex-grow: 1"][style*="height: 100%"]:has(canvas)'


def phone_sheet_css(max_height_pct: float = SHEET_MAX_HEIGHT_PCT) -> str:
    """The ``<style>`` element laying out viser's phone sheet under the 3D view.

    Args:
        max_height_pct: The sheet's greatest height, % of the window; the 3D view gets the
            rest.

    Raises:
        ValueError: A height outside 20..60 %.
    """
    if not 20.0 <= max_height_pct <= VISER_SHEET_MAX_HEIGHT_PCT:
        raise ValueError(f"phone sheet height must be 20 to 60 %, got {max_height_pct:g} %")
    inner = f'{_SHEET} div[style^="width: {VISER_SHEET_WIDTH_EM:g}em"]'
    return (f"<style>@media (max-width: {PHONE_MAX_WIDTH_EM:g}em) {{"
            f"{_SHEET}{{width:100%!important;max-height:{max_height_pct:g}%!important}}"
            f"{inner}{{width:100%!important}}"
            f"{_VIEW}{{flex:0 0 auto!important;width:100%!important;"
            f"height:{100 - max_height_pct:g}%!important}}"
            "}</style>")
