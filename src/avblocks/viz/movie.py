"""Movie files from RGB frames: MP4 (H.264) and GIF.

MP4 frames are piped raw to the ``ffmpeg`` bundled with ``imageio-ffmpeg``
(the ``movie`` extra); GIFs are written with Pillow (a Matplotlib
dependency). :class:`MovieWriter` streams frames one by one;
:func:`write_movie` writes an iterable of frames; :func:`html5_video` wraps
MP4 bytes in an HTML ``<video>`` tag for notebooks.

>>> import numpy as np, tempfile, os
>>> path = os.path.join(tempfile.mkdtemp(), "a.gif")
>>> _ = write_movie([np.zeros((8, 8, 3), np.uint8)] * 3, path, fps=10)
>>> os.path.getsize(path) > 0
True
"""

from __future__ import annotations

import base64
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..core.errors import AvError, ParameterError

VIDEO_SUFFIXES = {".mp4", ".m4v", ".mov", ".mkv", ".avi", ".webm"}


def _ffmpeg():
    try:
        import imageio_ffmpeg
    except ImportError:
        raise AvError("writing MP4 needs imageio-ffmpeg: pip install 'avblocks[movie]' "
                      "(or save a .gif)") from None
    return imageio_ffmpeg


def check_movie_path(path) -> Path:
    """Check a movie file name before anything is simulated: a known suffix
    (``.gif``, ``.mp4``...) and, for video, the ``movie`` extra. Returns the
    path."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf != ".gif" and suf not in VIDEO_SUFFIXES:
        raise ParameterError("unknown movie format", param="movie",
                             expected=sorted(VIDEO_SUFFIXES | {".gif"}),
                             found=suf or f"no suffix in '{path}'")
    if suf in VIDEO_SUFFIXES:
        _ffmpeg()
    return path


def progress_bar(total, progress=None, desc="frames"):
    """A tqdm bar, shown when ``progress`` is True, or when it is None and
    stderr is a terminal."""
    from tqdm.auto import tqdm
    show = progress if progress is not None else sys.stderr.isatty()
    return tqdm(total=total, disable=not show, desc=desc, leave=False)


class MovieWriter:
    """Write RGB frames (H, W, 3) uint8 to ``path`` one at a time.

    The format follows the suffix: ``.gif`` (Pillow) or a video container
    (``.mp4`` etc., H.264 through imageio-ffmpeg). The frame size is fixed by
    the first frame; odd sizes are cropped by one pixel (H.264 with yuv420p
    needs even sizes). Use as a context manager or call :meth:`close`.
    """

    def __init__(self, path, fps=20.0, *, codec="libx264", quality=7, preset="veryfast"):
        self.path = Path(path)
        self.fps = float(fps)
        if not self.fps > 0:
            raise ParameterError("fps must be positive", param="fps", expected="> 0",
                                 found=fps)
        suf = self.path.suffix.lower()
        if suf == ".gif":
            self.kind = "gif"
        elif suf in VIDEO_SUFFIXES:
            self.kind = "video"
            _ffmpeg()
        else:
            raise ParameterError("unknown movie format", param="path",
                                 expected=sorted(VIDEO_SUFFIXES | {".gif"}), found=suf)
        self.codec, self.quality, self.preset = codec, quality, preset
        self.size = None
        self.count = 0
        self._gen = None
        self._gif = []

    def append(self, frame):
        frame = np.asarray(frame)
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] not in (3, 4):
            raise ParameterError("a frame must be an (H, W, 3) uint8 array", param="frame",
                                 expected="(H, W, 3) uint8",
                                 found=f"{frame.shape} {frame.dtype}")
        frame = frame[:, :, :3]
        if self.size is None:
            h, w = frame.shape[:2]
            if self.kind == "video":
                h, w = h - h % 2, w - w % 2
            self.size = (w, h)
            if self.kind == "video":
                self._open_video()
        w, h = self.size
        if frame.shape[0] < h or frame.shape[1] < w:
            raise ParameterError("frame size changed during the movie", param="frame",
                                 expected=(h, w), found=frame.shape[:2])
        frame = frame[:h, :w]
        if self.kind == "video":
            self._gen.send(np.ascontiguousarray(frame))
        else:
            from PIL import Image
            self._gif.append(Image.fromarray(frame).quantize(colors=255, method=2,
                                                             dither=0))
        self.count += 1

    def _open_video(self):
        ff = _ffmpeg()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._gen = ff.write_frames(str(self.path), self.size, fps=self.fps,
                                    codec=self.codec, quality=self.quality,
                                    macro_block_size=1, ffmpeg_log_level="error",
                                    output_params=["-preset", self.preset])
        self._gen.send(None)

    def close(self) -> Path:
        """Finish the file and return its path."""
        if self.kind == "video":
            if self._gen is not None:
                self._gen.close()
                self._gen = None
        elif self._gif:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            ms = max(20, int(round(1000.0 / self.fps / 10.0)) * 10)
            self._gif[0].save(self.path, save_all=True, append_images=self._gif[1:],
                              duration=ms, loop=0, optimize=False, disposal=1)
            self._gif = []
        if self.count == 0:
            raise AvError(f"no frames were written to {self.path}")
        return self.path

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.close()
        elif self._gen is not None:
            self._gen.close()


def write_movie(frames, path, fps=20.0, *, total=None, progress=None, **kw) -> Path:
    """Write an iterable of RGB frames to ``path`` (MP4 or GIF by suffix)."""
    bar = progress_bar(total, progress)
    try:
        with MovieWriter(path, fps, **kw) as w:
            for f in frames:
                w.append(f)
                bar.update(1)
    finally:
        bar.close()
    return Path(path)


def html5_video(frames, fps=20.0, *, total=None, progress=None, embed_limit_mb=40.0) -> str:
    """An HTML ``<video>`` tag with the frames as an embedded H.264 MP4."""
    fd, tmp = tempfile.mkstemp(suffix=".mp4")
    os.close(fd)
    try:
        write_movie(frames, tmp, fps, total=total, progress=progress)
        data = Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)
    if len(data) > embed_limit_mb * 2**20:
        raise AvError(f"the movie is {len(data) / 2**20:.1f} MB, more than "
                      f"embed_limit_mb={embed_limit_mb}: save it to a file, or decimate "
                      "(every=...)")
    b64 = base64.b64encode(data).decode("ascii")
    return ('<video controls autoplay loop muted playsinline style="max-width:100%">'
            f'<source type="video/mp4" src="data:video/mp4;base64,{b64}"></video>')


def read_video(path):
    """Decode a video with imageio-ffmpeg's ffmpeg: ``(frames (F, H, W, 3), fps)``.

    Handy for tests and checks (no ffprobe needed)."""
    ff = _ffmpeg()
    gen = ff.read_frames(str(path))
    meta = gen.__next__()
    w, h = meta["size"]
    frames = [np.frombuffer(b, np.uint8).reshape(h, w, 3) for b in gen]
    return np.stack(frames) if frames else np.zeros((0, h, w, 3), np.uint8), meta["fps"]
