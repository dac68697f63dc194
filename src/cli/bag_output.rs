//! `-o FILE.mcap` for `level` and `match` (CONTRACT.md, "ROS bags"): a ROS 2 bag with every
//! input message copied through, in log-time order, and the command's own messages stamped
//! and logged with each pose's (or scan's) base scan, so that the output plays like the input.
//!
//! The input bag is read a second time on a thread of its own while the command writes, a
//! bounded number of messages ahead, so memory stays flat in the bag's length. ROS 1 input is
//! transcoded to CDR for the types levelscan knows (a ROS 2 bag plays only CDR); other types are
//! copied with their ROS 1 encoding and schema.

use super::output::Output;
use levelscan::formats::InputError;
use levelscan::formats::bag::convert::{
    ScanMeta, attitude, odom_matched, scan_level, status_string,
};
use levelscan::formats::bag::source::Channel;
use levelscan::formats::bag::write::NoSeek;
use levelscan::formats::bag::{
    Bag, BagWriter, CdrMessage, Imu, JointState, LaserScan, Odometry, PoseStamped, RawMessage,
    StringMsg,
};
use levelscan::scan::Scan;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::Path;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};

/// What the output is: JSON Lines, or a ROS 2 bag (MCAP).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// Scan JSON Lines.
    Jsonl,
    /// A ROS 2 bag: one MCAP file (profile ros2, CDR messages).
    Mcap,
}

/// The format to write: `--format` when given, else MCAP for an `-o` path ending in `.mcap`,
/// else JSON Lines.
pub fn output_format(flag: Option<OutputFormat>, path: Option<&Path>) -> OutputFormat {
    flag.unwrap_or_else(|| {
        if path.is_some_and(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
        }) {
            OutputFormat::Mcap
        } else {
            OutputFormat::Jsonl
        }
    })
}

/// An input message owned, for the copy thread.
struct Owned {
    channel: Arc<Channel>,
    log_time: u64,
    publish_time: u64,
    data: Vec<u8>,
}

/// Messages queued between the copy thread and the writer.
const QUEUE: usize = 1024;

/// The bag being written, and the input it copies through.
pub struct BagOutput {
    writer: BagWriter<NoSeek<Output>>,
    input: Option<Receiver<Result<Owned, InputError>>>,
    peeked: Option<Owned>,
    /// Index of the record written, for stamps of scans without time.
    records: usize,
    kind: Kind,
}

/// Which command writes: it decides which input topics its own replace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Level,
    Match,
}

impl BagOutput {
    /// Starts the output; `input` is the bag to copy through (none for text input).
    pub fn new(
        out: Output,
        name: &str,
        input: Option<Bag>,
        kind: Kind,
    ) -> anyhow::Result<BagOutput> {
        let writer = BagWriter::unseekable(out, name)?;
        let input = input.map(|bag| {
            let (tx, rx) = sync_channel(QUEUE);
            std::thread::spawn(move || {
                let mut channels: HashMap<(String, String), Arc<Channel>> = HashMap::new();
                let result = bag.for_each_message(&mut |m| {
                    let key = (m.channel.topic.clone(), m.channel.message_type.clone());
                    let channel = channels
                        .entry(key)
                        .or_insert_with(|| Arc::new(m.channel.clone()))
                        .clone();
                    let owned = Owned {
                        channel,
                        log_time: m.log_time,
                        publish_time: m.publish_time,
                        data: m.data.to_vec(),
                    };
                    Ok(if tx.send(Ok(owned)).is_err() {
                        ControlFlow::Break(())
                    } else {
                        ControlFlow::Continue(())
                    })
                });
                if let Err(e) = result {
                    let _ = tx.send(Err(e));
                }
            });
            rx
        });
        Ok(BagOutput {
            writer,
            input,
            peeked: None,
            records: 0,
            kind,
        })
    }

    /// Topics this command writes: an input that already has them (a bag leveled before) does
    /// not get them copied, so that each still holds one message per pose or scan.
    const WRITTEN: [&'static str; 5] = [
        "/scan_level",
        "/attitude",
        "/level_status",
        "/odom_matched",
        "/match_status",
    ];

