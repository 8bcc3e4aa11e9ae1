"""Stand-ins shared by the console tests that drive panels without a browser."""

from __future__ import annotations


class FakeClient:
    """What operator_only, app.refuse and app.notify_all use of a viser ClientHandle."""

    def __init__(self, cid: int) -> None:
        self.client_id = cid
        self.notes: list[tuple[str, str]] = []

    def add_notification(self, title: str, body: str, **_: object) -> None:
        self.notes.append((title, body))
