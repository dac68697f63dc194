#!/usr/bin/env python3
"""A floor plan (.wall) from a CARMEN log's own scans, on the log's own path.

usage: scripts/log_to_plan.py LOG[.gz] OUT.wall [--every K] [--eps M] [--gap M] [--max-range M]
                                                [--clear M]

Every K-th `FLASER` scan is placed at its corrected pose; runs of consecutive beams whose points
lie within --gap metres (or 3 beam spacings at their range) of each other become polylines,
simplified by Douglas-Peucker at --eps metres so that a wall seen in one scan is a few straight
segments, not its range noise. A segment that passes within --clear metres of a pose on the
path is dropped: the robot drove there, so what the scan saw there moved (people, doors). The plan's poses are the log's corrected poses, one per scan
(heading in degrees, z 0.3 m, level). `levelscan simulate OUT.wall --flat --elevations 0`
then gives scans along the log's path through its own geometry with an exact true pose: a
control for `eval real`, whose reference (the corrected poses) is not exact.

Beams are spread as `formats::carmen::flaser_bearings` spreads them. Standard library only.
"""
import gzip
import json
import math
import sys


def flaser_bearings(n):
    step = math.pi / (max(n, 2) - 1) if n % 2 == 1 else math.pi / n
    return [-math.pi / 2 + step * i for i in range(n)]


def read_scans(path):
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rt") as f:
        for line in f:
            t = line.split()
            if not t or t[0] != "FLASER":
                continue
            n = int(t[1])
            ranges = [float(r) for r in t[2 : 2 + n]]
            x, y, th = (float(v) for v in t[2 + n : 5 + n])
            yield ranges, (x, y, th)


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
    args = sys.argv[1:]
    opts = {"--every": 5, "--eps": 0.015, "--gap": 0.15, "--max-range": 30.0, "--clear": 0.3}
    pos = []
    i = 0
    while i < len(args):
        if args[i] in opts:
            opts[args[i]] = type(opts[args[i]])(args[i + 1])
            i += 2
        else:
            pos.append(args[i])
            i += 1
    if len(pos) != 2:
        sys.exit(__doc__)
    log, out = pos
    walls, poses = [], []
    for k, (ranges, (x, y, th)) in enumerate(read_scans(log)):
        poses.append([round(x, 5), round(y, 5), 0.3, round(math.degrees(th), 5), 0.0, 0.0])
        if k % opts["--every"]:
            continue
        bearings = flaser_bearings(len(ranges))
        spacing = bearings[1] - bearings[0]
        run, prev_r = [], None
        for r, b in zip(ranges + [0.0], bearings + [0.0]):
            ok = 0.05 < r < opts["--max-range"]
            if ok:
                p = (x + r * math.cos(th + b), y + r * math.sin(th + b))
                gap = max(opts["--gap"], 3 * spacing * r)
                if run and math.dist(run[-1], p) > gap:
                    ok = False
            if not ok:
                if len(run) >= 2:
                    walls.append([[round(a, 4), round(c, 4)] for a, c in simplify(run, opts["--eps"])])
                run = []
                if 0.05 < r < opts["--max-range"]:
                    run = [(x + r * math.cos(th + b), y + r * math.sin(th + b))]
                continue
            run.append(p)
    if opts["--clear"] > 0:
        walls = clear_path(walls, poses, opts["--clear"])
    plan = {"version": "w0.1", "wallheight": 3.0, "walls": walls, "poses": poses}
    with open(out, "w") as f:
        json.dump(plan, f, separators=(",", ":"))
    segs = sum(len(w) - 1 for w in walls)
    print(f"{out}: {len(walls)} polylines, {segs} segments, {len(poses)} poses", file=sys.stderr)


if __name__ == "__main__":
    main()
