"""The tty-worker keeper process: kernel pty workers stay real-time while its parent runs.

``python -m hw_bridge.tty_keeper PRIORITY EVERY_S`` is started by
:class:`hw_bridge.realtime.TtyWorkerKeeper` (root only): it promotes the tty workers
(:func:`hw_bridge.realtime.promote_tty_workers`), prints how many on stdout, promotes new ones
every ``EVERY_S`` s and, when its stdin closes (the parent stopped it or went away), hands them
back to ordinary scheduling.
"""

from __future__ import annotations

import sys

from hw_bridge.realtime import demote_tty_workers, promote_tty_workers


def keep(priority: int, every: float) -> int:
    """The keeper process: promote now and every ``every`` s until stdin closes, then demote."""
    import select
    # (Its CPUs are those its parent had when starting it: the emulator starts it before
    # moving itself to the real-time CPU, so ordinary work stays off that CPU.)
    promoted = promote_tty_workers(priority)
    print(len(promoted), flush=True)
    while True:
        ready, _, _ = select.select([sys.stdin], [], [], every)
        if ready and not sys.stdin.read(1):  # EOF: the parent stopped us or went away
            break
        promoted += promote_tty_workers(priority)
    demote_tty_workers(promoted, priority)
    return 0


if __name__ == "__main__":
    sys.exit(keep(int(sys.argv[1]), float(sys.argv[2])))
