"""Why a jog or a tip target does not move a disarmed extensible arm: arming is the operator's.

Connecting never arms an arm (issue #27); only the operator's Arm device does. On hardware
whose measurements the view shows (the device emulator, a real port) a jog or a target on a
disarmed arm would change the console's command and move nothing, silently. The Jog and Tip
target panels ask :func:`disarmed_note` first and, when it answers, say so and move nothing.
"""

from __future__ import annotations

from typing import Any

ARM_FIRST = "arm first (Hardware tab: Arm device): a disarmed arm does not move"


def disarmed_note(app: Any) -> str | None:
    """Why a jog or a tip target cannot move the extensible arm now (None: it can, or the
    console only previews commands): the view shows what the encoders measure and the arm is
    not armed. Nothing here arms it behind the operator's back."""
    runner = app.services.extensible_runner
    if runner is None or app.store.mirror_commands or not runner.started:
        return None
    return ARM_FIRST if runner.snapshot.state in ("disarmed", "disconnected") else None
