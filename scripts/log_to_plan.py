#!/usr/bin/env python3
"""A floor plan (.wall) from a CARMEN log's own scans, on the log's own path.

usage: scripts/log_to_plan.py LOG[.gz] OUT.wall [--every K] [--eps M] [--gap M] [--max-range M]
                                                [--clear M]

Every K-th scan is placed at its corrected pose; runs of consecutive beams whose points lie
within --gap metres (or 3 beam spacings at their range) of each other become polylines,
simplified by Douglas-Peucker at --eps metres so that a wall seen in one scan is a few straight
segments, not its range noise. A segment that passes within --clear metres of a pose on the path
is dropped: the robot drove there, so what the scan saw there moved (people, doors). The plan's
poses are the log's corrected poses, one per scan (heading in degrees, z 0.3 m, level).
`levelscan simulate OUT.wall --flat --elevations 0` then gives scans along the log's path
through its own geometry with an exact true pose: a control for `eval real`, whose reference
(the corrected poses) is not exact (docs/RESULTS.md).

Reads `FLASER` lines (beams spread as `formats::carmen::flaser_bearings` spreads them, pose the
line's first) and `ROBOTLASER1` lines (bearings from `start_angle` by `angular_res`, pose the
laser's). Standard library only.
"""
import argparse
import gzip
import json
import math
import sys


def flaser_bearings(n):
    step = math.pi / (max(n, 2) - 1) if n % 2 == 1 else math.pi / n
    return [-math.pi / 2 + step * i for i in range(n)]


def read_scans(path):
    """(ranges, bearings, (x, y, heading)) per scan line, or exits naming the line."""
    opener = gzip.open if path.endswith(".gz") else open
    try:
        with opener(path, "rt") as f:
            for number, line in enumerate(f, 1):
                t = line.split()
                if not t or t[0] not in ("FLASER", "ROBOTLASER1"):
                    continue
                try:
                    yield parse(t)
                except (ValueError, IndexError):
                    sys.exit(f"{path}:{number}: a {t[0]} line that does not parse")
    except (OSError, UnicodeDecodeError) as e:
        sys.exit(f"{path}: cannot read it as a CARMEN log ({e})")


def parse(t):
    if t[0] == "FLASER":
        n = int(t[1])
        ranges = [float(r) for r in t[2 : 2 + n]]
        pose = tuple(float(v) for v in t[2 + n : 5 + n])
        bearings = flaser_bearings(n)
    else:
        start, res = float(t[2]), float(t[4])
        n = int(t[8])
        ranges = [float(r) for r in t[9 : 9 + n]]
        m = int(t[9 + n])
        pose = tuple(float(v) for v in t[10 + n + m : 13 + n + m])
        bearings = [start + res * i for i in range(n)]
    if len(ranges) != n or len(pose) != 3:
        raise ValueError
    return ranges, bearings, pose


def simplify(points, eps):
    """Douglas-Peucker: the points of `points` a polyline within `eps` of it keeps."""
    if len(points) < 3:
        return points
    keep = [False] * len(points)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        a, b = stack.pop()
        (ax, ay), (bx, by) = points[a], points[b]
        dx, dy = bx - ax, by - ay
        length = math.hypot(dx, dy) or 1e-12
        worst, at = -1.0, -1
        for i in range(a + 1, b):
            px, py = points[i]
            d = abs(dx * (py - ay) - dy * (px - ax)) / length
            if d > worst:
                worst, at = d, i
        if worst > eps:
            keep[at] = True
            stack.append((a, at))
            stack.append((at, b))
    return [p for p, k in zip(points, keep) if k]


def seg_dist(p, a, b):
    (px, py), (ax, ay), (bx, by) = p, a, b
    dx, dy = bx - ax, by - ay
    t = ((px - ax) * dx + (py - ay) * dy) / ((dx * dx + dy * dy) or 1e-12)
    t = min(1.0, max(0.0, t))
    return math.hypot(ax + t * dx - px, ay + t * dy - py)


