"""Tabs of a viser tab group in a chosen order: viser 1.1.1 shows them in the order added.

viser's ``GuiTabGroupHandle`` has no public way to reorder its tabs or read their labels; its
private handle list is the group's one source of truth for the tab tuples it sends, so sorting
it and rebuilding the props reorders what every browser shows. Kept here, in the one package
that touches viser's internals (``console.web``).
"""

from __future__ import annotations

from typing import Any, Sequence


def order_tabs(group: Any, order: Sequence[str]) -> None:
    """Sort ``group``'s tabs by their labels' places in ``order`` and resend its props.

    Raises:
        ValueError: a tab's label is not in ``order``.
    """
    group._tab_handles.sort(key=lambda h: order.index(h._label))
    group._rebuild_tab_props()


def tab_labels(group: Any) -> tuple[str, ...]:
    """The labels of ``group``'s tabs, in the order the browser shows them."""
    return tuple(h._label for h in group._tab_handles)
