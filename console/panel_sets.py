"""Which panels a console gets by default: the composition's choice, kept out of the app.

``ConsoleApp`` composes :data:`DEFAULT_PANELS` when it is given no ``panels=``; ``serve.py``
adds the rest (grasp, control, extensible, hardware, session, view panels). The app itself
knows no panel class: panels see it through :class:`console.panels.common.host.PanelHost`.
"""

from __future__ import annotations

from console.panels.common.base import Panel
from console.panels.common.jog import JogPanel
from console.panels.common.readout import ReadoutPanel

DEFAULT_PANELS: tuple[type[Panel], ...] = (JogPanel, ReadoutPanel)

__all__ = ["DEFAULT_PANELS"]
