"""A recording's events as sentences with times, so a replay's log reads like what happened.

The recorder stores records (``phase`` from the control loop's view, ``fault``, ``link`` health,
operator ``action`` texts, ``timing`` 20 times a second, ...); a replay's log shows people
sentences instead: "Phase: approach → grasp", "Armed", "Link lost: no STATE for 42 ms",
"Device armed by Bea", "STOP pressed by Bea". :func:`sentences` turns the events into
:class:`Sentence` s in time order, keeping only what changed (phase, armed, link state, a new
link fault), every loop fault and every operator action; loop timing, states, plans, the table
and overlays are drawn or plotted, not told. :mod:`console.playback.replay_markers` makes them
the timeline's markers.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Iterable, Literal

from console.recording.timeline import Event

Category = Literal["phase", "fault", "stop", "action", "link"]
SYSTEM = ("", "server")  # records nobody in particular made

_HARDWARE = {"arm the device": "Device armed", "disarm the device": "Device disarmed",
             "disconnect": "Disconnected the device"}


@dataclasses.dataclass(frozen=True)
class Sentence:
    """One line of the log: time (s since the recording started), category, who, the words."""

    t: float
    category: Category
    who: str
    text: str


def _cap(text: str) -> str:
    return text[:1].upper() + text[1:]


def _by(text: str, who: str) -> str:
    """``text`` with "by ``who``" when a person did it and the text does not name them yet."""
    return text if who in SYSTEM or who in text else f"{text} by {who}"


def action_sentence(what: str, who: str) -> tuple[Category, str]:
    """An operator action record's ``what`` (and ``who`` did it) as a sentence."""
    what = what.strip()
    low = what.lower()
    if low.startswith("stop:"):
        rest = what[5:].strip()
        return "stop", _cap(rest) if rest.lower().startswith("stop") else f"Stopped: {rest}"
    if low.startswith("refused:"):
        rest = what[8:].strip()
        return "action", (f"Refused: {rest}" if who in SYSTEM else f"{who} was refused: {rest}")
    if low.startswith(("hardware fault:", "control process died:", "fault")):
        return "fault", _cap(what)
    if low.startswith("hardware:"):
        rest = what[9:].strip()
        if rest.startswith("connect "):
            words = "Connected " + rest[len("connect "):]
        else:
            words = _HARDWARE.get(rest, _cap(rest))
        return "action", _by(words, who)
    if low == "started recording":
        return "action", _by("Recording started", who)
    return "action", _by(_cap(what), who)


def _phase_sentences(data: dict[str, Any], last: dict[str, Any]) -> list[tuple[Category, str]]:
    out: list[tuple[Category, str]] = []
    phase, reason, armed = data.get("phase"), data.get("reason"), data.get("armed")
    if armed is not None and armed != last.get("armed"):
        if last.get("armed") is not None or armed:
            out.append(("phase", "Armed" if armed else "Disarmed"))
        last["armed"] = armed
    why = f" ({reason})" if reason else ""
    if phase != last.get("phase"):
        before = last.get("phase")
        out.append(("phase", f"Phase: {phase}{why}" if before is None
                    else f"Phase: {before} → {phase}{why}"))
    elif reason and reason != last.get("reason"):
        out.append(("phase", f"Phase {phase}: {reason}"))
    last["phase"], last["reason"] = phase, reason
    return out


def _link_sentences(data: dict[str, Any], last: dict[str, Any]) -> list[tuple[Category, str]]:
    out: list[tuple[Category, str]] = []
    fault, state = data.get("fault"), data.get("state")
    if fault and fault != last.get("fault"):
        out.append(("fault", f"Link lost: {fault}"))
    elif state and state != last.get("state"):
        out.append(("link", f"Link {state}"))
    last["fault"], last["state"] = fault, state
    return out


def sentences(events: Iterable[Event]) -> list[Sentence]:
    """The log of a recording's ``events`` (see the module docstring), in time order."""
    out: list[Sentence] = []
    phases: dict[str, Any] = {}
    links: dict[str, dict[str, Any]] = {}  # per device
    for e in sorted(events, key=lambda e: e.t):
        data = e.data if isinstance(e.data, dict) else {}
        found: list[tuple[Category, str]] = []
        if e.kind == "action":
            found = [action_sentence(e.text, e.who)]
        elif e.kind == "phase":
            found = _phase_sentences(data, phases)
        elif e.kind == "fault":
            found = [("fault", f"Fault: {data.get('fault')}")]
        elif e.kind == "link":
            found = _link_sentences(data, links.setdefault(str(data.get("device", "")), {}))
        out.extend(Sentence(float(e.t), cat, e.who, text) for cat, text in found)
    return out
