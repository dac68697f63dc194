#!/usr/bin/env python3
"""Random floor plans (.wall), for measuring the leveler on rooms nobody tuned it on.

usage: scripts/random_plans.py OUTDIR [--count N] [--seed S]

Writes OUTDIR/plan_S.wall, OUTDIR/plan_S+1.wall, ... : N plans, each drawn from its own seed, so
plan 1007 is the same whatever the count. A plan is one room of a random kind (a rectangle, a
convex polygon, a star-shaped polygon, an L, or a round room of many short walls), 2.5 to 30 m
across, with up to six boxes inside it, up to two columns built half into its walls, and
sometimes a partition; the wall height is 2.2-6 m, with a ceiling half of the time. No poses: use
`levelscan simulate PLAN --random N` or `levelscan eval accuracy PLAN...`, e.g.

    scripts/random_plans.py fresh --count 60 --seed 1000
    levelscan eval accuracy fresh/*.wall --estimator robust --seed 7 --poses 200

Standard library only.
"""
import argparse
import json
import math
import os
import random
import sys


def rectangle(rng):
    w, h = rng.uniform(3, 30), rng.uniform(2.5, 20)
    return [(0, 0), (w, 0), (w, h), (0, h)]


def convex(rng):
    """Corners at sorted random angles on an ellipse."""
    n = rng.randint(4, 9)
    a, b = rng.uniform(3, 12), rng.uniform(3, 12)
    angles = sorted(rng.uniform(0, 2 * math.pi) for _ in range(n))
    return [(a * math.cos(t), b * math.sin(t)) for t in angles]


def star(rng):
    """Corners at even angles (jittered), each at its own distance from the centre."""
    n = rng.randint(5, 11)
    r = rng.uniform(3, 12)
    corners = []
    for i in range(n):
        t = 2 * math.pi * i / n + rng.uniform(-0.2, 0.2)
        d = r * rng.uniform(0.6, 1.0)
        corners.append((d * math.cos(t), d * math.sin(t)))
    return corners


def l_shape(rng):
    w, h = rng.uniform(6, 20), rng.uniform(5, 14)
    fx, fy = rng.uniform(0.4, 0.7), rng.uniform(0.4, 0.7)
    return [(0, 0), (w, 0), (w, h * fy), (w * fx, h * fy), (w * fx, h), (0, h)]


def round_room(rng):
    n = rng.randint(16, 40)
    r = rng.uniform(2.5, 8)
    return [(r * math.cos(2 * math.pi * i / n), r * math.sin(2 * math.pi * i / n)) for i in range(n)]


KINDS = {"rectangle": rectangle, "convex": convex, "star": star, "l_shape": l_shape, "round": round_room}


def inside(p, polygon):
    """Crossing parity of the ray from p towards +x."""
    x, y = p
    odd = False
    for (ax, ay), (bx, by) in zip(polygon, polygon[1:] + polygon[:1]):
        if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
            odd = not odd
    return odd


def box(cx, cy, w, h, angle):
    c, s = math.cos(angle), math.sin(angle)
    return [(cx + c * x - s * y, cy + s * x + c * y)
            for x, y in ((-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2))]


def closed(points):
    return [[round(x, 3), round(y, 3)] for x, y in points + points[:1]]


def plan(seed):
    rng = random.Random(seed)
    kind = rng.choice(sorted(KINDS))
    room = KINDS[kind](rng)
    xs, ys = [p[0] for p in room], [p[1] for p in room]
    lo, hi = (min(xs), min(ys)), (max(xs), max(ys))
    walls = [closed(room)]
    for _ in range(rng.randint(0, 6)):
        corners = box(rng.uniform(lo[0], hi[0]), rng.uniform(lo[1], hi[1]),
                      rng.uniform(0.2, 1.5), rng.uniform(0.2, 1.5), rng.uniform(0, math.pi))
        if all(inside(c, room) for c in corners):
            walls.append(closed(corners))
    # Columns built half into a wall: centred on a point of one of the room's walls.
    for _ in range(rng.randint(0, 2)):
        i = rng.randrange(len(room))
        (ax, ay), (bx, by) = room[i], room[(i + 1) % len(room)]
        t, side = rng.uniform(0.2, 0.8), rng.uniform(0.3, 0.8)
        corners = box(ax + t * (bx - ax), ay + t * (by - ay), side, side, math.atan2(by - ay, bx - ax))
        k = rng.randrange(4)  # drawn from any corner, inside the room or outside it
        walls.append(closed(corners[k:] + corners[:k]))
    if rng.random() < 0.4:
        x0, y0 = rng.uniform(lo[0], hi[0]), rng.uniform(lo[1], hi[1])
        t, length = rng.uniform(0, math.pi), rng.uniform(1, 4)
        x1, y1 = x0 + length * math.cos(t), y0 + length * math.sin(t)
        if inside((x0, y0), room) and inside((x1, y1), room):
            walls.append([[round(x0, 3), round(y0, 3)], [round(x1, 3), round(y1, 3)]])
    return {
        "version": "w0.1",
        "wallheight": rng.choice([2.2, 2.5, 3.0, 4.0, 6.0]),
        "ceiling": rng.random() < 0.5,
        "walls": walls,
    }, kind


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("outdir")
    parser.add_argument("--count", type=int, default=30)
    parser.add_argument("--seed", type=int, default=1000)
    args = parser.parse_args()
    if args.count < 1:
        sys.exit("random_plans.py: --count must be at least 1")
    os.makedirs(args.outdir, exist_ok=True)
    for seed in range(args.seed, args.seed + args.count):
        p, kind = plan(seed)
        path = os.path.join(args.outdir, f"plan_{seed}.wall")
        with open(path, "w") as f:
            json.dump(p, f)
        print(f"{path}: {kind}, {len(p['walls'])} walls, {p['wallheight']} m high"
              f"{', ceiling' if p['ceiling'] else ''}")


if __name__ == "__main__":
    main()
