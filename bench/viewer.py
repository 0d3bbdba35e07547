"""The 3D page's size and speed: animation.glb and viewer.html of a paper case and of a 300k-triangle scan.

    .venv/bin/python -m orthosim_bench.viewer --out out/viewer-bench.json

For each scene: the GLB's and the page's bytes (the page's own code apart), the seconds to write
both, and in headless Chromium (WebGL2 through SwiftShader, the software GPU: a machine with a GPU
is faster) the milliseconds from navigation to the first drawn frame and per frame afterwards
(`viewer_check.open_viewer`, median of `loads` loads, 640x480, antialiased), beside the baseline of
the same run: orthosim's offscreen renderer (llvmpipe) drawing the same keyframes. Scenes: case 1 (the paper's, simulated in
this process, every step a keyframe) and a labelled upper-arch scan of at least 300,000 triangles
built as `scanarch.labelled_scan_timings` builds it (the smooth parametric crowns subdivided, the gum
collar given rings), loaded as a `labelled-scan` model, with one incisor moved over 20 keyframes (the
scene's bytes are its meshes; the keyframes add 28 bytes per tooth each). Targets (issue 41): the
scan's GLB under 30 MB (`treatment_gltf.MAX_GLB_BYTES`), the page's own code under 1 MB.
"""

from __future__ import annotations

import json
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np


def offscreen_frame_ms(dentition, keyframes, size=(640, 480)) -> float:
    """The baseline measured in the same run: ms per frame of orthosim's offscreen renderer drawing
    the same keyframes (frontal view, `size`), median, the first (set-up) frame left out."""
    from orthosim_render.frame_state import FrameState
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    scene = DentitionScene(dentition, size)
    times = []
    with Renderer(size) as renderer:
        for k in list(keyframes)[:11]:
            scene.update(FrameState(poses=k.poses, extracted=k.hidden, moving=k.moving))
            started = time.perf_counter()
            renderer.render(scene, "frontal")
            times.append(1000 * (time.perf_counter() - started))
    return statistics.median(times[1:])


def _page_figures(out: Path, dentition, keyframes, title: str, loads: int) -> dict:
    from orthosim_render.viewer_check import open_viewer
    from orthosim_render.viewer_page import page_code_bytes, write_viewer

    started = time.perf_counter()
    files = write_viewer(out, dentition, keyframes, title)
    write_s = time.perf_counter() - started
    opened = [open_viewer(files["viewer"], test=False, measure_frames=10) for _ in range(loads)]
    errors = sorted({e for o in opened for e in o.errors})
    return {"keyframes": len(keyframes), "triangles": sum(len(t.mesh.faces) for t in dentition.teeth.values())
            + sum(len(g.faces) for g in dentition.gingiva.values()),
            "glb_bytes": files["glb"].stat().st_size, "page_bytes": files["viewer"].stat().st_size,
            "page_code_bytes": page_code_bytes(), "write_s": round(write_s, 3),
            "first_frame_ms": statistics.median(o.drawn_ms for o in opened if o.drawn_ms is not None) if not errors else None,
            "frame_ms": statistics.median(o.frame_ms for o in opened if o.frame_ms is not None) if not errors else None,
            "offscreen_frame_ms": offscreen_frame_ms(dentition, keyframes), "errors": errors}


def case_keyframes(case_path: Path):
    """(dentition, keyframes) of a case simulated in this process, every step a keyframe."""
    from orthosim.exchange.case import load_case
    from orthosim.runtime.strategies import step_records
    from orthosim_render.viewer_page import SceneRecorder

    case = load_case(case_path)
    with step_records(case, case.detector, in_process=True) as source:
        recorder = SceneRecorder(source.dentition, case.extractions)
        for _ in recorder.watch(source.records):
            pass
    return source.dentition, recorder.keyframes


def scan_keyframes(folder: Path, faces_target: int = 300_000):
    """(dentition, keyframes) of a labelled upper-arch scan of at least `faces_target` triangles, one
    incisor moved 2 mm lingually and turned 6 degrees over 20 keyframes."""
    import trimesh

    from orthosim.exchange.labelledscan import load_labelled_scans
    from orthosim.model.parametric import parametric_dentition
    from orthosim_bench.scanarch import write_labelled_arch
    from orthosim_render.treatment_gltf import SceneKeyframe

    model = parametric_dentition("smooth")

    def scan(rings: int):
        path = write_labelled_arch(model, "upper", folder, "viewer", subdivisions=1, gum_rings=rings)
        return path, len(trimesh.load(path, force="mesh", process=False).faces)

    _, two = scan(2)
    _, three = scan(3)
    path, _ = scan(max(2, 2 + int(np.ceil((faces_target - two) / (three - two)))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dentition = load_labelled_scans(path, None)
    rest = dentition.rest_poses()
    tooth = 11 if 11 in rest else next(iter(rest))
    frames = []
    for k in range(21):
        a = np.radians(6.0 * k / 20)
        pose = rest[tooth].copy()
        turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        pose[:3, :3] = turn @ pose[:3, :3]
        pose[:3, 3] += [0.0, 0.0, -2.0 * k / 20]
        frames.append(SceneKeyframe(k, 30.0 * k, {**rest, tooth: pose}, moving=frozenset({tooth}) if k else frozenset()))
    return dentition, frames


def viewer_figures(case_path: Path | None = None, loads: int = 3) -> dict:
    """The figures of the module doc, for case 1 (or `case_path`) and the 300k-triangle scan."""
    from orthosim.exchange.case import DEFAULT_CASE
    from orthosim_render.treatment_gltf import MAX_GLB_BYTES

    out = {"target_glb_bytes": MAX_GLB_BYTES, "target_page_code_bytes": 1_000_000, "browser": "headless Chromium, SwiftShader WebGL2"}
    with tempfile.TemporaryDirectory(prefix="orthosim-viewer-bench-") as tmp:
        dentition, keyframes = case_keyframes(Path(case_path or DEFAULT_CASE))
        out["case"] = _page_figures(Path(tmp) / "case", dentition, keyframes, "case", loads)
        dentition, keyframes = scan_keyframes(Path(tmp) / "scan")
        out["scan"] = _page_figures(Path(tmp) / "scanpage", dentition, keyframes, "scan", loads)
    return out


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/viewer-bench.json"))
    parser.add_argument("--loads", type=int, default=3)
    args = parser.parse_args()
    figures = viewer_figures(loads=args.loads)
    from orthosim.storage.atomic import write_text

    write_text(args.out, json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
