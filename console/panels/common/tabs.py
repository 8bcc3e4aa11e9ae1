"""The console's tabs by task, so a demo runs without scrolling through one long column.

Every panel names its tab (``Panel.tab``); :class:`ConsoleTabs` makes one viser tab group below
the header (``console.panels.common.header``) and a tab the first time a panel asks for it. Tabs keep the
order of :data:`TAB_ORDER` whatever order panels are added in, and a robot without, say,
experiments shows no empty *Experiments* tab.
"""

from __future__ import annotations

import threading
from typing import Any

import viser

from console.web.tab_order import order_tabs, tab_labels

TAB_ORDER: tuple[str, ...] = ("Operate", "Hardware", "Experiments", "Session")


class ConsoleTabs:
    """One tab group; ``tab(name)`` returns (creating on first use) the tab to build into.

    Args:
        gui: The server's GUI API.
        order: Where the tab group sits in the control panel (below the header).
    """

    def __init__(self, gui: viser.GuiApi, order: float = 1.0) -> None:
        self._gui = gui
        self._order = order
        self._group: Any = None
        self._tabs: dict[str, Any] = {}
        self._lock = threading.Lock()

    def tab(self, name: str) -> Any:
        """The tab called ``name`` (one of :data:`TAB_ORDER`), made on first use."""
        if name not in TAB_ORDER:
            raise ValueError(f"unknown tab {name!r}; tabs: {', '.join(TAB_ORDER)}")
        with self._lock:
            if name in self._tabs:
                return self._tabs[name]
            if self._group is None:
                self._group = self._gui.add_tab_group(order=self._order)
            handle = self._group.add_tab(name)  # no icons: the four labels fit on one row
            self._tabs[name] = handle
            # viser shows tabs in the order they were added; keep TAB_ORDER instead
            order_tabs(self._group, TAB_ORDER)
            return handle

    @property
    def names(self) -> tuple[str, ...]:
        """The tabs made so far, in the order the browser shows them."""
        with self._lock:
            if self._group is None:
                return ()
            return tab_labels(self._group)
