#!/usr/bin/env python3
"""Writes a levelscan scan JSON Lines file (`levelscan simulate` output) as a ROS bag with the
pure-Python `rosbags` library, an implementation independent of levelscan's, so that the tests
check levelscan's reader against bags as ROS tools write them (tests/bag_interop.rs).

    write_bag.py SCANS.jsonl OUT --format mcap|ros1|sqlite3 [options]

`mcap` writes a rosbag2 directory (metadata.yaml + MCAP storage), `sqlite3` one with the
default sqlite3 storage (which levelscan may refuse), `ros1` a ROS 1 `.bag` file.

The layout is the one the contract (CONTRACT.md, "ROS bags") fixes for `simulate -o run.mcap`:
- `/scan`, sensor_msgs/LaserScan in frame `laser`: angle_min = theta[0], angle_increment the
  (even) spacing of theta, NaN where there is no return, range_min/range_max;
- `/joint_states`, sensor_msgs/JointState with joint `hinge`, position = the scan's elevation,
  once just before and once just after each scan (so that the elevation interpolated at the
  scan's stamp is exactly its own);
- `/odom`, nav_msgs/Odometry (frame odom, child base_link) at each scan's stamp: the scan's
  odometry [x, y, yaw];
- `/ground_truth`, geometry_msgs/PoseStamped (frame world) at each scan's stamp: true_pose.
Pose k (the k-th run of equal `sequence`) starts at 1000 + 2k s, its scans 0.1 s apart. Every
message's log time is its header stamp.

Options make the bad bags of the tests: a wrong joint name, no joint messages, joint messages
far from the scans, a second LaserScan topic, a String on the scan topic, the scan topic renamed.
The script also writes, with --expect FILE, the scans as the bag stores them (float32 angles and
ranges) as JSON Lines, for a comparison free of float32 rounding.
"""

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore

POSE_START_S = 1000.0  # pose k starts at 1000 + 2k s (contract)
POSE_PERIOD_S = 2.0
SCAN_PERIOD_S = 0.1  # scans of one pose 0.1 s apart (contract)
JOINT_LEAD_S = 0.01  # joint messages this long before and after each scan


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scans", help="scan JSON Lines (levelscan simulate output)")
    p.add_argument("out", help="output: a directory (mcap, sqlite3) or a .bag file (ros1)")
    p.add_argument("--format", choices=["mcap", "ros1", "sqlite3"], required=True)
    p.add_argument("--compress", action="store_true",
                   help="zstd storage compression (mcap), lz4 chunks (ros1)")
    p.add_argument("--scan-topic", default="/scan")
    p.add_argument("--joint-topic", default="/joint_states")
    p.add_argument("--joint-name", default="hinge",
                   help="the hinge joint's name in /joint_states")
    p.add_argument("--extra-joint", default=None,
                   help="a second joint (position 0) named in every JointState")
    p.add_argument("--no-joints", action="store_true", help="write no JointState messages")
    p.add_argument("--joint-offset", type=float, default=0.0,
                   help="shift every joint message by this many seconds (bad case: far off)")
    p.add_argument("--no-odom", action="store_true")
    p.add_argument("--no-truth", action="store_true")
    p.add_argument("--second-scan-topic", default=None,
                   help="also write every scan on this LaserScan topic")
    p.add_argument("--string-scan", action="store_true",
                   help="write std_msgs/String on the scan topic instead of LaserScan")
    p.add_argument("--range-min", type=float, default=0.02, help="LaserScan range_min (m)")
    p.add_argument("--range-max", type=float, default=None,
                   help="LaserScan range_max (m); default just above the longest reading")
    p.add_argument("--time-increment", type=float, default=0.0,
                   help="LaserScan time_increment (s); 0: stop-and-scan")
    p.add_argument("--sweep-rate", type=float, default=0.0,
                   help="nodding hinge (deg/s), for scans with ray_elevation (simulate "
                        "--sweep-rate): time_increment from it, joint messages on the sweep")
    p.add_argument("--expect", default=None,
                   help="also write the scans as stored in the bag as JSON Lines here")
    return p.parse_args(argv)


def read_scans(path):
    scans = []
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if line.strip():
                try:
                    scans.append(json.loads(line))
                except json.JSONDecodeError as e:
                    sys.exit(f"{path}:{n}: {e}")
    if not scans:
        sys.exit(f"{path}: no scans")
    return scans


def stamps(scans):
    """Seconds of each scan: pose k (k-th run of one sequence) at 1000 + 2k, scans 0.1 s apart."""
    out, pose, within, last = [], -1, 0, object()
    for s in scans:
        if s.get("sequence") != last:
            pose, within, last = pose + 1, 0, s.get("sequence")
        out.append(POSE_START_S + POSE_PERIOD_S * pose + SCAN_PERIOD_S * within)
        within += 1
    return out