    /// Copies the input's messages logged at or before `log_time`.
    fn copy_until(&mut self, log_time: u64) -> anyhow::Result<()> {
        loop {
            if self.peeked.is_none() {
                let Some(rx) = &self.input else { return Ok(()) };
                match rx.recv() {
                    Ok(item) => self.peeked = Some(item?),
                    Err(_) => {
                        self.input = None;
                        return Ok(());
                    }
                }
            }
            let next = self.peeked.as_ref().expect("just filled");
            if next.log_time > log_time {
                return Ok(());
            }
            let m = self.peeked.take().expect("just checked");
            if !self.replaces(&m.channel.topic) {
                self.copy(&m)?;
            }
        }
    }

    /// True when this run writes `topic` itself (level: its three topics; match: its two).
    fn replaces(&self, topic: &str) -> bool {
        let own = match self.kind {
            Kind::Level => &Self::WRITTEN[..3],
            Kind::Match => &Self::WRITTEN[3..],
        };
        own.contains(&topic)
    }

    /// One input message: transcoded to CDR when it is ROS 1 of a type levelscan knows.
    fn copy(&mut self, m: &Owned) -> anyhow::Result<()> {
        let c = &m.channel;
        if c.message_encoding == "ros1" {
            let t = m.log_time;
            let topic = c.topic.as_str();
            let done = match c.message_type.as_str() {
                LaserScan::TYPE => self.transcode::<LaserScan>(topic, t, &m.data)?,
                JointState::TYPE => self.transcode::<JointState>(topic, t, &m.data)?,
                Odometry::TYPE => self.transcode::<Odometry>(topic, t, &m.data)?,
                PoseStamped::TYPE => self.transcode::<PoseStamped>(topic, t, &m.data)?,
                Imu::TYPE => self.transcode::<Imu>(topic, t, &m.data)?,
                StringMsg::TYPE => self.transcode::<StringMsg>(topic, t, &m.data)?,
                _ => false,
            };
            if done {
                return Ok(());
            }
        }
        self.writer.copy_raw(&RawMessage {
            topic: &c.topic,
            schema_name: &c.schema_name,
            schema_encoding: &c.schema_encoding,
            schema_data: &c.schema_data,
            message_encoding: &c.message_encoding,
            log_time: m.log_time,
            publish_time: m.publish_time,
            data: &m.data,
        })?;
        Ok(())
    }

    /// Writes a ROS 1 message as CDR; false (copy it raw) when it does not decode.
    fn transcode<M: CdrMessage>(
        &mut self,
        topic: &str,
        t: u64,
        data: &[u8],
    ) -> anyhow::Result<bool> {
        match M::from_ros1(data) {
            Ok(msg) => {
                self.writer.write(topic, t, &msg)?;
                Ok(true)
            }
            Err(_) => Ok(false),
        }
    }

    /// `level`'s messages for one pose's record: `/scan_level`, `/attitude`, `/level_status`.
    pub fn level_record(&mut self, record: &Scan) -> anyhow::Result<()> {
        let meta = ScanMeta::of(record, self.records);
        self.records += 1;
        self.copy_until(meta.log_time)?;
        let t = meta.log_time;
        self.writer
            .write("/scan_level", t, &scan_level(record, &meta))?;
        self.writer
            .write("/attitude", t, &attitude(record, &meta))?;
        let data = status_string(record, "level").unwrap_or_else(|| "null".to_string());
        self.writer.write("/level_status", t, &StringMsg { data })?;
        Ok(())
    }

    /// `match`'s messages for one scan's record: `/odom_matched`, `/match_status`.
    pub fn match_record(&mut self, record: &Scan) -> anyhow::Result<()> {
        let meta = ScanMeta::of(record, self.records);
        self.records += 1;
        self.copy_until(meta.log_time)?;
        let t = meta.log_time;
        if let Some(odom) = odom_matched(record, &meta) {
            self.writer.write("/odom_matched", t, &odom)?;
        }
        let data = status_string(record, "match").unwrap_or_else(|| "null".to_string());
        self.writer.write("/match_status", t, &StringMsg { data })?;
        Ok(())
    }

    /// Copies the rest of the input, writes the summary, and finishes the output.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.copy_until(u64::MAX)?;
        let out = self.writer.finish()?.into_inner();
        out.finish()
    }
}
