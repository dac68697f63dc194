//! Writes ROS 2 bags as MCAP files (CONTRACT.md, "ROS bags"; MCAP registry, "ROS2" profile):
//! header profile `ros2`, `ros2msg` schemas ([`super::schemas`]), `cdr` messages, zstd chunk
//! compression, message indexes after each chunk and a summary with the schemas, channels,
//! statistics and chunk indexes, so that `ros2 bag play`, Foxglove and the reference readers
//! open the file and seek in it.
//!
//! Two kinds of message go in: levelscan's own ([`BagWriter::write`], any [`CdrMessage`],
//! its channel created on the topic's first message), and messages of an input bag copied
//! through unchanged ([`BagWriter::copy_raw`], with the input's schema and encoding).

use super::cdr::CdrMessage;
use super::schemas::{DEFAULT_QOS, ros2msg_schema};
use mcap::records::MessageHeader;
use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};

pub use mcap::write::NoSeek;

/// Uncompressed bytes per chunk \[bytes\]: 1 MiB, the mcap crate's and the Go and C++
/// writers' default, a few hundred LaserScans: small enough that a reader seeking to a time
/// decompresses little, large enough that zstd compresses well.
pub const CHUNK_SIZE: u64 = 1 << 20;

/// A message of an input bag, to be copied through unchanged: its channel's topic, schema
/// and encoding, its times \[ns since the epoch\] and its serialized bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawMessage<'a> {
    pub topic: &'a str,
    /// e.g. `sensor_msgs/msg/LaserScan` (ROS 2) or `sensor_msgs/LaserScan` (ROS 1); empty for
    /// a channel without schema.
    pub schema_name: &'a str,
    /// `ros2msg`, `ros2idl`, `ros1msg`, ...; empty for a channel without schema.
    pub schema_encoding: &'a str,
    pub schema_data: &'a [u8],
    /// `cdr` (ROS 2) or `ros1`.
    pub message_encoding: &'a str,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: &'a [u8],
}

/// Why the bag could not be written; names the output file.
#[derive(Debug, thiserror::Error)]
pub enum BagWriteError {
    #[error("{file}: cannot write the bag: {source}")]
    Mcap {
        file: String,
        #[source]
        source: mcap::McapError,
    },
    #[error(
        "{file}: topic {topic} already holds {existing} messages, cannot also write {new} on it"
    )]
    TopicType {
        file: String,
        topic: String,
        existing: String,
        new: String,
    },
    #[error("{file}: no ros2msg schema known for {type_name} (topic {topic})")]
    UnknownType {
        file: String,
        topic: String,
        type_name: String,
    },
}

/// One channel of the output: its topic's schema name, message encoding and MCAP id, and the
/// next message sequence number on it.
struct OutChannel {
    schema_name: String,
    message_encoding: String,
    id: u16,
    sequence: u32,
}

/// An MCAP writer for ROS 2 bags. Call [`BagWriter::finish`] at the end: it writes the
/// summary; a writer dropped without it leaves a file without a complete summary.
pub struct BagWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    /// The output's name, for errors.
    name: String,
    /// Channels by topic (several when an input bag had one topic with several types).
    channels: HashMap<String, Vec<OutChannel>>,
    messages: u64,
}

/// The writer options of every bag levelscan writes (see the module documentation).
fn options() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .profile("ros2")
        .library(format!("levelscan {}", env!("CARGO_PKG_VERSION")))
        .compression(Some(mcap::Compression::Zstd))
        // Single-threaded zstd: the same bytes on every machine (the multi-threaded frame
        // layout differs from single-threaded), and chunks of 1 MiB gain nothing from threads.
        .compression_threads(0)
        .chunk_size(Some(CHUNK_SIZE))
        .emit_statistics(true)
        .emit_message_indexes(true)
        .emit_chunk_indexes(true)
        .emit_summary_offsets(true)
        .repeat_schemas(true)
        .repeat_channels(true)
}

impl<W: Write + Seek> BagWriter<W> {
    /// Starts a bag on a seekable output (a file); `name` is the output's name for errors.
    pub fn new(out: W, name: impl Into<String>) -> Result<Self, BagWriteError> {
        Self::with_options(out, name.into(), options())
    }

    fn with_options(out: W, name: String, opts: mcap::WriteOptions) -> Result<Self, BagWriteError> {
        let mcap = opts.create(out).map_err(|source| BagWriteError::Mcap {
            file: name.clone(),
            source,
        })?;
        Ok(Self {
            mcap,
            name,
            channels: HashMap::new(),
            messages: 0,
        })
    }

    fn mcap_error(&self, source: mcap::McapError) -> BagWriteError {
        BagWriteError::Mcap {
            file: self.name.clone(),
            source,
        }
    }

