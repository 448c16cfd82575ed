"""Camera perception (`stack bev perception camera`): a classical colour detector on the RGB image.

What it reads is what a real camera stack reads: the RGB image (after any image fault:
blur, noise and occlusion act on these pixels before detection), the depth image of an
RGB-D camera, the intrinsics and the *nominal* extrinsics. It never reads the renderer's
body-id image (that is ground truth, and blind to image faults).

1. **Colour segmentation.** The twin paints each road-user class in one colour
   (`addt_dsl.vehicles.VEHICLES`: red cars, blue trucks, orange cyclists, pink pedestrians),
   distinct from the road (grey), markings (white), verges (green) and the sky (white).
   A pixel belongs to a class when its hue is within `HUE_TOLERANCE` of the class's hue
   and its saturation at least `SATURATION_FRACTION` of the class's (hue and saturation do
   not change with shading, so lit and shadowed faces both pass). A 3 x 3 median filter
   removes isolated pixels (sensor noise, salt and pepper).
2. **Blobs.** Connected components (opencv, 8-connected) of each class's mask with at
   least `MIN_PIXELS` pixels are objects. Two same-coloured vehicles that touch in the image
   merge into one blob (a known limit of colour segmentation).
3. **Range** from the depth image: the `FACE_PERCENTILE` percentile of the blob's depths
   (the near face; blurred edges that pick up road or sky pixels are far, so they do not
   pull it).
4. **Bearing** from the blob's centroid column and row through the pinhole intrinsics:
   the face point in the camera frame is `(d, -(u - cx) d / fx, -(v - cy) d / fy)`.
5. **Objects** in the vehicle frame through the nominal extrinsics (a `shift camera` fault
   moves the actual mount, not the calibration), moved from the visible face to the box
   centre by half the class's length along the vehicle's x axis (traffic is assumed to be
   aligned with the ego's lane), then in world coordinates. Heading = the ego's heading
   (same prior); no velocity (`nan`): the tracker estimates it from successive frames, as
   for the learned lidar detector.

Fault sites are the lidar perceptions' (`perception.x`, `perception.y`, `perception.count`).
"""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.stack.nodes import GroundTruthPerception, Obj, vehicle_to_world
from addt_dsl.vehicles import VEHICLES

HUE_TOLERANCE = 8  # [opencv hue units, 2 deg each]
SATURATION_FRACTION = 0.6  # of the class colour's saturation
MIN_VALUE = 12  # [8-bit] darker pixels have no reliable hue
MIN_PIXELS = 6  # after the median filter; a car's rear (1.9 x 1.5 m) passes out to ~65 m at 160 px, 60 deg
FACE_PERCENTILE = 20.0
# Box size priors per class [m] (length, width): what the detector assumes, not what the
# scenario declared. The twin's default sizes.
CLASS_SIZE_M = {name: (v.length_m, v.width_m) for name, v in VEHICLES.items()}


def _hsv_of(rgba) -> tuple[int, int]:
    """(hue, saturation) of a colour in opencv's 8-bit HSV (hue 0-179)."""
    import cv2

    px = np.array([[[round(c * 255) for c in rgba[:3]]]], dtype=np.uint8)
    h, s, _ = cv2.cvtColor(px, cv2.COLOR_RGB2HSV)[0, 0]
    return int(h), int(s)


class ColourDetector:
    """Blobs of the class colours in an RGB image, with their range and bearing."""

    def __init__(self, classes: dict[str, tuple] | None = None):
        classes = classes or {name: v.rgba for name, v in VEHICLES.items()}
        self.classes = {name: _hsv_of(rgba) for name, rgba in classes.items()}

    def masks(self, image: np.ndarray) -> dict[str, np.ndarray]:
        """Per class, the uint8 mask (255 = the class colour) of an HxWx3 RGB image."""
        import cv2

        img = image
        if img.dtype != np.uint8:  # float images in [0, 1] (the image-fault contract allows them)
            img = np.clip(np.rint(np.asarray(img, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)
        hsv = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2HSV)
        hue = hsv[..., 0].astype(np.int16)
        sat, val = hsv[..., 1], hsv[..., 2]
        out = {}
        for name, (h, s) in self.classes.items():
            dh = np.abs(hue - h)
            dh = np.minimum(dh, 180 - dh)  # hue is circular
            mask = (dh <= HUE_TOLERANCE) & (sat >= SATURATION_FRACTION * s) & (val >= MIN_VALUE)
            out[name] = cv2.medianBlur(mask.astype(np.uint8) * 255, 3)
        return out

    def detect(self, image: np.ndarray, depth: np.ndarray, intrinsics: np.ndarray) -> list[tuple]:
        """(class, face point in the camera frame [m] as (forward, left, up), pixels) per blob."""
        import cv2

        fx, fy, cx, cy = intrinsics[0, 0], intrinsics[1, 1], intrinsics[0, 2], intrinsics[1, 2]
        found = []
        for name, mask in self.masks(image).items():
            if not mask.any():
                continue
            n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
            for i in range(1, n):
                if stats[i, cv2.CC_STAT_AREA] < MIN_PIXELS:
                    continue
                rows, cols = np.nonzero(labels == i)
                d = float(np.percentile(depth[rows, cols], FACE_PERCENTILE))
                u, v = float(cols.mean()) + 0.5, float(rows.mean()) + 0.5  # pixel centres
                found.append((name, (d, -(u - cx) * d / fx, -(v - cy) * d / fy), int(len(rows))))
        return found


class CameraPerception:
    """The perception node of `stack bev perception camera` (see the module docstring)."""

    name = "perception"
    sites = GroundTruthPerception.sites

    def __init__(self, settings: dict, ctx=None):
        self.detector = ColourDetector()

    @staticmethod
    def accepts(frame) -> bool:
        """Camera frames (with an image and a depth image) are this node's input."""
        return "image" in frame.data and "depth" in frame.data

    def run(self, frame, sensor, ego_pose, corrupt) -> list[Obj]:
        from addt_dsl.runtime.sensors import sensor_to_vehicle

        data = frame.data
        far = getattr(sensor, "far", math.inf)
        heading = ego_pose[2]
        nominal = sensor.nominal
        objs = []
        for name, face, _pixels in self.detector.detect(data["image"], data["depth"], data["intrinsics"]):
            if not face[0] < 0.98 * far:  # the blob is at the far plane: no range
                continue
            length, width = CLASS_SIZE_M.get(name, CLASS_SIZE_M["car"])
            pv = sensor_to_vehicle(np.array([face]), nominal)[0]
            # From the visible face to the box centre, along the vehicle's x axis.
            px = float(pv[0]) + math.copysign(0.5 * length, float(pv[0]) - nominal.x)
            px = corrupt("perception.x", px)
            py = corrupt("perception.y", float(pv[1]))
            objs.append(Obj(*vehicle_to_world(ego_pose, px, py), heading, math.nan, math.nan, length, width))
        count = int(corrupt("perception.count", float(len(objs))))
        return objs[:max(0, count)]
