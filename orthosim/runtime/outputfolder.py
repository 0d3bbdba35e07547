"""The output folder of a run: checked before any work, written privately, swapped in whole at the end.

    with output_folder(out_dir) as staging:   # refuses a bad --out now, in one line
        ...write every output into staging...  # run.json last
    # out_dir now holds this run's outputs and nothing else

Why a private staging folder rather than writing into `out_dir` directly: a run that fails or is
stopped part-way (disk full, Ctrl-C, SIGTERM, a crash) must leave the folder as it was, and a
rerun must replace an earlier run's outputs whole (no stale frames beyond the new count), which
file-by-file atomic writes cannot give. The staging folder sits beside the target (same file
system, so the final move is a rename) as `.NAME.orthosim-staging-PID`; on success it takes the
target's place in one atomic exchange (Linux `renameat2(RENAME_EXCHANGE)`, two renames
elsewhere), and the earlier run is deleted afterwards. On failure it is deleted and the target is
untouched.

Two runs into one folder: a lock file beside the target (`.NAME.orthosim-lock`, held with
`flock` for the whole run) refuses the second at once with a clear message. Staging folders left
by a run that was killed outright (SIGKILL, power loss) are removed by the next run into the same
folder, which holds the lock and so knows they are stale.

An existing folder is replaced only when it holds an orthosim run (it has run.json, or only the
files a run writes); any other folder is refused, so `--out ~/Documents` never deletes anything.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import shutil
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from orthosim.errors import OrthosimError
from orthosim.runtime.runfolder import RUN_FILE

# What an `orthosim run` folder may hold without run.json (a run from before run.json existed):
# such a folder is an earlier run, and may be replaced.
RUN_OUTPUTS = frozenset({RUN_FILE, "metrics.json", "distances.csv", "distances_per_step.csv", "steps.jsonl", "frames",
                         "scene", "animation.mp4", "animation.gif", "evidence.json", "index.html"})
_STAGING = ".orthosim-staging-"
_OLD = ".orthosim-old-"
_LOCK = ".orthosim-lock"
_DISK_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO}
_NEARLY_FULL_BYTES = 1 << 20  # a writer that fails with this little room left failed for want of it


class OutputFolderError(OrthosimError):
    """`--out` cannot take this run: a file, unwritable, read-only, busy, foreign, or the disk filled."""


def check_output_folder(target: str | Path, carry: tuple[str, ...] = ()) -> Path:
    """Refuse, in one line, an `--out` that cannot take a run; returns it as an absolute path.

    carry: names in the folder that are the run's inputs (its case file), kept across the swap.

    Only what can be told without writing: a file in the way, a foreign folder. Whether the place
    can be written is found by creating the staging folder (`output_folder`), the only test that
    holds for root, read-only mounts and network file systems alike.
    """
    target = Path(os.path.abspath(target))
    where = f"--out {target}"
    if target.exists() and not target.is_dir():
        raise OutputFolderError(where, None, "is a file, not a folder", "give a folder path (new or from an earlier run)")
    if target.is_dir():
        try:
            names = {p.name for p in target.iterdir()}
        except OSError as err:
            raise OutputFolderError(where, None, f"cannot be read ({err.strerror})", "give a folder you can write") from None
        foreign = sorted(n for n in names if n not in RUN_OUTPUTS and n not in carry)
        if foreign and RUN_FILE not in names:
            raise OutputFolderError(where, None, f"holds files that no orthosim run wrote ({', '.join(foreign[:3])}"
                                    f"{', ...' if len(foreign) > 3 else ''}), which replacing it would delete",
                                    "give a new or empty folder, or one an earlier run wrote")
    parent = target.parent
    if parent.exists() and not parent.is_dir():
        raise OutputFolderError(where, None, f"{parent} is a file, not a folder", "give a path inside a folder")
    return target


@contextmanager
def output_folder(target: str | Path, carry: tuple[str, ...] = ()) -> Iterator[Path]:
    """Check `target`, lock it, and yield a private staging folder that replaces it whole on success.

    carry: files of the target that are the run's own inputs (a batch writes each variant's
    case.toml into its run folder, then runs it there): copied into the staging folder first, so
    the finished folder still holds them.

    Raises OutputFolderError (one line) before any work when the target cannot take the run, when
    another run holds it, and after a failure to write for want of space or permission (the
    target then left as it was). Any other error passes through, the target equally untouched.
    """
    target = check_output_folder(target, carry)
    where = f"--out {target}"
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputFolderError(where, None, f"its folder {parent} cannot be created ({err.strerror})",
                                "give a path where you can write") from None
    with _locked(target, where):
        _remove_stale(target)
        staging = parent / f".{target.name}{_STAGING}{os.getpid()}"
        try:
            staging.mkdir()
        except OSError as err:
            raise OutputFolderError(where, None, f"cannot be written ({err.strerror})",
                                    "give a folder on a writable file system where you have write permission") from None
        try:
            for name in carry:
                if (target / name).is_file():
                    shutil.copy2(target / name, staging / name)
            yield staging
            _swap_in(staging, target)
        except BaseException as exc:
            disk = _disk_error(exc, parent)  # before the staging folder's space is given back
            shutil.rmtree(staging, ignore_errors=True)
            if disk is not None:
                raise OutputFolderError(where, None, f"writing the run failed ({disk}); the folder is left as it was "
                                        "before the run", "free space on that disk or give another --out") from None
            raise


@contextmanager
def _locked(target: Path, where: str) -> Iterator[None]:
    """Hold the target's lock file for the block; refuse at once if another run holds it."""
    import fcntl

    lock = target.parent / f".{target.name}{_LOCK}"
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as err:
            raise OutputFolderError(where, None, f"cannot be written ({err.strerror})",
                                    "give a folder on a writable file system where you have write permission") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            holder = _read_holder(lock)
            raise OutputFolderError(where, None, f"another orthosim run{holder} is writing this folder",
                                    "wait for it to finish, or give another --out") from None
        # the holder before us may have removed the file between our open and our lock: then we
        # hold a lock nobody else can see; start again on the file that is there now
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        try:
            os.unlink(lock)  # while still held: the next run makes a fresh one
        except OSError:
            pass
        os.close(fd)