    /// Writes one of levelscan's messages on `topic`, log and publish time `log_time` \[ns\],
    /// CDR encoded with its `ros2msg` schema. A topic that already carries another type is
    /// an error (one topic, one type, as ROS 2 requires of a bag it plays).
    pub fn write<M: CdrMessage>(
        &mut self,
        topic: &str,
        log_time: u64,
        msg: &M,
    ) -> Result<(), BagWriteError> {
        let index = match self.find(topic, M::TYPE, "cdr") {
            Some(i) => i,
            None => {
                if let Some(other) = self.channels.get(topic).and_then(|c| c.first()) {
                    return Err(BagWriteError::TopicType {
                        file: self.name.clone(),
                        topic: topic.to_string(),
                        existing: other.schema_name.clone(),
                        new: M::TYPE.to_string(),
                    });
                }
                let schema = ros2msg_schema(M::TYPE).ok_or_else(|| BagWriteError::UnknownType {
                    file: self.name.clone(),
                    topic: topic.to_string(),
                    type_name: M::TYPE.to_string(),
                })?;
                let metadata = default_metadata();
                self.add_channel(
                    topic,
                    M::TYPE,
                    "ros2msg",
                    schema.as_bytes(),
                    "cdr",
                    &metadata,
                )?
            }
        };
        self.put(topic, index, log_time, log_time, &msg.to_cdr())
    }

    /// Copies one input message through unchanged, on a channel like its input channel
    /// (same topic, schema and encoding) with the ROS 2 profile's default channel metadata
    /// ([`DEFAULT_QOS`]). Use [`BagWriter::copy_raw_with_metadata`] to keep the input
    /// channel's own metadata (its QoS: a latched `/tf_static` must stay transient local).
    pub fn copy_raw(&mut self, raw: &RawMessage<'_>) -> Result<(), BagWriteError> {
        match self.find(raw.topic, raw.schema_name, raw.message_encoding) {
            Some(index) => self.put_raw(raw, index),
            None => self.copy_raw_with_metadata(raw, &default_metadata()),
        }
    }

    /// [`BagWriter::copy_raw`] with the input channel's metadata (used when the message's
    /// channel is created, i.e. on the first message of its topic and type).
    pub fn copy_raw_with_metadata(
        &mut self,
        raw: &RawMessage<'_>,
        metadata: &BTreeMap<String, String>,
    ) -> Result<(), BagWriteError> {
        let index = match self.find(raw.topic, raw.schema_name, raw.message_encoding) {
            Some(i) => i,
            None => self.add_channel(
                raw.topic,
                raw.schema_name,
                raw.schema_encoding,
                raw.schema_data,
                raw.message_encoding,
                metadata,
            )?,
        };
        self.put_raw(raw, index)
    }

    fn put_raw(&mut self, raw: &RawMessage<'_>, index: usize) -> Result<(), BagWriteError> {
        self.put(raw.topic, index, raw.log_time, raw.publish_time, raw.data)
    }

    /// The messages written so far.
    pub fn message_count(&self) -> u64 {
        self.messages
    }

    /// Ends the last chunk, writes the summary and footer, and hands back the output (for a
    /// [`NoSeek`] output, `.into_inner()` gives the stream).
    pub fn finish(mut self) -> Result<W, BagWriteError> {
        self.mcap.finish().map_err(|e| self.mcap_error(e))?;
        Ok(self.mcap.into_inner())
    }

    fn find(&self, topic: &str, schema_name: &str, encoding: &str) -> Option<usize> {
        self.channels
            .get(topic)?
            .iter()
            .position(|c| c.schema_name == schema_name && c.message_encoding == encoding)
    }

    fn add_channel(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_encoding: &str,
        schema_data: &[u8],
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<usize, BagWriteError> {
        // A channel without schema has schema id 0 (MCAP spec, Channel record).
        let schema_id = if schema_name.is_empty() && schema_encoding.is_empty() {
            0
        } else {
            self.mcap
                .add_schema(schema_name, schema_encoding, schema_data)
                .map_err(|e| self.mcap_error(e))?
        };
        let id = self
            .mcap
            .add_channel(schema_id, topic, message_encoding, metadata)
            .map_err(|e| self.mcap_error(e))?;
        let list = self.channels.entry(topic.to_string()).or_default();
        list.push(OutChannel {
            schema_name: schema_name.to_string(),
            message_encoding: message_encoding.to_string(),
            id,
            sequence: 0,
        });
        Ok(list.len() - 1)
    }

    fn put(
        &mut self,
        topic: &str,
        index: usize,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), BagWriteError> {
        let channel = &mut self.channels.get_mut(topic).expect("channel added")[index];
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time,
            publish_time,
        };
        channel.sequence = channel.sequence.wrapping_add(1);
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_error(e))?;
        self.messages += 1;
        Ok(())
    }
}

impl<W: Write> BagWriter<NoSeek<W>> {
    /// Starts a bag on an output that cannot seek (standard output, a pipe, a staged file
    /// written front to back): each chunk is built in memory (at most about [`CHUNK_SIZE`])
    /// and written whole, with the same records as [`BagWriter::new`] writes.
    pub fn unseekable(out: W, name: impl Into<String>) -> Result<Self, BagWriteError> {
        Self::with_options(
            NoSeek::new(out),
            name.into(),
            options().disable_seeking(true),
        )
    }
}

/// The channel metadata of a channel levelscan creates: `offered_qos_profiles`, which the
/// ROS 2 profile requires.
pub fn default_metadata() -> BTreeMap<String, String> {
    BTreeMap::from([("offered_qos_profiles".to_string(), DEFAULT_QOS.to_string())])
}
