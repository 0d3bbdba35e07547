"""Everything that draws or writes images, video and reports for orthosim (installed as `orthosim_render`).

Importing this package changes nothing in the process: the OpenGL backend (EGL or OSMesa) is chosen
when something first draws, in `offscreen_backend`, and only then is PYOPENGL_PLATFORM set.

- Drawing: `offscreen_backend` (which backend, probed through ctypes before PyOpenGL loads),
  `pyrender_setup` (pyrender loaded with the fixes it needs headless), `scene` (the scene built once
  from a dentition, updated per frame), `renderer` and `lean_renderer` (the context and the draw
  loop), `cameras` (the five named views), `cej` (crown and root split at the CEJ for colouring),
  `standin` (simple shapes for what has no mesh), `spheretree_view` (sphere trees drawn),
  `contact_faces` (exact contact faces per frame, each answer computed once while it holds).
- The library's picture of a step: `frame` (`render_frame(model, record)`, a `Frame` array a notebook
  shows as a picture), also `orthosim_render.render_frame` and `orthosim_render.Frame`.
- Frames and video: `frame_state` (what one frame shows), `timeline` (frames from step records),
  `overlay` (case, day counter, legend, FDI labels), `animation` (frames, MP4, GIF, the run's
  drawing), `png` (fast PNG writing), `cputime` (CPU per frame of every thread and child).
- Pictures and pages: `occlusion_figure` (occlusal contacts drawn), `staging` and `staging_page`
  (a staging's animation and page), `evidence_page` (the evidence table's page), `report/` (the
  contact-area report).
- 3D scenes and the interactive page: `gltf` (a glTF 2.0 binary written and read with numpy and
  struct), `treatment_gltf` (a treatment as one animated glTF scene, `animation.glb`), `viewer_page`
  (`viewer.html`: the scene embedded in a WebGL2 page, its code and shaders in `viewer/`),
  `viewer_check` (the page opened in headless Chromium, its id picture against the label pass).
- Image regression: `imgdiff` (a render against its golden), `imageerrors` (its one-line errors),
  `regression` (a case's step drawn for a test), `semantic_labels` (what each pixel shows), `explain`
  (what changed, tooth by tooth), `pytest_plugin` (the `orthosim_image_regression` fixture).
"""

_FROM = {"render_frame": "orthosim_render.frame", "Frame": "orthosim_render.frame"}  # loaded on first use (PEP 562)
__all__ = sorted(_FROM)


def __getattr__(name: str):
    if name not in _FROM:
        raise AttributeError(f"module 'orthosim_render' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(_FROM[name]), name)
