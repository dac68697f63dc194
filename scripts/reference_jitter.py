#!/usr/bin/env python3
"""How much of the drift `eval real` measures is the reference's own error.

Reads `levelscan match` outputs (JSON Lines with `estimate` and `true_pose` per scan, the
reference being a SLAM-corrected CARMEN log) and splits each step's difference against the
reference into two parts by their autocorrelation: error of the reference poses that is
independent from pose to pose ("white jitter", sigma_r per pose) makes consecutive step
differences anti-correlated (lag-1 covariance -sigma_r^2), while an error that is independent
from step to step (the matcher's, or the reference's own random walk) does not. Then it draws
the white jitter alone onto the reference and measures the drift over 10 m (KITTI-style, as
src/eval/drift.rs does): the drift any matcher, even a perfect one, shows against this reference.

Usage: scripts/reference_jitter.py MATCH.jsonl [MATCH.jsonl ...]
e.g.   levelscan match intel-corrected.log.gz --mode pairwise -o intel.jsonl
"""
import json
import math
import random
import statistics
import sys


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def between(a, b):
    """b in a's frame (x, y, heading)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    c, s = math.cos(a[2]), math.sin(a[2])
    return (c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2]))


def drift_percent(est, ref, length):
    """Mean translational error of segments `length` metres of reference path long [%]."""
    dist = [0.0]
    for p, q in zip(ref, ref[1:]):
        dist.append(dist[-1] + math.hypot(q[0] - p[0], q[1] - p[1]))
    total, n, end = 0.0, 0, 0
    for start in range(len(ref)):
        end = max(end, start)
        while end < len(ref) and dist[end] - dist[start] < length:
            end += 1
        if end == len(ref):
            break
        t, m = between(ref[start], ref[end]), between(est[start], est[end])
        e = between(t, m)
        total += math.hypot(e[0], e[1]) / length
        n += 1
    return 100 * total / n


def split(est, ref):
    """(white jitter per pose, step-independent part) per component x [m], y [m], heading [rad]."""
    d = []
    for k in range(len(est) - 1):
        a, b = between(est[k], est[k + 1]), between(ref[k], ref[k + 1])
        d.append((a[0] - b[0], a[1] - b[1], wrap(a[2] - b[2])))
    out = []
    for j in range(3):
        x = [v[j] for v in d]
        med = statistics.median(x)
        mad = 1.4826 * statistics.median(abs(v - med) for v in x)
        # Gross mismatches (beyond 6 robust sigmas) would dominate both moments: zeroed.
        x = [v - med if abs(v - med) < 6 * mad else 0.0 for v in x]
        var = sum(v * v for v in x) / len(x)
        lag1 = sum(a * b for a, b in zip(x, x[1:])) / len(x)
        white = math.sqrt(max(-lag1, 0.0))
        out.append((white, math.sqrt(max(var - 2 * white * white, 0.0))))
    return out


def main():
    rng = random.Random(1)
    print("| file | drift 10 m | white jitter x, y [mm], heading [deg] | step-independent x, y [mm], heading [deg] | drift 10 m of the white jitter alone |")
    print("|---|---:|---|---|---:|")
    for path in sys.argv[1:]:
        recs = [json.loads(line) for line in open(path)]
        est = [r["estimate"] for r in recs]
        ref = [r["true_pose"] for r in recs]
        (wx, sx), (wy, sy), (wt, st) = split(est, ref)
        floor = statistics.mean(
            drift_percent(
                [(p[0] + rng.gauss(0, wx), p[1] + rng.gauss(0, wy), p[2] + rng.gauss(0, wt)) for p in ref],
                ref,
                10.0,
            )
            for _ in range(20)
        )
        print(
            f"| {path} | {drift_percent(est, ref, 10.0):.2f}% | {wx * 1e3:.1f}, {wy * 1e3:.1f}, {math.degrees(wt):.2f} "
            f"| {sx * 1e3:.1f}, {sy * 1e3:.1f}, {math.degrees(st):.2f} | {floor:.2f}% |"
        )


if __name__ == "__main__":
    main()