def split(t):
    """(sec, nanosec) of t seconds, exact to the nanosecond for these stamps."""
    ns = int(round(t * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000, ns


def bearing_grid(scan, path):
    """angle_min and angle_increment of an evenly spaced theta, as float32 will hold them."""
    theta = scan["theta"]
    n = len(theta)
    inc = (theta[-1] - theta[0]) / (n - 1) if n > 1 else 0.0
    for i, t in enumerate(theta):
        if abs(theta[0] + i * inc - t) > 1e-9:
            sys.exit(f"{path}: scan {scan.get('sequence')}: theta is not evenly spaced at ray {i}")
    return np.float32(theta[0]), np.float32(inc)


def sweep(scan, args):
    """(time_increment s, joint position at t s after the first ray) of a scan. A nodding
    hinge turns at --sweep-rate through the scan's ray_elevation (linear in the ray index), so
    the time between rays is the elevation step over the rate; the header stamp is the first
    ray's time (the ROS LaserScan convention)."""
    rays = scan.get("ray_elevation")
    if not args.sweep_rate or not rays or len(rays) < 2:
        return args.time_increment, lambda t: scan["elevation"]
    rate = math.radians(args.sweep_rate)
    dt = (rays[-1] - rays[0]) / ((len(rays) - 1) * rate)
    return float(np.float32(dt)), lambda t: rays[0] + rate * t


def ranges_of(scan):
    valid = scan.get("valid") or [1 if r is not None else 0 for r in scan["readings"]]
    return np.array([r if (r is not None and v) else math.nan
                     for r, v in zip(scan["readings"], valid)], dtype=np.float32)


def quat_from_rpy(roll, pitch, yaw):
    """(x, y, z, w) of Rz(yaw) Ry(pitch) Rx(roll), REP-103 fixed axes (the contract's pose)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


class Messages:
    """Builds the messages of one typestore (ROS 2 humble or ROS 1 noetic)."""

    def __init__(self, ts, ros1):
        self.ts, self.ros1, self.seq = ts, ros1, 0
        self.T = ts.types

    def header(self, t, frame):
        sec, nsec, _ = split(t)
        stamp = self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        self.seq += 1
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=self.seq, stamp=stamp, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def laser_scan(self, t, scan, args, path, range_max):
        amin, inc = bearing_grid(scan, path)
        n = scan["nrays"]
        return self.T["sensor_msgs/msg/LaserScan"](
            header=self.header(t, "laser"), angle_min=float(amin),
            angle_max=float(np.float32(amin + inc * (n - 1))), angle_increment=float(inc),
            time_increment=sweep(scan, args)[0], scan_time=SCAN_PERIOD_S,
            range_min=args.range_min, range_max=range_max, ranges=ranges_of(scan),
            intensities=np.zeros(0, dtype=np.float32))

    def joint_state(self, t, names, positions):
        z = np.zeros(0, dtype=np.float64)
        return self.T["sensor_msgs/msg/JointState"](
            header=self.header(t, ""), name=names,
            position=np.array(positions, dtype=np.float64), velocity=z, effort=z)

    def pose(self, p):
        G = self.T
        x, y = p[0], p[1]
        if len(p) == 6:
            z, q = p[2], quat_from_rpy(p[5], p[4], p[3])
        else:
            z, q = 0.0, quat_from_rpy(0.0, 0.0, p[2])
        return G["geometry_msgs/msg/Pose"](
            position=G["geometry_msgs/msg/Point"](x=x, y=y, z=z),
            orientation=G["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))

    def odometry(self, t, p):
        G = self.T
        cov = np.zeros(36, dtype=np.float64)
        zero = G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return G["nav_msgs/msg/Odometry"](
            header=self.header(t, "odom"), child_frame_id="base_link",
            pose=G["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(p), covariance=cov),
            twist=G["geometry_msgs/msg/TwistWithCovariance"](
                twist=G["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov))

    def pose_stamped(self, t, p):
        return self.T["geometry_msgs/msg/PoseStamped"](header=self.header(t, "world"),
                                                       pose=self.pose(p))

    def string(self, text):
        return self.T["std_msgs/msg/String"](data=text)

    def serialize(self, msg, msgtype):
        if self.ros1:
            return self.ts.serialize_ros1(msg, msgtype)
        return self.ts.serialize_cdr(msg, msgtype)


def open_writer(args):
    out = Path(args.out)
    if args.format == "ros1":
        from rosbags.rosbag1 import Writer
        w = Writer(out)
        if args.compress:
            w.set_compression(Writer.CompressionFormat.LZ4)
        return w, get_typestore(Stores.ROS1_NOETIC), True
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
    plugin = StoragePlugin.MCAP if args.format == "mcap" else StoragePlugin.SQLITE3
    w = Writer(out, version=9, storage_plugin=plugin)
    if args.compress:
        w.set_compression(CompressionMode.STORAGE if args.format == "mcap"
                          else CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    return w, get_typestore(Stores.ROS2_HUMBLE), False


def events(scans, times, args):
    """(time s, kind, scan) of every message to write, in log-time order."""
    ev = []
    for s, t in zip(scans, times):
        ev.append((t, 1, "scan", s))
        if not args.no_joints:
            ev.append((t - JOINT_LEAD_S + args.joint_offset, 0, "joint", s))
            span = sweep(s, args)[0] * (s["nrays"] - 1)
            ev.append((t + span + JOINT_LEAD_S + args.joint_offset, 2, "joint", s))
        if not args.no_odom and s.get("odometry") is not None:
            ev.append((t, 1, "odom", s))
        if not args.no_truth and s.get("true_pose") is not None:
            ev.append((t, 1, "truth", s))
    ev.sort(key=lambda e: (e[0], e[1]))
    return ev


def write(args, scans, times):
    for s, t in zip(scans, times):
        s["_stamp"] = t

    def joint_at(s, t):
        return sweep(s, args)[1](t - s["_stamp"] - args.joint_offset)

    w, ts, ros1 = open_writer(args)
    m = Messages(ts, ros1)
    scan_type = "std_msgs/msg/String" if args.string_scan else "sensor_msgs/msg/LaserScan"
    longest = max((r for s in scans for r in s["readings"] if r is not None), default=1.0)
    range_max = args.range_max if args.range_max is not None else float(longest) + 1.0
    names = [args.joint_name] + ([args.extra_joint] if args.extra_joint else [])
    with w:
        conn = {"scan": [w.add_connection(args.scan_topic, scan_type, typestore=ts)]}
        if args.second_scan_topic:
            conn["scan"].append(w.add_connection(args.second_scan_topic,
                                                 "sensor_msgs/msg/LaserScan", typestore=ts))
        conn["joint"] = [w.add_connection(args.joint_topic, "sensor_msgs/msg/JointState",
                                          typestore=ts)]
        conn["odom"] = [w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)]
        conn["truth"] = [w.add_connection("/ground_truth", "geometry_msgs/msg/PoseStamped",
                                          typestore=ts)]
        for t, _, kind, s in events(scans, times, args):
            for c in conn[kind]:
                if kind == "scan":
                    if args.string_scan and c is conn["scan"][0]:
                        msg = m.string(json.dumps({"sequence": s.get("sequence")}))
                        mtype = "std_msgs/msg/String"
                    else:
                        msg = m.laser_scan(t, s, args, args.scans, range_max)
                        mtype = "sensor_msgs/msg/LaserScan"
                elif kind == "joint":
                    msg = m.joint_state(t, names, [joint_at(s, t)] + [0.0] * (len(names) - 1))
                    mtype = "sensor_msgs/msg/JointState"
                elif kind == "odom":
                    msg, mtype = m.odometry(t, s["odometry"]), "nav_msgs/msg/Odometry"
                else:
                    msg, mtype = m.pose_stamped(t, s["true_pose"]), "geometry_msgs/msg/PoseStamped"
                w.write(c, split(t)[2], m.serialize(msg, mtype))
    return range_max


def write_expect(path, scans, times, args, range_max):
    """The scans as the bag holds them: float32 bearings and ranges, the contract's stamps."""
    with open(path, "w", encoding="utf-8") as f:
        for s, t in zip(scans, times):
            amin, inc = bearing_grid(s, args.scans)
            r = ranges_of(s)
            keep = [not math.isnan(x) and args.range_min <= x <= range_max for x in r]
            rec = {k: v for k, v in s.items() if k != "_stamp"}
            rec["theta"] = [float(amin) + i * float(inc) for i in range(s["nrays"])]
            rec["readings"] = [float(x) if k else None for x, k in zip(r, keep)]
            rec["valid"] = [1 if k else 0 for k in keep]
            rec.pop("min_theta", None)
            rec.pop("max_theta", None)
            sec, nsec, _ = split(t)
            rec["timestamp"] = [sec, nsec // 1000]
            f.write(json.dumps(rec) + "\n")


def main(argv):
    args = parse_args(argv)
    scans = read_scans(args.scans)
    times = stamps(scans)
    range_max = write(args, scans, times)
    if args.expect:
        write_expect(args.expect, scans, times, args, range_max)
    print(f"wrote {args.out}: {len(scans)} scans", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv[1:])
