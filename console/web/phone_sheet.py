"""A narrower, shorter control sheet on phones, so the arm stays in view beside and above it.

Below viser's phone breakpoint (Mantine's ``xs``, 36 em = 576 px) viser 1.1.1 shows the control
panel as a bottom sheet 20 em wide and up to 60 % of the window high, on the right: on a
390 × 844 phone it covers two thirds of the width and the lower 60 % of the 3D view, where the
arm stands. :func:`phone_sheet_css` is a style sheet that, on phones only, makes it
:data:`SHEET_WIDTH_EM` wide (viser's ``small`` control width) and at most
:data:`SHEET_MAX_HEIGHT_PCT` % high; its content scrolls inside it, STOP and the phase stay at
its top. The selectors name viser's own inline styles of that sheet (viser's DOM: an internal,
hence here); on another viser they match nothing and the sheet stays as viser draws it.
Desktop and tablet widths are untouched (there the panel is docked beside the 3D view,
``console.scene.stage.setup_theme``).
"""

from __future__ import annotations

PHONE_MAX_WIDTH_EM = 36.0  # viser's mobile layout: (max-width: theme.breakpoints.xs)
SHEET_WIDTH_EM = 16.0  # viser's "small" control width
SHEET_MAX_HEIGHT_PCT = 50.0
VISER_SHEET_WIDTH_EM = 20.0  # viser 1.1.1's BottomPanel: width 20em, max-height 60%
VISER_SHEET_MAX_HEIGHT_PCT = 60

_SHEET = (f'.mantine-Paper-root[style*="position: fixed"]'
          f'[style*="max-height: {VISER_SHEET_MAX_HEIGHT_PCT}%"]')


def phone_sheet_css(width_em: float = SHEET_WIDTH_EM,
                    max_height_pct: float = SHEET_MAX_HEIGHT_PCT) -> str:
    """The ``<style>`` element narrowing and shortening viser's phone sheet.

    Args:
        width_em: The sheet's width on phones (em of the sheet's font).
        max_height_pct: Its greatest height, % of the window.

    Raises:
        ValueError: A width outside 10..20 em or a height outside 20..60 %.
    """
    if not 10.0 <= width_em <= VISER_SHEET_WIDTH_EM:
        raise ValueError(f"phone sheet width must be 10 to 20 em, got {width_em:g} em")
    if not 20.0 <= max_height_pct <= VISER_SHEET_MAX_HEIGHT_PCT:
        raise ValueError(f"phone sheet height must be 20 to 60 %, got {max_height_pct:g} %")
    inner = f'{_SHEET} div[style^="width: {VISER_SHEET_WIDTH_EM:g}em"]'
    return (f"<style>@media (max-width: {PHONE_MAX_WIDTH_EM:g}em) {{"
            f"{_SHEET}{{width:{width_em:g}em!important;"
            f"max-height:{max_height_pct:g}%!important}}"
            f"{inner}{{width:{width_em:g}em!important}}"
            "}</style>")