def clear_path(walls, poses, radius):
    """Splits the polylines where a segment passes within `radius` of a pose."""
    cell = {}
    for x, y, *_ in poses:
        cell.setdefault((math.floor(x), math.floor(y)), []).append((x, y))

    def blocked(a, b):
        x0, x1 = sorted((a[0], b[0]))
        y0, y1 = sorted((a[1], b[1]))
        for i in range(math.floor(x0 - radius), math.floor(x1 + radius) + 1):
            for j in range(math.floor(y0 - radius), math.floor(y1 + radius) + 1):
                for p in cell.get((i, j), ()):
                    if seg_dist(p, a, b) < radius:
                        return True
        return False

    out = []
    for w in walls:
        run = [w[0]]
        for a, b in zip(w, w[1:]):
            if blocked(a, b):
                if len(run) >= 2:
                    out.append(run)
                run = [b]
            else:
                run.append(b)
        if len(run) >= 2:
            out.append(run)
    return out


def main():
    ap = argparse.ArgumentParser(
        description="A floor plan (.wall) from a CARMEN log's own scans, on the log's own path."
    )
    ap.add_argument("log", help="CARMEN log (FLASER or ROBOTLASER1 lines), gzipped or not")
    ap.add_argument("out", help="the plan to write (.wall)")
    ap.add_argument("--every", type=int, default=5, help="walls from every K-th scan (5)")
    ap.add_argument("--eps", type=float, default=0.015,
                    help="Douglas-Peucker tolerance [m] (0.015: about the range noise)")
    ap.add_argument("--gap", type=float, default=0.15,
                    help="neighbouring points farther apart break a polyline [m] (0.15, or "
                         "3 beam spacings at their range)")
    ap.add_argument("--max-range", type=float, default=30.0,
                    help="readings at or beyond it are no return [m] (30)")
    ap.add_argument("--clear", type=float, default=0.3,
                    help="drop segments within this of a pose on the path [m] (0.3; 0 keeps all)")
    a = ap.parse_args()
    if a.every < 1 or a.eps < 0 or a.gap <= 0 or a.max_range <= 0 or a.clear < 0:
        ap.error("--every must be at least 1, --gap and --max-range positive, --eps and --clear >= 0")
    log, out = a.log, a.out
    walls, poses = [], []
    for k, (ranges, bearings, (x, y, th)) in enumerate(read_scans(log)):
        poses.append([round(x, 5), round(y, 5), 0.3, round(math.degrees(th), 5), 0.0, 0.0])
        if k % a.every or len(ranges) < 2:
            continue
        spacing = abs(bearings[1] - bearings[0])
        run = []
        # A trailing no-return closes the last run.
        for r, b in zip(ranges + [0.0], bearings + [0.0]):
            p = (x + r * math.cos(th + b), y + r * math.sin(th + b)) if 0.05 < r < a.max_range else None
            if p is not None and run and math.dist(run[-1], p) <= max(a.gap, 3 * spacing * r):
                run.append(p)
                continue
            if len(run) >= 2:
                walls.append([[round(u, 4), round(v, 4)] for u, v in simplify(run, a.eps)])
            run = [p] if p is not None else []
    if not poses:
        sys.exit(f"{log}: no FLASER or ROBOTLASER1 lines: not a CARMEN laser log")
    if a.clear > 0:
        walls = clear_path(walls, poses, a.clear)
    plan = {"version": "w0.1", "wallheight": 3.0, "walls": walls, "poses": poses}
    with open(out, "w") as f:
        json.dump(plan, f, separators=(",", ":"))
    segs = sum(len(w) - 1 for w in walls)
    print(f"{out}: {len(walls)} polylines, {segs} segments, {len(poses)} poses", file=sys.stderr)


if __name__ == "__main__":
    main()
