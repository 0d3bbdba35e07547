"""The process around orthosim: how its processes end together and how the C heap is tuned.

`lifeline` (helper processes die with their parent; SIGTERM stops a run as Ctrl-C does), `malloc`
(glibc's heap told to keep freed memory, so the collision step stops paying page faults).
"""
