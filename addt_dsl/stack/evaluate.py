"""Evaluate the BEV detector on held-out generated scans: `python -m addt_dsl.stack.evaluate`.

    python -m addt_dsl.stack.evaluate [--scenes 1500] [--seed 1000003] [--yaw-shift 0 1 2 5]

Prints, per distance band from the ego (0-20, 20-40, 40-60 m): recall, precision, mean
position error [m] and mean heading error [deg] of matched detections; then per class
(car, truck, pedestrian, cyclist) and band: recall, mean position error and the share
of matched detections given the right class.

- Ground truth counted for recall: boxes with at least `--min-hits` (default 2) lidar
  returns (an object nobody's lidar sees cannot be detected; nuScenes filters likewise).
- Matching: detections in order of confidence, each to the nearest unmatched box within
  2 m (centre distance, nuScenes' middle threshold). A detection matched to a box with
  fewer returns is neither a hit nor a false positive.
- Heading error is the box-axis error, modulo 180°: the detector gives the box axis (a
  lidar box looks the same from either end; the tracker's motion tells the front).
- `--yaw-shift DEG ...` moves the *actual* lidar mount by that yaw while the stack keeps
  the nominal calibration (the `shift` fault): errors grow with shift and distance.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

import numpy as np

from addt_dsl import extras, units
from addt_dsl.stack.bev_grid import CLASSES
from addt_dsl.stack.synth import generate, in_grid, load_samples

BANDS = ((0.0, 20.0), (20.0, 40.0), (40.0, 60.0))
MATCH_M = 2.0


@dataclass
class BandStats:
    gt: int = 0
    found: int = 0
    detections: int = 0
    false_pos: int = 0
    pos_err: float = 0.0
    head_err: float = 0.0
    matched: int = 0
    right_class: int = 0  # matched detections whose class output is the box's class

    @property
    def class_accuracy(self) -> float:
        return self.right_class / self.matched if self.matched else math.nan

    @property
    def recall(self) -> float:
        return self.found / self.gt if self.gt else math.nan

    @property
    def precision(self) -> float:
        counted = self.detections
        return (counted - self.false_pos) / counted if counted else math.nan

    @property
    def mean_pos(self) -> float:
        return self.pos_err / self.matched if self.matched else math.nan

    @property
    def mean_head_deg(self) -> float:
        return math.degrees(self.head_err / self.matched) if self.matched else math.nan


def _band(d: float) -> int | None:
    for k, (lo, hi) in enumerate(BANDS):
        if lo <= d < hi:
            return k
    return None


def evaluate(samples, detector, min_hits: int = 2, by_kind: dict | None = None,
             by_class: dict | None = None) -> list[BandStats]:
    """Band statistics for `detector(points, sensor_xy) -> (N, 7) boxes` over `samples`.

    `by_kind`, if given, collects recall within 40 m per class: {class: [found, gt]};
    `by_class` band statistics per class: {class: [BandStats per band]}.
    """
    stats = [BandStats() for _ in BANDS]
    by_kind = {} if by_kind is None else by_kind
    by_class = {} if by_class is None else by_class
    for s in samples:
        det = detector(s.points, s.sensor_xy)
        keep = in_grid(s.boxes)
        gt, hits, cls = s.boxes[keep], s.hits[keep], s.classes[keep]
        counted = hits >= min_hits
        for k in np.flatnonzero(counted):
            b = _band(math.hypot(gt[k, 0], gt[k, 1]))
            if b is not None:
                stats[b].gt += 1
                by_class.setdefault(CLASSES[cls[k]], [BandStats() for _ in BANDS])[b].gt += 1
                if b < 2:
                    by_kind.setdefault(CLASSES[cls[k]], [0, 0])[1] += 1
        taken = np.zeros(len(gt), dtype=bool)
        for row in det:  # sorted by confidence already
            b = _band(math.hypot(row[0], row[1]))
            if len(gt):
                d = np.hypot(gt[:, 0] - row[0], gt[:, 1] - row[1])
                d[taken] = np.inf
                k = int(np.argmin(d))
                match = k if d[k] < MATCH_M else None
            else:
                match = None
            if match is None:
                if b is not None:
                    stats[b].detections += 1
                    stats[b].false_pos += 1
                continue
            taken[match] = True
            if not counted[match]:
                continue  # a box too thinly seen to be required: neither hit nor false positive
            if b is not None:
                stats[b].detections += 1
            gb = _band(math.hypot(gt[match, 0], gt[match, 1]))
            if gb is None:
                continue
            name = CLASSES[cls[match]]
            if gb < 2:
                by_kind.setdefault(name, [0, 0])[0] += 1
            pos_err = math.hypot(gt[match, 0] - row[0], gt[match, 1] - row[1])
            dh = abs(units.wrap_angle(row[2] - gt[match, 2]))
            for st in (stats[gb], by_class[name][gb]):
                st.found += 1
                st.matched += 1
                st.pos_err += pos_err
                st.head_err += min(dh, math.pi - dh)
                st.right_class += int(len(row) > 6 and row[6] == cls[match])
    return stats


def format_table(stats: list[BandStats], title: str = "") -> str:
    lines = [title] if title else []
    lines.append(f"{'band':>9} {'gt':>6} {'recall':>7} {'precision':>9} {'pos err m':>9} "
                 f"{'head err deg':>12}")
    for (lo, hi), st in zip(BANDS, stats):
        lines.append(f"{f'{lo:.0f}-{hi:.0f} m':>9} {st.gt:>6} {st.recall:>7.3f} {st.precision:>9.3f} "
                     f"{st.mean_pos:>9.3f} {st.mean_head_deg:>12.2f}")
    near = BandStats(*(sum(getattr(s, f) for s in stats[:2]) for f in
                       ("gt", "found", "detections", "false_pos", "pos_err", "head_err", "matched")))
    lines.append(f"{'0-40 m':>9} {near.gt:>6} {near.recall:>7.3f} {near.precision:>9.3f} "
                 f"{near.mean_pos:>9.3f} {near.mean_head_deg:>12.2f}")
    return "\n".join(lines)


def format_class_table(by_class: dict) -> str:
    """Recall, mean position error and class accuracy per class and band."""
    lines = [f"{'class':>10} {'band':>9} {'gt':>6} {'recall':>7} {'pos err m':>9} {'class ok':>8}"]
    for name in CLASSES:
        for (lo, hi), st in zip(BANDS, by_class.get(name, [BandStats() for _ in BANDS])):
            lines.append(f"{name:>10} {f'{lo:.0f}-{hi:.0f} m':>9} {st.gt:>6} {st.recall:>7.3f} "
                         f"{st.mean_pos:>9.3f} {st.class_accuracy:>8.3f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m addt_dsl.stack.evaluate", description=__doc__.split("\n")[0])
    ap.add_argument("--weights", default=None, help="weights file (default: the shipped one)")
    ap.add_argument("--scenes", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=1_000_003, help="held out: training uses small seeds")
    ap.add_argument("--lidar", default=None,
                    help="RAYSxCHANNELS of the runtime's Lidar (default: the one the weights were trained for)")
    ap.add_argument("--lidar-vfov", type=float, default=None, metavar="DEG",
                    help="vertical field of view of a multi-channel lidar (default: the weights' training "
                         "value, else bev_grid.DETECTOR_LIDAR's)")
    ap.add_argument("--lidar-pitch", type=float, default=None, metavar="DEG",
                    help="mount pitch, positive down (default: level; the default sensor: 2)")
    ap.add_argument("--min-hits", type=int, default=2)
    ap.add_argument("--threshold", type=float, default=None)
    ap.add_argument("--yaw-shift", type=float, nargs="*", default=[0.0], metavar="DEG",
                    help="actual-vs-nominal lidar yaw misalignment(s) [deg]")
    ap.add_argument("--cache", default=None, help="evaluate on stored scans (npz from synth.save_samples) instead")
    args = ap.parse_args(argv)
    if (message := extras.missing_message("torch", "evaluating the learned detector")) is not None:
        print(message, file=sys.stderr)
        return 2

    from addt_dsl.stack.learned import WEIGHTS_PATH, LearnedPerception

    settings = {} if args.threshold is None else {"detect_threshold": args.threshold}
    node = LearnedPerception(settings, weights=args.weights or WEIGHTS_PATH)
    lidar = args.lidar or node.meta.get("lidars", ["360x1"])[0]
    vfov_deg = args.lidar_vfov if args.lidar_vfov is not None else node.meta.get("lidar_vfov_deg")
    lidar_settings = {} if vfov_deg is None else {"vfov": math.radians(vfov_deg)}
    if args.lidar_pitch is not None:
        lidar_settings["pitch"] = math.radians(args.lidar_pitch)
    lidar_settings = lidar_settings or None
    for shift in args.yaw_shift:
        if args.cache:
            samples = load_samples(args.cache)[: args.scenes]
        else:
            samples = generate(args.scenes, args.seed, lidars=(lidar,),
                               yaw_shift_rad=math.radians(shift), lidar_settings=lidar_settings)
        kinds: dict = {}
        classes: dict = {}
        stats = evaluate(samples, node.detect, args.min_hits, kinds, classes)
        seen = ",".join(sorted({s.lidar for s in samples}))
        print(format_table(stats, f"yaw shift {shift:g} deg, {len(samples)} scans, lidar {seen}, "
                                  f"threshold {node.threshold:g}, ground truth with >= {args.min_hits} returns"))
        print("recall within 40 m by kind: " + ", ".join(
            f"{kind} {found / gt:.3f} ({gt})" for kind, (found, gt) in sorted(kinds.items()) if gt))
        print(format_class_table(classes))
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
