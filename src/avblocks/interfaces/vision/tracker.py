""":class:`ColorBlobTracker`: the largest blob of a colour in each image.

Method (per image, all images of the agent axis in a few OpenCV calls)::

    hsv  = cvtColor(image, RGB2HSV)                 (H in [0, 180), S, V in [0, 255])
    mask = lower <= hsv <= upper                    (hue interval wraps when
                                                     lower_h > upper_h: red)
    mask = opening(mask, k x k)                     (optional, k = open_px)
    blobs = 8-connected components of mask
    the largest blob (pixel count >= min_area):
        centroid = mean (u, v) of its pixels        (u column, v row)
        area     = its pixel count
        bbox     = (u_min, v_min, width, height)

The N masks are stacked into one (N (H + 1), W) picture with a blank row
between images, so one ``connectedComponentsWithStats`` call labels all of
them and blobs never join across images; the largest blob per image is
picked with array operations (no Python loop over agents).

Reference: OpenCV documentation, ``cv::inRange``,
``cv::connectedComponentsWithStats``; A. R. Smith, "Color gamut transform
pairs", SIGGRAPH 1978 (HSV).
"""

from __future__ import annotations

import numpy as np

from ...core.block import Block
from ...core.errors import AvError, ParameterError, ShapeError

_NAME = "ColorBlobTracker"


class VisionUnavailable(AvError, ImportError):
    """OpenCV (``opencv-python-headless``) is not installed."""


def import_cv2():
    try:
        import cv2
    except ImportError:
        raise VisionUnavailable("OpenCV is not installed",
                                hint="pip install 'avblocks[vision]' "
                                     "(opencv-python-headless)") from None
    return cv2


def _hsv(v, name):
    a = np.asarray(v, float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ParameterError("HSV bound must be (h, s, v)", block=_NAME, param=name,
                             found=v)
    if not (0 <= a[0] <= 180 and 0 <= a[1] <= 255 and 0 <= a[2] <= 255):
        raise ParameterError("HSV bound out of OpenCV's range", block=_NAME, param=name,
                             expected="h in [0, 180], s and v in [0, 255]", found=v)
    return a


def blob_masks(images, lower, upper, open_px=0):
    """Boolean masks (N, H, W) of pixels whose HSV lies in [lower, upper]."""
    cv2 = import_cv2()
    imgs = np.ascontiguousarray(images, dtype=np.uint8)
    n, h, w = imgs.shape[:3]
    hsv = cv2.cvtColor(imgs.reshape(n * h, w, 3), cv2.COLOR_RGB2HSV)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    if lo[0] <= hi[0]:
        m = cv2.inRange(hsv, lo, hi)
    else:   # hue wraps around 180 -> 0 (red)
        m = cv2.inRange(hsv, lo, np.array([180.0, hi[1], hi[2]])) | cv2.inRange(
            hsv, np.array([0.0, lo[1], lo[2]]), hi)
    if open_px > 1:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (int(open_px), int(open_px)))
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, k)
    return m.reshape(n, h, w) > 0


def largest_blobs(masks, min_area=1):
    """Largest 8-connected blob of each mask (N, H, W): ``(centroid (N, 2),
    area (N,), bbox (N, 4), found (N,))``; zeros where none is found."""
    cv2 = import_cv2()
    masks = np.asarray(masks, bool)
    n, h, w = masks.shape
    stack = np.zeros((n, h + 1, w), np.uint8)
    stack[:, :h] = masks
    _nl, _lab, stats, cents = cv2.connectedComponentsWithStats(
        stack.reshape(n * (h + 1), w), connectivity=8, ltype=cv2.CV_32S)
    stats, cents = stats[1:], cents[1:]            # drop the background
    centroid = np.zeros((n, 2))
    area = np.zeros(n)
    bbox = np.zeros((n, 4))
    found = np.zeros(n, bool)
    if len(stats):
        img = stats[:, cv2.CC_STAT_TOP] // (h + 1)
        ar = stats[:, cv2.CC_STAT_AREA]
        order = np.lexsort((ar, img))              # by image, then area
        last = np.r_[img[order][1:] != img[order][:-1], True]
        best = order[last]
        bi = img[best]
        ok = ar[best] >= min_area
        best, bi = best[ok], bi[ok]
        found[bi] = True
        area[bi] = ar[best]
        c = cents[best].copy()
        c[:, 1] -= bi * (h + 1)
        centroid[bi] = c
        s = stats[best]
        bbox[bi] = np.column_stack([s[:, cv2.CC_STAT_LEFT],
                                    s[:, cv2.CC_STAT_TOP] - bi * (h + 1),
                                    s[:, cv2.CC_STAT_WIDTH], s[:, cv2.CC_STAT_HEIGHT]])
    return centroid, area, bbox, found


