"""`orthosim bench`'s `render_backends`: render frames per second through every offscreen OpenGL
backend found on this machine (an EGL GPU, EGL on Mesa's software device, OSMesa), in one run.

PyOpenGL fixes its platform once per process, so each backend draws in its own child process
(`python -m orthosim_bench.backends`, with ORTHOSIM_GL naming the backend), running the same
render-alone loop as the bench's `render` figure (draw plus colour read-back, the scene updated
outside the timed region, `SyntheticMotion` on every tooth with its contact markers). The children
are started once and take turns: each draws a short batch of frames while the others wait, for
`rounds` rounds (A, B, A, B, ...), so that every backend sees the same machine load even on a
shared machine whose load drifts; each backend's figure is 1 / the median of all its frame times,
and the ratio of each backend to OSMesa is taken within this one run (`ratios`: fps / OSMesa's fps;
`cpu_ratios`: OSMesa's CPU ms per frame, every thread of the process, / the backend's, the figure
a loaded machine moves least).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from orthosim_bench.subruns import SubRunFailed, exit_failure

_MARK = "render_backends:"


def _serve(case: Path, size: tuple[int, int], n_markers: int) -> None:
    """Child: build the scene once, then draw as many frames as each stdin line asks and print their times."""
    import time

    from orthosim.exchange.case import load_case

    from orthosim_bench.render import SyntheticMotion
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    dentition = load_case(case).build_dentition()
    motion = SyntheticMotion(dentition, n_markers=n_markers)
    renderer = Renderer(size)
    scene = DentitionScene(dentition, size)
    print(_MARK + json.dumps({"backend": renderer.backend.label, "gl_renderer": renderer.gl_renderer,
                              "gl_version": renderer.gl_version}), flush=True)
    i = 0
    for line in sys.stdin:
        times, cpu_s = [], 0.0
        for _ in range(int(line)):
            scene.update(motion(i))
            i += 1
            t0, c0 = time.perf_counter(), time.process_time()  # process time: llvmpipe's raster threads too
            renderer.render(scene, "frontal")
            times.append(time.perf_counter() - t0)
            cpu_s += time.process_time() - c0
        print(_MARK + json.dumps({"times": times, "cpu_s": cpu_s}), flush=True)
    renderer.close()


class _Child:
    """One backend's drawing process (see `_serve`)."""

    def __init__(self, backend: str, case: Path, size, n_markers: int):
        env = {**os.environ, "ORTHOSIM_GL": backend}
        env.pop("PYOPENGL_PLATFORM", None)  # the child's own choice sets it
        argv = [sys.executable, "-m", "orthosim_bench.backends", str(case), f"{size[0]}x{size[1]}", str(n_markers)]
        self.backend = backend
        self.proc = subprocess.Popen(argv, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.info = self._read()

    def _read(self):
        for line in self.proc.stdout:
            if line.startswith(_MARK):
                return json.loads(line[len(_MARK):])
        raise SubRunFailed("render_backends", exit_failure("render_backends", f"the render bench through {self.backend}",
                                                           self.proc.wait(), "(its standard error, above, says why)").why)

    def draw(self, frames: int) -> dict:
        self.proc.stdin.write(f"{frames}\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self) -> int:
        """Ends the child; its exit status."""
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()
        return self.proc.wait()


def render_backends(case: str | Path, size: tuple[int, int] = (640, 480), frames: int = 150, warmup: int = 20,
                    n_markers: int = 2000, rounds: int | None = None) -> dict:
    """{"fps": {label: {...}}, "ratios": {...}, ...}: every backend found, each in its own process (see above).

    `frames` measured frames per backend, in `rounds` turns (default: 5 frames a turn: a shared
    machine's load swings within seconds), after `warmup` frames each. Probes the
    system libraries only (`glbackend.available_backends`): call it while this process holds no GL
    context, since the EGL probe initialises and terminates each device's display.
    """
    from orthosim_render.offscreen_backend import available_backends

    labels = list(dict.fromkeys(b.label for b in available_backends()))
    children = []
    try:
        for label in labels:
            children.append(_Child(label, Path(case), size, n_markers))
        times: dict[str, list[float]] = {c.backend: [] for c in children}
        cpu: dict[str, float] = {c.backend: 0.0 for c in children}
        for child in children:
            child.draw(warmup)
        rounds = rounds or max(1, frames // 5)
        per_turn = max(1, frames // rounds)
        for _ in range(rounds):
            for child in children:
                turn = child.draw(per_turn)
                times[child.backend] += turn["times"]
                cpu[child.backend] += turn["cpu_s"]
    finally:
        codes = {child.backend: child.close() for child in children}
    failed = {backend: code for backend, code in codes.items() if code != 0}
    if failed:  # a backend's figures are those of a child that finished cleanly, or none
        backend, code = next(iter(failed.items()))
        raise SubRunFailed("render_backends", exit_failure("render_backends", f"the render bench through {backend}", code).why)
    fps = {c.backend: {"fps": 1.0 / statistics.median(times[c.backend]), "frames": len(times[c.backend]),
                       "cpu_ms_per_frame": 1000.0 * cpu[c.backend] / len(times[c.backend]),
                       "gl_renderer": c.info["gl_renderer"], "gl_version": c.info["gl_version"]} for c in children}
    ratios = {f"{label}_to_osmesa": fps[label]["fps"] / fps["osmesa"]["fps"]
              for label in fps if label != "osmesa" and "osmesa" in fps}
    # CPU per frame (all threads): what a frame costs whatever else the machine runs; osmesa / backend, so
    # above 1 means the backend costs less
    cpu_ratios = {f"{label}_to_osmesa": fps["osmesa"]["cpu_ms_per_frame"] / fps[label]["cpu_ms_per_frame"]
                  for label in fps if label != "osmesa" and "osmesa" in fps}
    return {"fps": fps, "ratios": ratios, "cpu_ratios": cpu_ratios, "backends_found": labels, "size": list(size), "warmup": warmup,
            "contact_markers": n_markers, "rounds": rounds,
            "egl_software_no_slower_than_osmesa": (ratios["egl/software_to_osmesa"] >= 1.0
                                                   if "egl/software_to_osmesa" in ratios else None)}


def main(argv: list[str]) -> None:
    case, size, markers = argv
    w, h = (int(v) for v in size.split("x"))
    _serve(Path(case), (w, h), int(markers))


if __name__ == "__main__":
    main(sys.argv[1:])
