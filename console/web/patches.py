"""Installs viser's patches on purpose, once, on the viser version they were tested on.

Nothing in ``console.web`` changes viser on import. :func:`install` checks ``viser.__version__``
against :data:`TESTED_VISER_VERSION` (another version is refused with :class:`UntestedViser`
unless the caller allows it), checks the receive loop's route
(``console.web.receive_guard.check_route``; a viser that no longer has it raises
:class:`~console.web.receive_guard.IncompatibleViser` whatever was allowed), then applies every
patch in :data:`PATCHES`. Whether they are in place is read from viser itself (each patch marks
what it replaced), so there is no state here; :func:`uninstall` puts viser's own code back
(tests observe upstream behaviour with it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from console.web import receive_guard, shared_sends, shared_windows

TESTED_VISER_VERSION = "1.1.1"


class UntestedViser(RuntimeError):
    """The installed viser is not the version the patches were tested on."""

    def __init__(self, found: str, tested: str = TESTED_VISER_VERSION) -> None:
        super().__init__(f"viser {found} is installed, but console.web's patches of viser's "
                         f"internals are tested on viser {tested} only (install viser=={tested}, "
                         "or allow an untested viser explicitly)")
        self.found = found
        self.tested = tested


@dataclasses.dataclass(frozen=True)
class Patch:
    """One change to viser: what it is called, how to apply it and how to undo it."""

    name: str
    apply: Callable[[], bool]
    undo: Callable[[], bool]


#: Every patch, in the order they are applied (the receive guard first: it may refuse).
PATCHES: tuple[Patch, ...] = (
    Patch("client guard in front of _message_consumer", receive_guard.install,
          receive_guard.uninstall),
    Patch("loop-safe AsyncMessageBuffer events", shared_sends.loop_safe_events,
          shared_sends.upstream_events),
    Patch("Message.as_serializable_dict shared by clients", shared_sends.share_wire_dicts,
          shared_sends.unshare_wire_dicts),
    Patch("_message_producer frames shared by clients", shared_sends.share_frames,
          shared_sends.unshare_frames),
    Patch("AsyncMessageBuffer._window_loop windows shared by clients", shared_windows.install,
          shared_windows.uninstall),
)


@dataclasses.dataclass(frozen=True)
class InstallReport:
    """What :func:`install` did.

    Attributes:
        viser_version: ``viser.__version__``.
        tested: Whether that is :data:`TESTED_VISER_VERSION`.
        applied: The patches applied by this call (empty when all were in place already).
    """

    viser_version: str
    tested: bool
    applied: tuple[str, ...]


def viser_version() -> str:
    """The installed viser's ``__version__``."""
    import viser

    return str(viser.__version__)


def check_version(*, allow_untested: bool = False) -> str:
    """The installed viser's version; raises :class:`UntestedViser` if it is not the tested one
    and ``allow_untested`` is False."""
    found = viser_version()
    if found != TESTED_VISER_VERSION and not allow_untested:
        raise UntestedViser(found)
    return found


def install(*, allow_untested: bool = False) -> InstallReport:
    """Apply every patch in :data:`PATCHES` (idempotent).

    Args:
        allow_untested: Patch a viser other than :data:`TESTED_VISER_VERSION` too.

    Raises:
        UntestedViser: another viser version, not allowed.
        IncompatibleViser: viser's receive route changed (nothing is patched then).
    """
    found = check_version(allow_untested=allow_untested)
    applied = tuple(p.name for p in PATCHES if p.apply())
    return InstallReport(found, found == TESTED_VISER_VERSION, applied)


def uninstall() -> tuple[str, ...]:
    """Undo every patch (tests); the names of those that were in place."""
    return tuple(p.name for p in reversed(PATCHES) if p.undo())


def installed() -> bool:
    """Whether every patch is in place."""
    from viser.infra import _async_message_buffer as amb
    from viser.infra import _infra
    from viser.infra import _messages as infra_messages

    buffer_cls = amb.AsyncMessageBuffer
    return all((getattr(_infra._message_consumer, "_client_guard", False),
                getattr(buffer_cls, "_loop_safe_event", False),
                getattr(infra_messages.Message, "_shared_wire_dicts", False),
                getattr(_infra._message_producer, "_shared_frames", False),
                getattr(buffer_cls, "_shared_windows", False)))
