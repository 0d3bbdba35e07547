"""A sequence produced in a child process and consumed in this one: the simulation beside the renderer.

    with in_child_process(simulate_case, case, "continuous") as records:
        for record in records:      # the same items, in the same order, as simulate_case(case, ...)
            ...

    child = ChildProcessIterator(preload=["orthosim.movement.simulation"])  # starts importing now
    dentition = case.build_dentition()                                      # meanwhile, here
    with child.submit(simulate_case, case, "continuous", dentition=dentition) as records:
        ...

    with in_child_process(simulate, model, "continuous", start_method="fork") as records:
        ...                                 # a copy of this process runs simulate(model, ...)

Why a process and not a thread: a simulation step is mostly Python and FCL calls that hold the
GIL, and so is much of updating the scene and feeding the encoders; on a thread the two take turns
instead of running on two cores. The child runs `factory(*args, **kwargs)` and sends each item it
yields, pickled, through a bounded queue, so it runs at most `depth` items ahead and memory stays
bounded. Two ways to start the child:
  - "spawn" (the default): a fresh interpreter, which is safe whatever threads or OpenGL contexts
    this process holds; it imports everything again (a second or more of CPU for numpy, trimesh,
    FCL and numba), `factory` and its arguments must be picklable (a module-level function), and,
    as with any spawned child, the main module must be importable again without side effects (the
    `orthosim` command, `python -c`, `-m`, or a script whose work sits under
    `if __name__ == "__main__":`); multiprocessing keeps its resource-tracker helper process until
    this one exits;
  - "fork" (`start_method="fork"`, Linux): a copy of this process at `submit`, with its imports,
    loaded caches and the arguments as they are (nothing pickled on the way in). Only for a caller
    that has started no threads and created no OpenGL context yet (`fork_is_safe` says whether
    this process has Python threads); `orthosim run` forks before it imports the renderer.
Either way only the items cross back, pickled, and the child is not daemonic, so it may start its
own worker processes (a cold sphere-tree cache builds trees over every core).

Errors: an exception raised in the child is raised again in the consumer, as the same type with the
same message (an `OrthosimError` stays one, and the CLI prints it as one line); a child that dies
without a word (killed, crashed) is reported as a `ChildProcessError`. Shutdown: leaving the `with`
block, `close()`, or exhausting the iterator stops the child and waits for it, so no process is
left behind; Ctrl-C is left to this process (the child ignores SIGINT and is stopped by `close`).
If this process is killed outright, the child ends with it (`orthosim.system.lifeline.exit_with_parent`).
"""

from __future__ import annotations

import ctypes
import gc
import importlib
import multiprocessing
import os
import pickle
import queue
import signal
import sys
import threading
import warnings
from typing import Any, Callable, Iterable, Sequence

from orthosim.system.lifeline import exit_with_parent

_ITEM, _END, _ERROR = "item", "end", "error"
_POLL_S = 0.1  # how often a waiting side checks whether the other has gone


