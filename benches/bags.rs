//! Benchmarks (divan): run with `cargo bench --bench bags`.
//!
//! ROS bag reading throughput (bytes of bag per second) on an MCAP file of LaserScans as a
//! recorder writes them (zstd chunks, 1081 rays of float32 as a Hokuyo UTM-30LX gives, the
//! hinge joint before and after each scan, odometry): the raw message stream, the first pass
//! (topics and signals), and the scans themselves (both passes, converted and grouped).

use divan::counter::BytesCount;
use divan::{Bencher, black_box};
use levelscan::formats::bag::{
    Bag, BagOptions, BagScans, CdrMessage, Header, JointState, LaserScan, Odometry, Time, survey,
};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::OnceLock;

fn main() {
    divan::main();
}

/// Scans in the benchmark bag: about 40 MB of ranges.
const SCANS: usize = 10_000;
const RAYS: usize = 1081;

fn bag_path() -> &'static (PathBuf, u64) {
    static BAG: OnceLock<(PathBuf, u64)> = OnceLock::new();
    BAG.get_or_init(|| {
        let path =
            std::env::temp_dir().join(format!("levelscan-bench-{}.mcap", std::process::id()));
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .compression(Some(mcap::Compression::Zstd))
            .create(file)
            .unwrap();
        let mut channel = |ty: &str, topic: &str| {
            let s = w.add_schema(ty, "ros2msg", b"").unwrap();
            w.add_channel(s, topic, "cdr", &BTreeMap::new()).unwrap()
        };
        let (scan_ch, joint_ch, odom_ch) = (
            channel(LaserScan::TYPE, "/scan"),
            channel(JointState::TYPE, "/joint_states"),
            channel(Odometry::TYPE, "/odom"),
        );
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut seq = 0u32;
        let mut put = |w: &mut mcap::Writer<_>, ch: u16, t: f64, data: &[u8]| {
            let ns = (t * 1e9) as u64;
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: seq,
                log_time: ns,
                publish_time: ns,
            };
            seq += 1;
            w.write_to_known_channel(&header, data).unwrap();
        };
        for k in 0..SCANS {
            let (pose, j) = (k / 5, k % 5);
            let t = 1000.0 + 2.0 * pose as f64 + 0.1 * j as f64;
            let header = |t: f64| Header {
                stamp: Time::from_seconds(t),
                frame_id: "laser".into(),
            };
            let e = -0.2 + 0.1 * j as f64;
            for tj in [t - 0.001, t + 0.026] {
                let js = JointState {
                    header: header(tj),
                    name: vec!["hinge".into()],
                    position: vec![e],
                    velocity: vec![],
                    effort: vec![],
                };
                put(&mut w, joint_ch, tj, &js.to_cdr());
            }
            let scan = LaserScan {
                header: header(t),
                angle_min: -2.35,
                angle_max: 2.35,
                angle_increment: 4.7 / (RAYS - 1) as f32,
                scan_time: 0.025,
                range_max: 30.0,
                range_min: 0.1,
                ranges: (0..RAYS).map(|_| rng.random_range(0.2..12.0f32)).collect(),
                ..Default::default()
            };
            put(&mut w, scan_ch, t, &scan.to_cdr());
            let mut odom = Odometry {
                header: header(t),
                ..Default::default()
            };
            odom.pose.position = [pose as f64 * 0.5, 0.0, 0.0];
            put(&mut w, odom_ch, t, &odom.to_cdr());
        }
        w.finish().unwrap();
        drop(w);
        let len = std::fs::metadata(&path).unwrap().len();
        (path, len)
    })
}

#[divan::bench]
fn messages(bencher: Bencher) {
    let (path, len) = bag_path();
    let bag = Bag::detect(path).unwrap().unwrap();
    bencher.counter(BytesCount::new(*len)).bench(|| {
        let mut bytes = 0usize;
        bag.for_each_message(&mut |m| {
            bytes += m.data.len();
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
        black_box(bytes)
    });
}

#[divan::bench]
fn first_pass(bencher: Bencher) {
    let (path, len) = bag_path();
    let bag = Bag::detect(path).unwrap().unwrap();
    bencher
        .counter(BytesCount::new(*len))
        .bench(|| black_box(survey(&bag, &BagOptions::default()).unwrap().topics.len()));
}

#[divan::bench]
fn scans(bencher: Bencher) {
    let (path, len) = bag_path();
    bencher.counter(BytesCount::new(*len)).bench(|| {
        let bag = Bag::detect(path).unwrap().unwrap();
        let (scans, _) = BagScans::open(bag, &BagOptions::default()).unwrap();
        black_box(scans.map(|s| s.unwrap().1.nrays()).sum::<usize>())
    });
}
