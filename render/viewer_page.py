"""`viewer.html` and `animation.glb`: the interactive 3D page of a run, a staging or a report.

    recorder = SceneRecorder(dentition, extracted)       # while a run's records stream past
    frames = frames_from_steps(recorder.watch(records), ...)
    recorder.write(out_dir, title=case.name)              # animation.glb + viewer.html

The page is one file that works from a file:// URL with no network: Chromium refuses to fetch a
sibling file from a file:// page, so the scene travels inside it, the GLB base64-encoded, beside
our own WebGL2 code (`render/viewer/`: viewer.js and the GLSL ES 3.00 shaders ported from
`render/shaders/`), inlined by a Jinja2 template (autoescaped; the inlined JSON and script have
every `</` escaped). The colours, light rig, legend and camera presets are the frames' own
(`orthosim_render.scene`, `overlay`, `cameras`). Both files are written atomically.
"""

from __future__ import annotations

import base64
import json
from functools import lru_cache
from pathlib import Path
from typing import Iterable, Iterator, Sequence

from orthosim.model import fdi as F
from orthosim.storage.atomic import write_bytes, write_text

from orthosim_render.cameras import VIEW_NAMES
from orthosim_render.scene import (AMBIENT, BACKGROUND, CONTACT_COLOR, CROWN_COLOR, ESTIMATED_ROOT_COLOR,
                                   GINGIVA_COLOR, LIGHT_RIG, MOVING_TINT, OCCLUSAL_MARGIN, ROOT_COLOR)
from orthosim_render.treatment_gltf import MM, ContactLocator, SceneKeyframe, keyframe_of_record, treatment_glb

ASSETS = Path(__file__).with_name("viewer")
SHADER_FILES = ("tooth.vert", "tooth.frag", "id.vert", "id.frag")
GLB_NAME = "animation.glb"
PAGE_NAME = "viewer.html"
VIEW_CAPTIONS = {"frontal": "Frontal", "right_buccal": "Right buccal", "left_buccal": "Left buccal",
                 "maxillary_occlusal": "Maxillary occlusal", "mandibular_occlusal": "Mandibular occlusal"}


def _css(rgb) -> str:
    return "#" + "".join(f"{int(round(255 * min(max(v, 0.0), 1.0))):02x}" for v in rgb)


def legend(dentition) -> list[tuple[str, str]]:
    """(name, CSS colour) of each colour the page shows, as the frames' legend names them."""
    items = [("crown", _css(CROWN_COLOR))]
    kinds = {t.root_kind for t in dentition.teeth.values()}
    if kinds - {"estimated"}:
        items.append(("root", _css(ROOT_COLOR)))
    if "estimated" in kinds:
        items.append(("estimated root", _css(ESTIMATED_ROOT_COLOR)))
    items += [("moving", _css([c * t for c, t in zip(CROWN_COLOR, MOVING_TINT)])), ("contact", _css(CONTACT_COLOR))]
    if dentition.gingiva:
        items.append(("gum (scan)", _css(GINGIVA_COLOR)))
    return items


def _inline_json(value) -> str:
    """JSON safe inside a <script> element: no `</` can close it early."""
    return json.dumps(value, separators=(",", ":")).replace("</", "<\\/")


@lru_cache(maxsize=1)
def _assets() -> tuple[str, str, str]:
    """(template text, viewer.js, shaders as JSON), read once."""
    shaders = {name: (ASSETS / name).read_text() for name in SHADER_FILES}
    return ((ASSETS / "viewer.html.j2").read_text(), (ASSETS / "viewer.js").read_text().replace("</", "<\\/"),
            _inline_json(shaders))


def page_code_bytes() -> int:
    """Bytes of the page's own code (template, script, shaders), without the scene: held under 1 MB."""
    return sum(len(text.encode()) for text in _assets())


def viewer_html(glb: bytes, dentition, title: str, timeline: str = "day") -> str:
    """The page (one string) that plays `glb`, the scene `treatment_glb` wrote for `dentition`."""
    from jinja2 import Environment
    from markupsafe import Markup

    template, script, shaders = _assets()
    config = {"background": list(BACKGROUND), "ambient": list(AMBIENT),
              "light_rig": [[list(d), list(c), k] for d, c, k in LIGHT_RIG],
              "names": {str(n): F.name(n) for n in dentition.fdis}, "occlusal_margin": OCCLUSAL_MARGIN * MM}
    page = Environment(autoescape=True).from_string(template)
    return page.render(title=title, timeline=timeline, background_css=_css(BACKGROUND), legend=legend(dentition),
                       views=[(v, VIEW_CAPTIONS.get(v, v)) for v in VIEW_NAMES],
                       config_json=Markup(_inline_json(config)), shaders_json=Markup(shaders),
                       scene_base64=Markup(base64.b64encode(glb).decode("ascii")), script=Markup(script))