class ChildProcessIterator:
    """Iterator over the items `factory(*args, **kwargs)` yields in a child process (see the module doc).

    Two stages, so that the child's start-up overlaps with the caller's own set-up: construction
    starts the child, which imports the `preload` modules (seconds for numpy, trimesh, FCL and
    numba) and waits; `submit` then gives it its work, whose arguments may be things the caller
    built meanwhile (a dentition). `in_child_process` does both at once. With
    `start_method="fork"` construction starts nothing (give no `preload`) and `submit` forks the
    child with its work. Use it as a context manager, or call `close`.
    """

    def __init__(self, *, depth: int = 4, name: str = "orthosim-producer", ignore_warnings: bool = False,
                 preload: Sequence[str] = (), start_method: str = "spawn"):
        if start_method not in ("spawn", "fork"):
            raise ValueError(f"start_method must be 'spawn' or 'fork', not {start_method!r}")
        if start_method == "fork" and preload:
            raise ValueError("preload is for a spawned child; a forked one has this process's imports")
        ctx = multiprocessing.get_context(start_method)
        self._ctx, self._name, self._ignore_warnings = ctx, name, ignore_warnings
        self._queue = ctx.Queue(maxsize=max(1, int(depth)))
        self._stop = ctx.Event()
        self._done = False
        self._submitted = False
        self._sender: threading.Thread | None = None
        self._work = None
        self._process = None
        if start_method == "fork":  # started by submit, with the work in hand
            return
        work_in, self._work = ctx.Pipe(duplex=False)
        try:
            self._start(ctx.Process(target=_produce, args=(work_in, self._queue, self._stop, ignore_warnings, tuple(preload),
                                                           os.getpid()), name=name, daemon=False))
        finally:
            work_in.close()  # the child's end

    def _start(self, process) -> None:
        self._process = process
        # Ctrl-C reaches every process of the terminal's foreground group; the child starts with
        # SIGINT ignored (an ignored signal stays ignored across exec and fork) and this process stops it.
        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
        try:
            process.start()
        finally:
            if main_thread:
                signal.signal(signal.SIGINT, previous)

    def submit(self, factory: Callable[..., Iterable], *args: Any, **kwargs: Any) -> "ChildProcessIterator":
        """Have the child run `factory(*args, **kwargs)` and send its items; once per child.

        spawn: the work is pickled here (an argument that cannot be pickled raises here) and written
        to the child on a thread: a large argument does not hold the caller up while the child is
        still importing. fork: the child is started now, as a copy of this process, and finds the
        work in its memory.
        """
        if self._submitted:
            raise RuntimeError("this child process has its work already")
        self._submitted = True
        if self._work is None:
            # the objects made so far are shared with the child page by page until written; the
            # collector writes to every object it scans, copying nearly all of them into both
            # processes: frozen, it leaves them alone (they are kept for the run anyway)
            gc.freeze()
            release_freed_heap()  # the child starts from the heap this process really uses
            self._start(self._ctx.Process(target=_produce, args=(None, self._queue, self._stop, self._ignore_warnings, (),
                                                                 os.getpid(), (factory, args, kwargs)),
                                          name=self._name, daemon=False))
            return self
        data = pickle.dumps((factory, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)

        def send():
            try:
                self._work.send_bytes(data)
            except OSError:  # the child is gone; __next__ reports how
                pass

        self._sender = threading.Thread(target=send, name=f"{self._process.name}-submit", daemon=True)
        self._sender.start()
        return self

    @property
    def pid(self) -> int | None:
        return None if self._process is None else self._process.pid

    def __iter__(self) -> "ChildProcessIterator":
        return self

    def __next__(self):
        if self._done:
            raise StopIteration
        if not self._submitted:
            raise RuntimeError("submit the child's work before reading its items")
        while True:
            try:
                kind, payload = self._queue.get(timeout=_POLL_S)
                break
            except queue.Empty:
                if self._done:  # closed from another thread
                    raise StopIteration from None
                if not self._process.is_alive():
                    try:  # whatever it sent before exiting is already in the pipe
                        kind, payload = self._queue.get(timeout=_POLL_S)
                        break
                    except queue.Empty:
                        code = self._process.exitcode
                        self.close()
                        raise ChildProcessError(f"{self._process.name} (pid {self.pid}) exited with code {code} "
                                                "before finishing its sequence") from None
        if kind == _ITEM:
            return pickle.loads(payload)
        self.close()
        if kind == _ERROR:
            raise pickle.loads(payload)
        raise StopIteration

    def close(self) -> None:
        """Stop the child (if it still runs) and wait for it; idempotent."""
        if getattr(self, "_closed", False):
            return
        self._closed = True
        self._done = True
        proc = self._process
        self._stop.set()
        if self._work is not None:
            self._work.close()  # a child still waiting for its work sees the end of the pipe and exits
        if proc is not None and proc.pid is not None:
            if not self._submitted:
                proc.terminate()  # no work given: it is only importing, nothing to finish
            proc.join(timeout=1.0)  # it notices the stop when it next sends, within one item
            if proc.exitcode is None:
                proc.terminate()  # e.g. still building its model
                proc.join(timeout=5.0)
            if proc.exitcode is None:
                proc.kill()
                proc.join()
        self._queue.close()
        self._queue.cancel_join_thread()

    def __enter__(self) -> "ChildProcessIterator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        if hasattr(self, "_process"):
            try:
                self.close()
            except Exception:  # e.g. at interpreter exit, where multiprocessing stops its children itself
                pass


def in_child_process(factory: Callable[..., Iterable], *args: Any, depth: int = 4, ignore_warnings: bool = False,
                     start_method: str = "spawn", **kwargs: Any) -> ChildProcessIterator:
    """The items of `factory(*args, **kwargs)`, made in a child process (`ChildProcessIterator`).

    depth: how many items the child may run ahead. ignore_warnings: the child drops Python
    warnings (when this process does the same work first and reports them once).
    start_method: "spawn" or "fork" (see the module doc).
    """
    return ChildProcessIterator(depth=depth, ignore_warnings=ignore_warnings,
                                start_method=start_method).submit(factory, *args, **kwargs)


def fork_is_safe() -> bool:
    """Whether this process may fork a child that goes on working: on Linux (macOS's system
    libraries do not survive a fork), and with no Python thread running but the main one (a thread
    holding a lock at the fork would leave it held for ever in the child). OpenGL contexts are the
    caller's to avoid."""
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and threading.active_count() == 1
            and threading.current_thread() is threading.main_thread())


