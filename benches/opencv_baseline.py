#!/usr/bin/env python3
"""OpenCV baseline for the speed and accuracy comparison (not run by CI).

The classic pipeline: Otsu threshold, findContours, the largest dark contour,
fitEllipse. Timed single-threaded per frame on the same frames the criterion
benchmarks use, and scored against the frames' truth.jsonl when present.

    python3 -m venv /tmp/cv && /tmp/cv/bin/pip install opencv-python-headless numpy
    /tmp/cv/bin/python benches/opencv_baseline.py FRAMES_DIR [FRAMES_DIR ...]
"""
import json
import math
import pathlib
import statistics
import sys
import time

import cv2

cv2.setNumThreads(1)


def detect(gray):
    _, dark = cv2.threshold(gray, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    contours, _ = cv2.findContours(dark, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    best = None
    for c in contours:
        if len(c) < 20:
            continue
        area = cv2.contourArea(c)
        if best is None or area > best[0]:
            best = (area, c)
    if best is None:
        return None
    (cx, cy), (w, h), angle = cv2.fitEllipse(best[1])
    a, b = max(w, h) / 2, min(w, h) / 2
    theta = math.radians(angle) + (0 if w >= h else math.pi / 2)
    theta = (theta + math.pi / 2) % math.pi - math.pi / 2
    return cx, cy, a, b, theta


def main():
    for folder in map(pathlib.Path, sys.argv[1:]):
        frames = sorted(folder.glob("*.png"))
        truth = {}
        if (folder / "truth.jsonl").exists():
            for line in (folder / "truth.jsonl").read_text().splitlines():
                t = json.loads(line)
                truth[t["frame"]] = t
        images = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in frames]
        times, centre, axes = [], [], []
        for f, img in zip(frames, images):
            best = None
            for _ in range(20):
                t0 = time.perf_counter()
                e = detect(img)
                dt = time.perf_counter() - t0
                best = dt if best is None else min(best, dt)
            times.append(best)
            t = truth.get(f.name, {}).get("ellipse")
            if e and t:
                centre.append(math.hypot(e[0] - t["cx"], e[1] - t["cy"]))
                axes.append(max(abs(e[2] - t["a"]), abs(e[3] - t["b"])))
        for f, dt in zip(frames, times):
            print(f"{folder}/{f.name}: {dt * 1e3:.3f} ms")
        line = f"{folder}: {len(frames)} frames, {statistics.median(times) * 1e3:.3f} ms median per frame"
        if centre:
            centre.sort()
            axes.sort()
            p95 = lambda v: v[min(len(v) - 1, math.ceil(0.95 * len(v)) - 1)]
            line += (f"; centre err median {statistics.median(centre):.2f} px p95 {p95(centre):.2f}"
                     f"; axes err median {statistics.median(axes):.2f} px p95 {p95(axes):.2f}")
        print(line)


if __name__ == "__main__":
    main()
