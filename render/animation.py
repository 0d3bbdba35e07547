"""Turning a sequence of frame states into files: PNG frames, an MP4 and optionally a GIF.

`render_run` is the CLI's entry point: it builds the scene once, renders every state from each
chosen view (several views are tiled into one frame, left to right, three per row), and hands the
images to a `FrameSink`, which encodes on background threads while the next frame renders:
  - PNG: one file per frame, `frames/NNNNN.png`, encoded by `orthosim_render.png` (3x faster than
    Pillow's writer), each written to a temporary file then renamed (`orthosim.storage.atomic`);
  - MP4: H.264 through the ffmpeg binary that the `imageio-ffmpeg` wheel ships, fed through a
    pipe (the encoder runs in its own process), written to a temporary file renamed at the end;
  - GIF (optional): the frame's own size, palette per frame; for long runs every k-th frame only,
    k doubling whenever more than GIF_MAX_FRAMES are kept, so memory stays bounded;
  - split views (optional): besides the tiled frame, each view's image as
    `frames/<view>/NNNNN.png`.
The queues between the renderer and the encoders are bounded: a slow disk slows the run down
instead of filling memory. `RenderOptions(single_core=True)` (a batch worker, one per core) does all
of it on the calling thread instead: no frame-taking or encoder threads, ffmpeg on one thread.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np

from orthosim.storage.atomic import atomic_path
from orthosim.runtime.background import release_freed_heap
from orthosim.runtime.options import RenderOptions

from orthosim_render.cameras import check_view
from orthosim_render.frame_state import FrameState
from orthosim_render.png import encode_png

VIDEO_FPS = 30
GIF_MAX_FRAMES = 240
_END = object()
# ffmpeg's encoder (libx264, and its lookahead) and its filters (the RGB -> YUV conversion) on one thread each
_ONE_THREAD_FFMPEG = ["-threads", "1", "-filter_threads", "1"]
_umask = os.umask(0)
os.umask(_umask)
_FILE_MODE = 0o666 & ~_umask


def tile(images: Sequence[np.ndarray], columns: int = 3) -> np.ndarray:
    """Views side by side, `columns` per row; empty cells take the first image's corner colour."""
    if len(images) == 1:
        return images[0]
    h, w, c = images[0].shape
    cols = min(columns, len(images))
    rows = -(-len(images) // cols)
    out = np.empty((rows * h, cols * w, c), np.uint8)
    out[:] = images[0][0, 0]
    for i, im in enumerate(images):
        r, k = divmod(i, cols)
        out[r * h:(r + 1) * h, k * w:(k + 1) * w] = im
    return out


class _Worker(threading.Thread):
    """Runs `handle(item)` for each queued item; re-raises its first error in the caller on `finish`."""

    def __init__(self, name: str, handle, maxsize: int = 8):
        super().__init__(name=name, daemon=True)
        self.q: queue.Queue = queue.Queue(maxsize=maxsize)
        self.handle = handle
        self.error: BaseException | None = None
        self.start()

    def run(self):
        while True:
            item = self.q.get()
            if item is _END:
                return
            if self.error is None:
                try:
                    self.handle(item)
                except BaseException as exc:  # kept and re-raised in the rendering thread
                    self.error = exc

    def put(self, item):
        if self.error is not None:
            raise self.error
        self.q.put(item)

    def finish(self):
        self.q.put(_END)
        self.join()
        if self.error is not None:
            raise self.error


class _Inline:
    """A `_Worker` that runs `handle(item)` on the caller's thread, at once."""

    def __init__(self, handle):
        self.handle = handle

    def put(self, item):
        self.handle(item)

    def finish(self):
        pass


class FrameSink:
    """Writes frames as PNG files and/or an MP4 (and a GIF), encoding on background threads.

    inline: encode on the caller's thread instead (no encoder threads) and have ffmpeg encode on
    one thread: a run that must keep to one core (a batch worker, one per core)."""

    def __init__(self, out_dir: str | Path, *, png: bool = True, mp4: bool = True, gif: bool = False,
                 video_fps: int = VIDEO_FPS, png_threads: int = 2, split_views: Sequence[str] = (),
                 inline: bool = False):
        self.out_dir = Path(out_dir)
        self.frames_dir = self.out_dir / "frames"
        self.png, self.mp4, self.gif = png, mp4, gif
        self.video_fps = video_fps
        self.inline = inline
        self.count = 0
        self._stack = contextlib.ExitStack()
        if not (png or split_views):
            self._png_workers = []
        elif inline:
            self._png_workers = [_Inline(self._write_png)]
        else:
            self._png_workers = [_Worker(f"png-{i}", self._write_png) for i in range(png_threads)]
        self._video_worker = None
        self._video_size = None
        self._gif_frames: list = []
        self._gif_stride = 1
        self.split_views = tuple(split_views)
        if png:
            self.frames_dir.mkdir(parents=True, exist_ok=True)
        for view in self.split_views:
            (self.frames_dir / view).mkdir(parents=True, exist_ok=True)
        if not png:
            self.out_dir.mkdir(parents=True, exist_ok=True)

    # ------------------------------------------------------------------------------ writers
    def _write_png(self, item):
        index, image, folder = item
        data = encode_png(image)
        with atomic_path(folder / f"{index:05d}.png") as tmp:
            tmp.write_bytes(data)
            os.chmod(tmp, _FILE_MODE)  # mkstemp makes the file private; frames are ordinary outputs

    def _start_video(self, image: np.ndarray):
        import imageio_ffmpeg

        h, w = image.shape[:2]
        self._video_size = (w, h)
        tmp = self._stack.enter_context(atomic_path(self.out_dir / "animation.mp4"))
        os.chmod(tmp, _FILE_MODE)
        # Even dimensions for yuv420p; pad by repeating the edge instead of rescaling.
        self._pad = (h % 2, w % 2)
        writer = imageio_ffmpeg.write_frames(
            str(tmp), (w + self._pad[1], h + self._pad[0]), pix_fmt_in="rgb24", fps=self.video_fps,
            # quiet: ffmpeg's own lines would break the one-line error a failed write ends in (a full
            # disk shows as the writer's OSError, which orthosim.runtime.outputfolder turns into that line)
            codec="libx264", macro_block_size=1, ffmpeg_log_level="quiet",
            output_params=["-preset", "ultrafast", "-crf", "20"] + (_ONE_THREAD_FFMPEG if self.inline else []),
        )
        writer.send(None)  # start ffmpeg
        self._video_writer = writer

        def handle(frame):
            writer.send(frame)

        self._video_worker = _Inline(handle) if self.inline else _Worker("mp4", handle)

    def _keep_for_gif(self, image: np.ndarray):
        if self.count % self._gif_stride:
            return
        self._gif_frames.append(np.ascontiguousarray(image[:, :, :3]))
        if len(self._gif_frames) > GIF_MAX_FRAMES:
            self._gif_frames = self._gif_frames[::2]
            self._gif_stride *= 2

    # --------------------------------------------------------------------------------- API
    def add(self, image: np.ndarray, views: Sequence[np.ndarray] = ()) -> None:
        """Queue one frame, (h, w, 3) RGB or (h, w, 4) RGBA uint8; PNGs keep the alpha, video drops it.
        views: each split view's own image, in the order of `split_views`."""
        if self.png:
            self._png_workers[self.count % len(self._png_workers)].put((self.count, image, self.frames_dir))
        for i, (view, im) in enumerate(zip(self.split_views, views)):
            self._png_workers[(self.count + i + 1) % len(self._png_workers)].put((self.count, im, self.frames_dir / view))
        if self.mp4:
            if self._video_worker is None:
                self._start_video(image)
            rgb = image[:, :, :3]
            if self._pad != (0, 0):
                rgb = np.pad(rgb, ((0, self._pad[0]), (0, self._pad[1]), (0, 0)), mode="edge")
            self._video_worker.put(np.ascontiguousarray(rgb))
        if self.gif:
            self._keep_for_gif(image)
        self.count += 1

    def close(self) -> dict:
        """Flush every encoder, move the files into place; returns what was written."""
        written = {"frames": self.count}
        try:
            for w in self._png_workers:
                w.finish()
            if self._video_worker is not None:
                self._video_worker.finish()
                self._video_writer.close()
                written["mp4"] = str(self.out_dir / "animation.mp4")
            if self.png:
                written["frames_dir"] = str(self.frames_dir)
            if self.gif and self._gif_frames:
                from PIL import Image

                ims = [Image.fromarray(f) for f in self._gif_frames]
                duration = int(round(1000 * self._gif_stride / self.video_fps))
                with atomic_path(self.out_dir / "animation.gif") as tmp:
                    os.chmod(tmp, _FILE_MODE)
                    ims[0].save(tmp, format="GIF", save_all=True, append_images=ims[1:], duration=duration, loop=0)
                written["gif"] = str(self.out_dir / "animation.gif")
        except BaseException:
            self._stack.__exit__(*sys.exc_info())  # drop the temporary MP4
            raise
        self._stack.close()  # rename the MP4 into place
        return written


    def abort(self) -> None:
        """Stop after a failure: stop the encoders and leave no temporary or partial video behind."""
        for w in self._png_workers + ([self._video_worker] if self._video_worker else []):
            with contextlib.suppress(BaseException):
                w.finish()
        if self._video_worker is not None:
            with contextlib.suppress(BaseException):
                self._video_writer.close()
        self._stack.__exit__(RuntimeError, RuntimeError("aborted"), None)


def prefetch(items: Iterable, depth: int = 2) -> Iterator:
    """Yield the items of `items`, produced on a background thread up to `depth` ahead.

    Why: a frame's simulation step and the previous frame's drawing and encoding do not depend on
    each other, and much of both runs outside the GIL (numpy, llvmpipe's raster threads, zlib,
    the ffmpeg process); producing the next state while this one is drawn makes the run as slow as
    the slower stage instead of the sum of both. Errors raised by the producer surface here.
    """
    q: queue.Queue = queue.Queue(maxsize=max(1, depth))
    stop = threading.Event()
    failure: list[BaseException] = []

    def put(item) -> bool:
        """Queue `item`, waiting while the queue is full; False if the consumer stopped first."""
        while not stop.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce():
        try:
            for item in items:
                if not put(item):
                    return
        except BaseException as exc:  # handed to the consumer
            failure.append(exc)
        put(_END)

    worker = threading.Thread(target=produce, name="prefetch", daemon=True)
    worker.start()
    try:
        while True:
            item = q.get()
            if item is _END:
                if failure:
                    raise failure[0]
                return
            yield item
    finally:
        stop.set()
        worker.join(timeout=5)


@contextlib.contextmanager
def _interrupt_between_frames():
    """Ctrl-C (SIGINT) raises KeyboardInterrupt where the caller checks, between frames.

    Why: raised wherever it lands, it may land inside an OpenGL call, whose ctypes argument
    conversion turns it into a `ctypes.ArgumentError` (a traceback instead of the CLI's one line),
    or inside an object's finalizer, where Python drops it and the run goes on. Yields the check;
    leaving the block checks once more. Main thread only (elsewhere the check does nothing).
    """
    caught: list[int] = []

    def check():
        if caught:
            caught.clear()
            raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield lambda: None  # not ours to change (another thread, or the caller handles Ctrl-C itself)
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield check
    finally:
        signal.signal(signal.SIGINT, previous)
    check()


class _Progress:
    """tqdm bar shown only on a terminal and only once the run has lasted a second."""

    def __init__(self, enabled: bool, total: int | None):
        self.bar = None
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="frame", delay=1.0, dynamic_ncols=True, leave=False)

    def update(self, n_done: int, fps: float):
        if self.bar is not None:
            self.bar.set_postfix_str(f"{fps:.1f} frames/s", refresh=False)
            self.bar.update(1)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _draw_frames(states, renderer, scene, views, overlay, sink, split_views: bool, on_frame, bar, interrupted) -> tuple[int, float]:
    """Draw each state (once per distinct state: a state given twice in a row repeats its image),
    overlay it, hand the frame to the sink; returns (frames handed over, seconds spent drawing)."""
    started = time.perf_counter()
    previous = images = frame = None
    render_s, n = 0.0, 0
    for state in states:
        if state is not previous:
            t0 = time.perf_counter()
            scene.update(state)
            images = [renderer.render(scene, v) for v in views]
            render_s += time.perf_counter() - t0
            if overlay is not None:  # labels drawn in place, once per distinct state
                for v, image in zip(views, images):
                    overlay.label(image, scene.view(v), state)
                frame = overlay.caption_frame(tile(images), state)
            else:
                frame = tile(images)
            previous = state
        sink.add(frame, images if split_views else ())
        if on_frame is not None:
            on_frame(state, scene)
        n += 1
        bar.update(n, n / max(time.perf_counter() - started, 1e-9))
        interrupted()
    return n, render_s