def release_freed_heap() -> bool:
    """Hand the C heap's free pages back to the system (glibc `malloc_trim`): building a model
    leaves tens of MB freed but still mapped (measured: a 28-tooth child, 327 -> 298 MB). Milliseconds;
    False where the C library is not glibc."""
    try:
        # the symbols already loaded into this process: no library search (find_library runs
        # ldconfig in a subprocess, ~2 ms, on each of a run's two calls)
        return bool(ctypes.CDLL(None).malloc_trim(0))
    except (OSError, AttributeError):
        return False
def _portable(exc: BaseException) -> bytes:
    """The pickled exception, or a RuntimeError naming it when it cannot cross a process boundary."""
    try:
        data = pickle.dumps(exc)
        pickle.loads(data)
        return data
    except Exception:
        return pickle.dumps(RuntimeError(f"{type(exc).__name__}: {exc}"))


def _produce(work, q, stop, ignore_warnings: bool, preload: tuple[str, ...], parent_pid: int, given=None) -> None:
    """The child: import, wait for the work (or take it as `given`, when forked), run the factory,
    send its items, then the end or the error."""
    exit_with_parent(parent_pid)  # a parent killed outright cannot stop us: end with it
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a forked child inherits the CLI's SIGTERM handler: `close` ends it now
    if ignore_warnings:
        warnings.simplefilter("ignore")
    parent = os.getppid()

    def send(kind: str, payload: bytes) -> bool:
        while not stop.is_set():
            try:
                q.put((kind, payload), timeout=_POLL_S)
                return True
            except queue.Full:
                if os.getppid() != parent:  # the consumer is gone without closing us
                    return False
        return False

    try:
        for module in preload:
            importlib.import_module(module)
        if given is not None:
            factory, args, kwargs = given
        else:
            try:
                factory, args, kwargs = pickle.loads(work.recv_bytes())
            except EOFError:  # closed before it gave any work
                return
            finally:
                work.close()
        items = iter(factory(*args, **kwargs))
        try:
            for item in items:
                # pickled here, not in the queue's feeder thread, so that an unpicklable item is an
                # error of the sequence, reported in order, rather than a traceback on stderr
                if not send(_ITEM, pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)):
                    break
            else:
                send(_END, b"")
        finally:
            close = getattr(items, "close", None)
            if close is not None:
                close()
    except BaseException as exc:  # handed to the consumer
        send(_ERROR, _portable(exc))
    if stop.is_set():
        q.cancel_join_thread()  # nobody reads any more: do not wait to flush