class ColorBlobTracker(Block):
    """Largest blob of an HSV colour range in each of N images.

    Ports
    -----
    image : in, (N, H, W, 3) uint8, RGB (row 0 at the top)
    centroid : out, (N, 2) [px], (u, v) = (column, row), pixel centres at
        integers; 0 where nothing is found
    area : out, (N,) [px]
    bbox : out, (N, 4) [px], (u_min, v_min, width, height)
    found : out, (N,) bool

    Parameters
    ----------
    lower, upper : (h, s, v)
        OpenCV HSV bounds (h in [0, 180), s and v in [0, 255]);
        ``lower_h > upper_h`` selects the hue interval that wraps through 0
        (red: ``lower=(170, 120, 70), upper=(10, 255, 255)``, see :meth:`red`).
    min_area : int
        Smallest blob counted as found [px] (default 4).
    open_px : int
        Morphological opening kernel [px] against speckle (default 0: off;
        it moves the centroid of small blobs by up to a pixel).

    The sample time is inherited (wire it after a :class:`SceneCamera`:
    it runs once per image).

    Equations
    ---------
    See the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((1, 20, 30, 3), np.uint8); img[0, 5:9, 10:16] = (255, 0, 0)
    >>> tr = ColorBlobTracker.red(1, 20, 30)
    >>> y = tr.output(0, {}, {"image": img}, np)
    >>> y["centroid"].tolist(), y["area"].tolist(), y["found"].tolist()
    ([[12.5, 6.5]], [24.0], [True])
    """

    #: NumPy/MuJoCo/OpenCV code: the compiled (JAX) backend refuses it by name.
    traceable = False

    #: what the editor's palette starts a new block with
    example = {"n": 1, "height": 120, "width": 160}

    def __init__(self, n, height, width, *, lower=(170, 120, 70),
                 upper=(10, 255, 255), min_area=4, open_px=0):
        super().__init__()
        import_cv2()
        self.n, self.height, self.width = int(n), int(height), int(width)
        if min(self.n, self.height, self.width) < 1:
            raise ParameterError("n, height and width must be >= 1", block=_NAME,
                                 param="n, height, width", found=(n, height, width))
        self.lower, self.upper = _hsv(lower, "lower"), _hsv(upper, "upper")
        if np.any(self.lower[1:] > self.upper[1:]):
            raise ParameterError("lower S, V must not exceed upper S, V", block=_NAME,
                                 param="lower", found=(lower, upper))
        self.min_area = int(min_area)
        self.open_px = int(open_px)
        self.declare_inherited()
        self.declare_input("image", (self.n, self.height, self.width, 3), "uint8")
        self.declare_output("centroid", (self.n, 2), unit="px", labels=("u", "v"))
        self.declare_output("area", (self.n,), unit="px")
        self.declare_output("bbox", (self.n, 4), unit="px",
                            labels=("u_min", "v_min", "width", "height"))
        self.declare_output("found", (self.n,), "bool")

    @classmethod
    def red(cls, n, height, width, **kw):
        """A tracker for saturated red (hue wrapping through 0)."""
        return cls(n, height, width, lower=(170, 120, 70), upper=(10, 255, 255), **kw)

    def output(self, t, x, u, xp):
        img = np.asarray(u["image"])
        if img.shape != (self.n, self.height, self.width, 3):
            raise ShapeError("image has the wrong shape", block=_NAME, port="image",
                             expected=(self.n, self.height, self.width, 3), found=img.shape)
        masks = blob_masks(img, self.lower, self.upper, self.open_px)
        c, a, b, f = largest_blobs(masks, self.min_area)
        return {"centroid": c, "area": a, "bbox": b, "found": f}