def render_run(dentition, frames: Iterable[FrameState], out_dir: str | Path, options: RenderOptions = RenderOptions(),
               *, total: int | None = None, progress: bool = True, caption=None,
               on_frame: Callable | None = None) -> dict:
    """Render every state in `frames` into out_dir (frames/NNNNN.png, animation.mp4, animation.gif),
    as `options` (`orthosim.runtime.options.RenderOptions`) asks: views, size (w, h pixels), which
    files, roots, contact faces, fps, split views, single core. Its `frames_per_step`, `seconds`,
    `labels` and `overlay` are the caller's: they choose `frames` and `caption`.

    `frames` is taken ahead on a thread (`prefetch`, unless options.single_core); `orthosim run` feeds
    it the records of a simulation running in a child process (`orthosim.runtime.background`), so
    that simulating the next steps and drawing this one use both cores instead of taking turns for
    one GIL.

    total: the number of frames, when known (for the progress bar). A state given twice in a row
    (the same object: a step in which nothing moved) is drawn once and its image repeated.
    `caption` (a `orthosim_render.overlay.FrameCaption`) draws the shared overlay onto every frame: case,
    detector, day N of M, the colour legend and, if it asks for them, FDI labels.
    on_frame(state, scene): called once each frame is handed to the encoders (`orthosim bench`
    times this very loop frame by frame through it).
    options.single_core keeps the run on the calling thread: `frames` taken as they come (no
    prefetch thread), frames encoded inline (no encoder threads), ffmpeg on one thread.

    Memory: once the scene is built, the dentition's meshes forget their trimesh caches
    (`Dentition.drop_mesh_caches`: derived values, computed again if asked for).

    Returns {"frames": n, "fps": end-to-end frames per second (render, read back, encode, write),
    "render_fps": ..., "views": [...], "size": [w, h], "encode_s": time to flush the encoders, ...}.
    The caller records it in run.json (it varies with the machine).
    """
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    views = [check_view(v) for v in (options.views or ("frontal",))]
    size, single_core, split_views = tuple(options.size), options.single_core, options.split_views
    out_dir = Path(out_dir)
    if total is None:
        total = len(frames) if hasattr(frames, "__len__") else None
    scene = DentitionScene(dentition, size, hide_roots=options.hide_roots, contact_faces=options.contact_faces,
                           contact_faces_exact=options.contact_faces_exact)
    sink = FrameSink(out_dir, png=options.png, mp4=options.mp4, gif=options.gif, video_fps=options.fps,
                     split_views=views if split_views else (), inline=single_core)
    bar = _Progress(progress, total)
    overlay = None
    if caption is not None:
        from orthosim_render.overlay import FrameOverlay

        overlay = FrameOverlay(caption, dentition, size)
    dentition.drop_mesh_caches()  # the scene and overlay keep their own arrays; the meshes' derived ones go
    release_freed_heap()
    try:
        with Renderer(size, alpha=options.alpha) as renderer, _interrupt_between_frames() as interrupted:
            started = time.perf_counter()
            n, render_s = _draw_frames(frames if single_core else prefetch(frames), renderer, scene, views, overlay, sink,
                                       split_views, on_frame, bar, interrupted)
            interrupted()
            t_close = time.perf_counter()
            written = sink.close()
            elapsed = time.perf_counter() - started
            encode_s = time.perf_counter() - t_close
            gl_renderer, gl_backend = renderer.gl_renderer, renderer.backend.label
    except BaseException:
        sink.abort()
        raise
    finally:
        bar.close()
    return {
        "frames": n,
        "fps": n / elapsed if elapsed > 0 else None,
        "render_fps": n / render_s if render_s > 0 else None,
        "views": list(views),
        "size": list(size),
        "gl_renderer": gl_renderer,
        "gl_backend": gl_backend,  # orthosim_render.offscreen_backend: egl/gpu, egl/software, egl/default or osmesa
        "video_fps": options.fps,
        "encode_s": encode_s,
        "overlay": None if caption is None else {"labels": caption.labels},
        # relative to out_dir: a run folder may be written in a staging place and moved (orthosim.runtime.outputfolder)
        "outputs": {k: os.path.relpath(v, out_dir) for k, v in written.items() if k != "frames"},
    }
