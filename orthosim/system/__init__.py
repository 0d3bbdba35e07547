"""The process around orthosim: how its processes end together and how the C heap is tuned.

`firstrun` (a long first step, building or compiling what later runs load from the caches, says
so on stderr in one line), `lazy` (a package's names imported on first use), `lifeline` (helper processes die with their parent; SIGTERM stops a run as Ctrl-C does), `malloc`
(glibc's heap told to keep freed memory, so the collision step stops paying page faults).
"""
