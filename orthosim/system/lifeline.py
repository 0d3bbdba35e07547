"""How orthosim's processes end together: helpers die with the process that started them, and
SIGTERM stops a run the way Ctrl-C does.

A run has helper processes: the simulation child (`orthosim.runtime.background`), the sphere-tree build
workers (`orthosim.spheretree.cache`) and the ffmpeg encoder (which ends by itself when its input
pipe closes). When the main process is killed outright (SIGKILL, the OOM killer), nothing in it
runs to stop them, so each helper arranges its own end: `exit_with_parent` asks Linux to send it
SIGKILL when its parent goes (prctl PR_SET_PDEATHSIG), and where that is not available a daemon
thread watches the parent's pid instead. Either way no helper outlives the run by more than a
fraction of a second, and none is left an orphan.

`sigterm_as_interrupt` makes SIGTERM (what `kill`, systemd, Slurm and CI runners send) run the
same clean stop as Ctrl-C: it calls whatever SIGINT handler is in force (so the renderer's "stop
between frames" applies too) and remembers that it was a SIGTERM, so the CLI can exit 143.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time

_PR_SET_PDEATHSIG = 1
_WATCH_S = 0.2


def exit_with_parent(parent_pid: int) -> None:
    """Make this process end as soon as `parent_pid` (the process that started it) is gone.

    Called first thing in a helper process. `parent_pid` is the pid the parent had when it started
    us: if it is already gone (we are an orphan before we could arrange anything), exit now.
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            # the death signal fires when the parent *thread* that forked us exits; orthosim starts
            # its helpers from the main thread, which lives as long as the process
            if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
                if os.getppid() != parent_pid:
                    os._exit(1)
                return
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(_WATCH_S)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


_terminated: list[int] = []


def sigterm_as_interrupt() -> None:
    """From now on SIGTERM stops this process as Ctrl-C would (main thread only)."""

    def on_sigterm(signum, frame):
        _terminated.append(signum)
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):
            handler(signal.SIGINT, frame)
        else:
            raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_sigterm)


def terminated() -> bool:
    """Whether a SIGTERM has asked this process to stop."""
    return bool(_terminated)
