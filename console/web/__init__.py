"""Every touch of viser's private internals, and the client guard, in one package.

viser 1.1.1 trusts its browsers and does per-client work that does not scale to a lab of
viewers; the console fixes both by patching viser's internals, and only here. Nothing is
patched on import: a process that serves a console calls :func:`install` first (``serve.py``
does; ``ConsoleApp`` refuses to build otherwise), which checks the viser version
(:data:`TESTED_VISER_VERSION`) and the receive loop's route, then applies every patch of
``console.web.patches``. It fails closed: a browser whose messages cannot be traced to a client
guard has every message refused. Whether the patches are in place is read from viser itself
(each patch marks what it replaced), so no state is kept here; :func:`uninstall` puts viser's
own code back (tests observe upstream behaviour with it).

Modules: ``patches`` (the list of patches, each with its undo), ``receive_guard`` (viser's
receive loop with the guard in front), ``client_guard`` / ``client_message_checks`` /
``client_values`` (what a browser may send), ``shared_sends`` / ``shared_windows`` (each
message, window and frame encoded once for all viewers; ``set_bone_poses``), ``share_tunnel``
(no public tunnel), ``callback_pool`` (viser's callback threads end when idle),
``resting_redraw`` (a still page does not redraw its 3D view once a second),
``scene_clicks`` (a browser's clicks claimed by one tool), ``widgets`` (widget ids, slider
marks), ``phone_sheet`` (a style sheet for viser's phone layout), ``tab_order`` (tabs in a
chosen order). This face imports them only when called, so none of them imports back into a
half-built package.
"""

from __future__ import annotations

import dataclasses

__all__ = ["TESTED_VISER_VERSION", "IncompatibleViser", "InstallReport", "UntestedViser",
           "install", "installed", "uninstall"]

TESTED_VISER_VERSION = "1.1.1"


class UntestedViser(RuntimeError):
    """The installed viser is not the version the patches were tested on."""

    def __init__(self, found: str, tested: str = TESTED_VISER_VERSION) -> None:
        super().__init__(f"viser {found} is installed, but console.web's patches of viser's "
                         f"internals are tested on viser {tested} only (install viser=={tested}, "
                         "or allow an untested viser explicitly)")
        self.found = found
        self.tested = tested


class IncompatibleViser(RuntimeError):
    """viser's code is not shaped as the patches expect: they refuse to install."""


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


def install(*, allow_untested: bool = False) -> InstallReport:
    """Apply every patch of ``console.web.patches`` (idempotent).

    Args:
        allow_untested: Patch a viser other than :data:`TESTED_VISER_VERSION` too.

    Raises:
        UntestedViser: another viser version, not allowed (nothing is patched).
        IncompatibleViser: viser's receive route changed (nothing is patched).
    """
    import viser

    from console.web.patches import PATCHES

    found = str(viser.__version__)
    if found != TESTED_VISER_VERSION and not allow_untested:
        raise UntestedViser(found)
    applied = tuple(p.name for p in PATCHES if p.apply())
    return InstallReport(found, found == TESTED_VISER_VERSION, applied)


def installed() -> bool:
    """Whether every patch is in place."""
    from console.web.patches import PATCHES

    return all(p.applied() for p in PATCHES)


def uninstall() -> tuple[str, ...]:
    """Undo every patch (tests); the names of those that were in place."""
    from console.web.patches import PATCHES

    return tuple(p.name for p in reversed(PATCHES) if p.undo())
