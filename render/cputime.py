"""CPU time per frame of every thread of this process and of its child processes (Linux /proc).

    before = cpu_snapshot()          # at one frame
    ...
    after = cpu_snapshot()           # at a later one
    cpu_ms_per_frame(before, after, frames)  # {"main": 4.1, "llvmpipe": 3.0, "png": 6.2, ...}

Why: end to end, the drawing loop, llvmpipe's raster threads, the PNG and MP4 encoders and the
simulation child share the machine's cores; the CPU each takes per frame says which one to cut,
and their sum against the cores says what frame rate the machine can reach at all. Threads are
grouped by name: Python threads by `threading` name less a trailing number ("png-0" -> "png"),
others by their kernel name ("llvmpipe-1" -> "llvmpipe"); child processes by their command name
("python", or "orthosim" when forked from the command: the simulation child; "ffmpeg": the MP4
encoder), all their threads together.
Elsewhere than Linux, `cpu_snapshot` returns None and the figures are left out.

A child that ends between the two snapshots (the simulation child sends its last step and exits
while the last frames are drawn) is no longer in /proc at the second one; its CPU is still
counted: the snapshot also holds what the process's waited-for children used in all
(`os.times()`), and what that grew by, less what the ended children had used at the first
snapshot, is theirs, under their group's name.
"""

from __future__ import annotations

import os
import re
import threading

_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat(path: str) -> tuple[str, float, int]:
    """(command name, user + system CPU seconds, parent pid) of one /proc stat file."""
    with open(path) as f:
        s = f.read()
    rest = s[s.rindex(")") + 2:].split()
    return s[s.index("(") + 1:s.rindex(")")], (int(rest[11]) + int(rest[12])) / _TICK, int(rest[1])


def _group(name: str) -> str:
    return re.sub(r"[-_:#]?\d+$", "", name) or name


def cpu_snapshot() -> dict[str, float] | None:
    """CPU seconds so far per thread of this process and per descendant process, keyed
    "group:id"; None where /proc is not available."""
    me = os.getpid()
    if not os.path.isdir(f"/proc/{me}/task"):
        return None
    names = {t.native_id: t.name for t in threading.enumerate()}
    out: dict[str, float] = {}
    for tid in os.listdir(f"/proc/{me}/task"):
        try:
            comm, cpu, _ = _stat(f"/proc/{me}/task/{tid}/stat")
        except (OSError, ValueError):
            continue
        name = "main" if int(tid) == me else _group(names.get(int(tid), comm))
        out[f"{name}:{tid}"] = cpu
    procs = {}
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                procs[int(pid)] = _stat(f"/proc/{pid}/stat")
            except (OSError, ValueError):
                continue
    family, grew = {me}, True
    while grew:
        grew = False
        for pid, (_, _, ppid) in procs.items():
            if ppid in family and pid not in family:
                family.add(pid)
                grew = True
    for pid in family - {me}:
        comm, cpu, _ = procs[pid]
        name = "simulation child" if comm.startswith(("python", "orthosim")) else _group(comm.split("-")[0])
        out[f"{name}:p{pid}"] = cpu  # "p": a process (a thread's key ends in its bare id)
    t = os.times()
    out[_REAPED] = t.children_user + t.children_system  # children waited for: gone from /proc
    return out


_REAPED = "reaped children:"  # a snapshot's key for the CPU of the children that ended and were waited for


def cpu_ms_per_frame(before: dict[str, float] | None, after: dict[str, float] | None, frames: int) -> dict[str, float] | None:
    """ms of CPU per frame by group between two snapshots, largest first, with their "total"."""
    if before is None or after is None or frames <= 0:
        return None
    groups: dict[str, float] = {}
    for key, cpu in after.items():
        spent = cpu - before.get(key, 0.0)
        if spent > 0 and key != _REAPED:
            name = key.rsplit(":", 1)[0]
            groups[name] = groups.get(name, 0.0) + spent
    ended = [key for key in before  # child processes gone since the first snapshot
             if key not in after and key != _REAPED and key.rsplit(":", 1)[1].startswith("p")]
    if _REAPED in before and _REAPED in after:
        # the ended children's last CPU came into os.times() when they were waited for
        spent = (after[_REAPED] - before[_REAPED]) - sum(before[key] for key in ended)
        names = {key.rsplit(":", 1)[0] for key in ended}
        if spent > 0:
            name = names.pop() if len(names) == 1 else "ended children"
            groups[name] = groups.get(name, 0.0) + spent
    out = {k: 1000.0 * v / frames for k, v in sorted(groups.items(), key=lambda kv: -kv[1])}
    out["total"] = sum(out.values())
    return out
