//! Benchmarks (divan): run with `cargo bench --bench formats`.
//!
//! Scan JSON Lines throughput (bytes per second) on scans laid out like the simulator's: 181
//! rays, full-precision bearings and ranges, a 6-number `true_pose`, odometry and `hit`. Serial
//! line parsing, the streaming reader, the batched parallel reader, and writing.

use divan::counter::{BytesCount, ItemsCount};
use divan::{Bencher, black_box};
use levelscan::formats::{ParallelScanReader, ScanReader, parse_scan_line, write_scan};
use levelscan::geometry::Pose;
use levelscan::scan::{Hit, Scan, even_bearings};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use std::f64::consts::FRAC_PI_2;
use std::io::Cursor;

fn main() {
    divan::main();
}

/// Scans per benchmark input: 5 scans for each of 100 poses, about 2 MB.
const SCANS: usize = 500;

fn scans() -> Vec<Scan> {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    (0..SCANS)
        .map(|k| {
            let n = 181;
            let readings: Vec<Option<f64>> = (0..n)
                .map(|_| (rng.random::<f64>() > 0.05).then(|| rng.random_range(0.3..15.0)))
                .collect();
            let pose = Pose::new(
                rng.random_range(0.0..20.0),
                rng.random_range(0.0..20.0),
                0.45,
                rng.random_range(-3.0..3.0),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
            );
            Scan {
                sequence: Some((k / 5) as u64),
                elevation: Some(((k % 5) as f64 - 2.0) * 5f64.to_radians()),
                theta: even_bearings(n, -FRAC_PI_2, FRAC_PI_2),
                valid: readings.iter().map(Option::is_some).collect(),
                hit: Some(
                    readings
                        .iter()
                        .map(|r| if r.is_some() { Hit::Wall } else { Hit::Nothing })
                        .collect(),
                ),
                readings,
                odometry: Some(Pose::planar(pose.x + 0.01, pose.y - 0.02, pose.rz)),
                true_pose: Some(pose),
                ..Scan::default()
            }
        })
        .collect()
}

fn text() -> Vec<u8> {
    let mut out = Vec::new();
    for s in scans() {
        write_scan(&mut out, &s).unwrap();
    }
    out
}

#[divan::bench]
fn parse_lines_serial(b: Bencher) {
    let text = text();
    let s = std::str::from_utf8(&text).unwrap();
    b.counter(BytesCount::new(text.len())).bench(|| {
        for line in s.lines() {
            black_box(parse_scan_line(line).unwrap());
        }
    });
}

#[divan::bench]
fn stream_reader(b: Bencher) {
    let text = text();
    b.counter(BytesCount::new(text.len())).bench(|| {
        for item in ScanReader::new(Cursor::new(&text), "bench") {
            black_box(item.unwrap());
        }
    });
}

#[divan::bench]
fn parallel_reader(b: Bencher) {
    let text = text();
    b.counter(BytesCount::new(text.len())).bench(|| {
        for item in ParallelScanReader::new(Cursor::new(&text), "bench") {
            black_box(item.unwrap());
        }
    });
}

#[divan::bench]
fn write_scans(b: Bencher) {
    let scans = scans();
    let bytes = text().len();
    let mut out = Vec::with_capacity(bytes);
    b.counter(BytesCount::new(bytes))
        .counter(ItemsCount::new(scans.len()))
        .bench_local(|| {
            out.clear();
            for s in &scans {
                write_scan(&mut out, s).unwrap();
            }
            black_box(out.len());
        });
}