def write_viewer(out_dir: str | Path, dentition, keyframes: Sequence[SceneKeyframe], title: str,
                 timeline: str = "day", shapes=None, labels: Sequence[str] | None = None,
                 changed=None) -> dict[str, Path]:
    """Write out_dir/animation.glb and out_dir/viewer.html (atomically); returns {"glb": path, "viewer": path}.
    shapes: FDI -> (mesh, face_part) shown instead of the tooth models; changed: FDI -> (keyframe,
    (mesh, face_part)), a tooth's shape from that keyframe on (`treatment_glb`)."""
    out_dir = Path(out_dir)
    glb = treatment_glb(dentition, keyframes, title=title, timeline=timeline, shapes=shapes, labels=labels,
                        changed=changed)
    write_bytes(out_dir / GLB_NAME, glb)
    write_text(out_dir / PAGE_NAME, viewer_html(glb, dentition, title, timeline))
    return {"glb": out_dir / GLB_NAME, "viewer": out_dir / PAGE_NAME}


class SceneRecorder:
    """Keeps a keyframe of every step record that streams past (poses, moving teeth, one contact
    centre per touching pair: a few kB a step), for the scene written once the run is drawn."""

    def __init__(self, dentition, extracted: Iterable[int] = ()):
        self.dentition = dentition
        self.extracted = frozenset(extracted)
        self.locator = ContactLocator(dentition)
        self.keyframes: list[SceneKeyframe] = []

    def watch(self, records: Iterable) -> Iterator:
        for record in records:
            self.keyframes.append(keyframe_of_record(record, self.extracted, self.locator))
            yield record

    def write(self, out_dir: str | Path, title: str) -> dict[str, Path]:
        return write_viewer(out_dir, self.dentition, self.keyframes, title)


# ------------------------------------------------------------------------------------------ a staging
def stage_shapes(run, stage: int = 0) -> dict[int, tuple]:
    """Each staged tooth's mesh at `stage` as the stage models give it (`orthosim.staging.models`:
    `stage_tooth_meshes`, the planned interproximal reduction cut from stage 1 on, and `printable`),
    with its faces' crown/root parts (local frame, mm)."""
    return _printed(run, stage, run.plan.teeth)


def _printed(run, stage: int, teeth) -> dict[int, tuple]:
    """stage_shapes of `teeth` only."""
    from orthosim.model.tooth import part_of_faces
    from orthosim.staging.models import printable, stage_tooth_meshes
    from orthosim.staging.reduction import reduced_meshes

    plan = run.plan
    reduced = reduced_meshes({n: run.dentition.teeth[n].mesh for n in teeth}, plan.ipr, plan.target) \
        if stage >= 1 and plan.ipr else None
    shapes = {}
    for n, mesh in stage_tooth_meshes(run.dentition, teeth, stage, reduced).items():
        mesh = printable(mesh)
        shapes[n] = (mesh, part_of_faces(mesh))
    return shapes


def staging_keyframes(run) -> list[SceneKeyframe]:
    """One keyframe per stage (0 = the start): the stage's poses, the teeth moving in it, and a marker
    per pair where interproximal reduction removes enamel (`staging.caseplan.ipr_contact_points`).
    Teeth the plan does not stage are hidden, as in the staging's frames."""
    from orthosim.staging.caseplan import ipr_contact_points

    plan, dent = run.plan, run.dentition
    hidden = frozenset(n for n in dent.fdis if n not in plan.teeth)
    rest = dent.rest_poses()
    locator = ContactLocator(dent)
    out = []
    for k in range(plan.n_stages + 1):
        poses = {**rest, **plan.poses(k)}
        moving = frozenset() if k == 0 else frozenset(
            n for i, n in enumerate(plan.teeth) if plan.progress[k][i] > plan.progress[k - 1][i])
        points, pairs = ipr_contact_points(run, k) if plan.ipr else (None, ())
        contacts = locator.markers(poses, pairs, points) if pairs else ()
        out.append(SceneKeyframe(k, float(k), poses, hidden, moving, contacts))
    return out


def write_staging_viewer(run, out_dir: str | Path) -> dict[str, Path]:
    """animation.glb (the stages as keyframes, the stage models' meshes) and viewer.html of a staging."""
    from orthosim.staging.reduction import tooth_cuts

    plan = run.plan
    cut = sorted(tooth_cuts(plan.ipr, plan.target)) if plan.ipr and plan.n_stages >= 1 else []
    changed = {n: (1, shape) for n, shape in _printed(run, 1, cut).items()}  # from stage 1 on, as the stage models
    return write_viewer(out_dir, run.dentition, staging_keyframes(run), run.case.name,
                        timeline="stage", shapes=stage_shapes(run, 0), changed=changed)


# ------------------------------------------------------------------------------------------ a report
def write_pose_viewer(data, out_dir: str | Path) -> dict[str, Path]:
    """The poses of a report's contact figure (`orthosim_render.report.gather.CaseData`: before
    treatment, then each detector's last pose) as keyframes, with their names on the slider."""
    names = list(data.pose_names)
    keyframes = [SceneKeyframe(k, float(k), data.poses[name], frozenset(data.extracted)) for k, name in enumerate(names)]
    labels = ["before" if name == "initial" else f"after, {name} detector" for name in names]
    return write_viewer(out_dir, data.dentition, keyframes, data.name, timeline="pose", labels=labels)