def _read_holder(lock: Path) -> str:
    try:
        pid = int(lock.read_text().split()[0])
        return f" (pid {pid})"
    except (OSError, ValueError, IndexError):
        return ""


def clear_leftovers(target: str | Path) -> None:
    """What runs killed mid-way left beside `target` (staging folders, a replaced folder not yet
    deleted, the lock file), removed while no run holds the folder. For a finished run that is kept
    rather than run again (a resumed batch): a kill that landed while its folder was being swapped
    in leaves the earlier copy beside it."""
    target = Path(target)
    try:
        with _locked(target, str(target)):
            _remove_stale(target)
    except OutputFolderError:
        pass  # another run holds it (or the place cannot be written): that run clears its own


def _remove_stale(target: Path) -> None:
    """Staging and replaced folders of this target left by runs that were killed (we hold the lock)."""
    for prefix in (_STAGING, _OLD):
        for stale in target.parent.glob(f".{target.name}{prefix}*"):
            shutil.rmtree(stale, ignore_errors=True)


def _swap_in(staging: Path, target: Path) -> None:
    """Put `staging` at `target`'s path in one step and delete what was there."""
    if not target.exists():
        os.rename(staging, target)
        return
    old = target.parent / f".{target.name}{_OLD}{os.getpid()}"
    if _exchange(staging, target):
        os.rename(staging, old)  # staging's path now holds the earlier run
    else:  # no atomic exchange here: a moment with no folder at target, never a mixed one
        os.rename(target, old)
        os.rename(staging, target)
    shutil.rmtree(old, ignore_errors=True)


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2); False where the system cannot."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):  # file system without exchange
        return False
    raise OSError(code, os.strerror(code), str(b))


def _disk_error(exc: BaseException, folder: Path) -> str | None:
    """'No space left on device' and the like, if `exc` (or what caused it) is a failure to write.

    A writer in another process (the ffmpeg encoder) reports a full disk only as a broken pipe or
    its own message, so a failure with the disk (nearly) full counts as one too.
    """
    seen, link = set(), exc
    while link is not None and id(link) not in seen:
        seen.add(id(link))
        if isinstance(link, OSError) and link.errno in _DISK_ERRNOS:
            return link.strerror or os.strerror(link.errno)
        link = link.__cause__ or link.__context__
    try:
        if isinstance(exc, Exception) and shutil.disk_usage(folder).free < _NEARLY_FULL_BYTES:
            return os.strerror(errno.ENOSPC)
    except OSError:
        pass
    return None
