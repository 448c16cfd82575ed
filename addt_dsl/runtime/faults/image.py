"""Camera image corruptions (opencv): blur, pixel noise, occlusion.

Contract with the camera sensors: a `camera` frame carries its image as a numpy array
`frame.data["image"]` of shape H×W×3 (uint8 in [0, 255], or float in [0, 1]); a
`camera_rig` frame carries its cameras' images as `frame.data["images"]`, K×H×W×3, and
the corruption acts on each image the `lens` setting picks (every camera by default, or
camera k: dirt on one lens). A corruption returns a new array of the same shape and
dtype; it never edits the sensor's buffer in place. Frames without an image pass
through unchanged.
opencv is imported when the first image is corrupted, not when the compiler loads
the registry.
"""

from __future__ import annotations

import numpy as np

from addt_dsl.registry import FAULTS
from addt_dsl.specs import faults as S
from addt_dsl.runtime.faults.base import FaultKind


def _full_scale(img: np.ndarray) -> float:
    """The value of a full-intensity pixel: 255 for integer images, 1 for float ones."""
    return float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0


def _back_to(img_f: np.ndarray, like: np.ndarray) -> np.ndarray:
    top = _full_scale(like)
    out = np.clip(img_f, 0.0, top)
    if np.issubdtype(like.dtype, np.integer):
        out = np.rint(out)
    return out.astype(like.dtype, copy=False)


class ImageFault(S.ImageFaultSpec, FaultKind):
    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        data = frame.data if isinstance(frame.data, dict) else {}
        if data.get("image") is not None:
            out, value, detail = self.corrupt(np.asarray(data["image"]))
            frame.data = {**data, "image": out}
            self.record(time_s, frame.sensor, value, **detail)
        elif data.get("images") is not None:
            images = np.asarray(data["images"])
            lens = int(self.settings["lens"])
            out = images.copy()
            for k in range(len(images)) if lens < 0 else (lens,):
                out[k], value, detail = self.corrupt(images[k], lens=k)
                self.record(time_s, f"{frame.sensor}.{k}", value, **detail)
            frame.data = {**data, "images": out}
        return frame, 0.0

    def corrupt(self, img: np.ndarray, lens: int = 0) -> tuple[np.ndarray, object, dict]:
        """Return (corrupted image, injected value, details for the trace) for the image of
        camera `lens` (0 for a plain camera)."""
        raise NotImplementedError


@FAULTS.implements
class Blur(S.Blur, ImageFault):

    def corrupt(self, img, lens=0):
        import cv2

        out = img.astype(np.float32)
        sigma, motion = float(self.settings["sigma"]), float(self.settings["motion"])
        if sigma > 0:
            out = cv2.GaussianBlur(out, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)
        if motion >= 1.0:
            n = int(round(motion)) | 1  # odd kernel so the blur is centred
            kernel = np.zeros((n, n), np.float32)
            kernel[n // 2, :] = 1.0
            rot = cv2.getRotationMatrix2D(((n - 1) / 2.0, (n - 1) / 2.0), float(self.settings["angle"]), 1.0)
            kernel = cv2.warpAffine(kernel, rot, (n, n))
            kernel /= max(float(kernel.sum()), 1e-9)
            out = cv2.filter2D(out, -1, kernel, borderType=cv2.BORDER_REFLECT)
        return _back_to(out, img), sigma, {"motion_px": motion}


@FAULTS.implements
class ImageNoise(S.ImageNoise, ImageFault):

    # Drawing fresh normals for every pixel of every frame costs more than rendering the
    # frame; instead a noise field a little larger than the image is drawn once, and each
    # frame uses it at a random offset and sign (2 x 64 x 64 distinct patterns).
    MARGIN = 64

    def __init__(self, *a):
        super().__init__(*a)
        self._field = None

    def _noise(self, shape) -> np.ndarray:
        h, w = shape[:2]
        m = self.MARGIN
        if self._field is None or self._field.shape[:2] != (h + m, w + m) or self._field.shape[2:] != shape[2:]:
            self._field = self.rng.standard_normal((h + m, w + m, *shape[2:]), dtype=np.float32)
        dy, dx = (int(v) for v in self.rng.integers(0, m, 2))
        sign = 1.0 if self.rng.random() < 0.5 else -1.0
        return self._field[dy:dy + h, dx:dx + w], sign

    def corrupt(self, img, lens=0):
        top = _full_scale(img)
        sigma = float(self.settings["sigma"]) * top / 255.0
        out = img.astype(np.float32)
        if sigma > 0:
            noise, sign = self._noise(img.shape)
            out += noise * np.float32(sign * sigma)
        salted = 0
        frac = float(self.settings["salt"])
        if frac > 0:
            h, w = img.shape[:2]
            mask = self.rng.random((h, w), dtype=np.float32) < frac
            salted = int(mask.sum())
            white = self.rng.random(salted) < 0.5
            out[mask] = np.where(white, top, 0.0)[:, None]
        return _back_to(out, img), float(self.settings["sigma"]), {"pixels": salted}


@FAULTS.implements
class Occlude(S.Occlude, ImageFault):

    def __init__(self, *a):
        super().__init__(*a)
        self._boxes: dict[tuple[int, int, int], list[tuple[int, int, int, int]]] = {}  # (lens, h, w) -> boxes

    def _place(self, h: int, w: int) -> list[tuple[int, int, int, int]]:
        n = int(self.settings["patches"])
        area = float(self.settings["fraction"]) * h * w / n
        boxes = []
        for _ in range(n):
            aspect = float(self.rng.uniform(0.5, 2.0))
            bw = int(round(min(w, max(1.0, np.sqrt(area * aspect)))))
            bh = int(round(min(h, max(1.0, area / max(bw, 1)))))
            if bh == h:  # cut at the image's height: the width takes the rest of the area
                bw = int(round(min(w, max(1.0, area / h))))
            x0 = int(self.rng.integers(0, w - bw + 1))
            y0 = int(self.rng.integers(0, h - bh + 1))
            boxes.append((x0, y0, x0 + bw, y0 + bh))
        return boxes

    def corrupt(self, img, lens=0):
        h, w = img.shape[:2]
        boxes = self._boxes.get((lens, h, w))
        if boxes is None:
            boxes = self._boxes[(lens, h, w)] = self._place(h, w)
        out = img.copy()
        fill = float(self.settings["value"]) * _full_scale(img) / 255.0
        covered = np.zeros((h, w), bool)
        if float(self.settings["fraction"]) > 0:
            for x0, y0, x1, y1 in boxes:
                out[y0:y1, x0:x1] = fill
                covered[y0:y1, x0:x1] = True
        return out, float(covered.mean()), {"boxes": boxes}
