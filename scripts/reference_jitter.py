#!/usr/bin/env python3
"""How much of `eval real`'s drift a reference's own per-pose jitter explains.

usage: scripts/reference_jitter.py DIR NAME [NAME ...]
  DIR holds `levelscan eval real LOG --out DIR`'s TUM files NAME.reference.tum, NAME.matched.tum.

The step differences d_k = (reference step k)^-1 (matched step k), in the step's frame, are
differenced jitter e_{k+1} - e_k plus the matcher's own error; white jitter of variance s^2 gives
them a lag-1 autocovariance of -s^2, which the matcher's independent errors do not change. Steps
over four MADs are left out. A perfect matcher scored against the reference perturbed by that
jitter (five Monte Carlo draws on the log's own path) gives the drift at 10 m the jitter alone
causes. Standard library only.
"""
import math
import random
import sys


def load(path):
    poses = []
    for line in open(path):
        v = [float(x) for x in line.split()]
        poses.append((v[1], v[2], 2.0 * math.atan2(v[6], v[7])))
    return poses


def wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def between(a, b):
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2]))


def compose(a, d):
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * d[0] - s * d[1], a[1] + s * d[0] + c * d[1], wrap(a[2] + d[2]))


def drift(estimate, reference, length):
    """Mean translational error over `length` m of reference path [%] (as eval real's)."""
    dist = [0.0]
    for k in range(1, len(reference)):
        dist.append(dist[-1] + math.hypot(reference[k][0] - reference[k - 1][0],
                                          reference[k][1] - reference[k - 1][1]))
    total, n, end = 0.0, 0, 0
    for start in range(len(reference)):
        end = max(end, start)
        while end < len(reference) and dist[end] - dist[start] < length:
            end += 1
        if end == len(reference):
            break
        err = between(between(reference[start], reference[end]),
                      between(estimate[start], estimate[end]))
        total += math.hypot(err[0], err[1]) / length
        n += 1
    return 100.0 * total / n


def jitter_sigmas(reference, matched):
    steps = [between(between(reference[k], reference[k + 1]), between(matched[k], matched[k + 1]))
             for k in range(len(reference) - 1)]
    sigmas = []
    for axis in range(3):
        x = [d[axis] for d in steps]
        mad = sorted(abs(a) for a in x)[len(x) // 2] * 1.4826
        pairs = [(a, b) for a, b in zip(x, x[1:]) if abs(a) < 4 * mad and abs(b) < 4 * mad]
        lag1 = sum(a * b for a, b in pairs) / len(pairs)
        sigmas.append(math.sqrt(max(-lag1, 0.0)))
    return sigmas


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    directory = sys.argv[1]
    for name in sys.argv[2:]:
        reference = load(f"{directory}/{name}.reference.tum")
        matched = load(f"{directory}/{name}.matched.tum")
        sx, sy, st = jitter_sigmas(reference, matched)
        floors = []
        for seed in range(5):
            rnd = random.Random(seed)
            jittered = [compose(p, (rnd.gauss(0, sx), rnd.gauss(0, sy), rnd.gauss(0, st)))
                        for p in reference]
            floors.append(drift(reference, jittered, 10.0))
        print(f"{name}: jitter per pose {100 * sx:.2f} / {100 * sy:.2f} cm, "
              f"{math.degrees(st):.3f} deg; drift at 10 m from it alone "
              f"{sum(floors) / len(floors):.2f}%, matched {drift(matched, reference, 10.0):.2f}%")


if __name__ == "__main__":
    main()
