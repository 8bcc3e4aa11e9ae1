"""Every touch of viser's private internals, and the client guard, in one package.

viser 1.1.1 trusts its browsers and does per-client work that does not scale to a lab of
viewers; the console fixes both by patching viser's internals, and only here. Nothing is
patched on import: a process that serves a console calls :func:`install` first (``serve.py``
does; ``ConsoleApp`` refuses to build otherwise), which checks the viser version
(:data:`TESTED_VISER_VERSION`) and the receive loop's route, and fails closed: a browser whose
messages cannot be traced to a client guard has every message refused.

Modules: ``patches`` (install / uninstall / installed), ``receive_guard`` (viser's receive loop
with the guard in front), ``client_guard`` / ``client_message_checks`` / ``client_values``
(what a browser may send), ``shared_sends`` / ``shared_windows`` (each message, window and frame
encoded once for all viewers; ``set_bone_poses``), ``share_tunnel`` (no public tunnel),
``scene_clicks`` (a browser's clicks claimed by one tool), ``widgets`` (widget ids, slider
marks).
"""

from console.web.patches import (TESTED_VISER_VERSION, InstallReport, UntestedViser, install,
                                 installed, uninstall)
from console.web.receive_guard import IncompatibleViser

__all__ = ["TESTED_VISER_VERSION", "IncompatibleViser", "InstallReport", "UntestedViser",
           "install", "installed", "uninstall"]
