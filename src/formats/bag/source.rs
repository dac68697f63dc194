//! The messages of a bag, in file order: MCAP files (the MCAP specification; ROS 2's profile),
//! rosbag2 directories (their `metadata.yaml` and MCAP files) and ROS 1 `.bag` files (format
//! 2.0), recognised by content. Each message comes with its channel (topic, type, encodings), its
//! log time and its bytes, undecoded; [`super::scans`] turns them into scans.
//!
//! MCAP is read with the `mcap` crate's sans-I/O linear reader, so memory stays flat in the
//! file's length (one chunk at a time) and a truncated file still yields every message before the
//! cut. ROS 1 bags go through the `rosbag` crate (memory-mapped, chunk by chunk).

use crate::formats::InputError;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::HashMap;
use std::io::Read;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// What a file or directory holds, told by its first bytes (or its `metadata.yaml`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BagKind {
    Mcap,
    Rosbag2,
    Ros1,
}

impl BagKind {
    pub fn name(self) -> &'static str {
        match self {
            BagKind::Mcap => "mcap",
            BagKind::Rosbag2 => "rosbag2",
            BagKind::Ros1 => "ros1",
        }
    }
}

/// The first bytes of an MCAP file (MCAP spec, "Magic").
pub const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
/// The first line of a ROS 1 bag of format 2.0 (ROS wiki, "Bags/Format/2.0").
pub const ROS1_MAGIC: &[u8] = b"#ROSBAG V2.0\n";
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";

/// A topic's description: what its messages are and how they are encoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Channel {
    pub topic: String,
    /// The message type in ROS 2 spelling (`sensor_msgs/msg/LaserScan`), also for ROS 1 bags.
    pub message_type: String,
    /// The schema's name as the file has it (ROS 1: `sensor_msgs/LaserScan`).
    pub schema_name: String,
    /// `ros2msg`, `ros1msg`, ...; empty for a channel without a schema.
    pub schema_encoding: String,
    pub schema_data: Vec<u8>,
    /// `cdr` (ROS 2) or `ros1`.
    pub message_encoding: String,
}

/// One message, its bytes as stored.
#[derive(Clone, Copy, Debug)]
pub struct BagMessage<'a> {
    pub channel: &'a Channel,
    /// Nanoseconds since the epoch.
    pub log_time: u64,
    pub publish_time: u64,
    pub data: &'a [u8],
}

/// A bag on disk: its kind and the files that hold its messages, in order.
#[derive(Clone, Debug)]
pub struct Bag {
    pub kind: BagKind,
    /// The path as the user gave it, for messages.
    pub name: String,
    files: Vec<PathBuf>,
}

/// The largest record (or decompressed chunk) the reader accepts \[bytes\]: far above any
/// chunk a recorder writes (rosbag2 and the MCAP writers default to about 1 MiB), low enough
/// that a corrupt length cannot make the reader reserve and fill gigabytes.
const RECORD_LIMIT: usize = 256 << 20;
/// Bytes asked of the file per read: large reads keep the reader near disk speed.
const READ_SIZE: usize = 1 << 20;

impl Bag {
    /// Recognises a bag at `path` by content. `Ok(None)` when it is not a bag (some other
    /// file for the text readers); an error for a bag levelscan cannot read (sqlite3 storage,
    /// ROS 1 format 1.2) or a directory that is no rosbag2 bag.
    pub fn detect(path: &Path) -> Result<Option<Bag>, InputError> {
        let name = path.display().to_string();
        if path.is_dir() {
            return rosbag2_files(path, &name).map(|files| {
                Some(Bag {
                    kind: BagKind::Rosbag2,
                    name,
                    files,
                })
            });
        }
        let mut head = [0u8; 16];
        let n = read_head(path, &mut head).map_err(|e| open_error(&name, &e))?;
        let head = &head[..n];
        let kind = if head.starts_with(MCAP_MAGIC) {
            BagKind::Mcap
        } else if head.starts_with(ROS1_MAGIC) {
            BagKind::Ros1
        } else if head.starts_with(b"#ROSBAG V") {
            return Err(InputError::new(
                name,
                "",
                "a ROS 1 bag of an old format version (levelscan reads format 2.0; \
                 `rosbag reindex`/`rosbag fix` rewrite it)",
            ));
        } else if head.starts_with(SQLITE_MAGIC) {
            return Err(sqlite_error(name));
        } else {
            return Ok(None);
        };
        Ok(Some(Bag {
            kind,
            files: vec![path.to_path_buf()],
            name,
        }))
    }

    /// Calls `f` with every message in file order until it breaks or fails. Errors name the
    /// file and, where known, the topic and log time of the last message read.
    pub fn for_each_message(
        &self,
        f: &mut dyn FnMut(&BagMessage) -> Result<ControlFlow<()>, InputError>,
    ) -> Result<(), InputError> {
        for file in &self.files {
            let name = if self.files.len() == 1 {
                self.name.clone()
            } else {
                file.display().to_string()
            };
            let flow = match self.kind {
                BagKind::Mcap | BagKind::Rosbag2 => read_mcap(file, &name, f)?,
                BagKind::Ros1 => read_ros1(file, &name, f)?,
            };
            if flow.is_break() {
                break;
            }
        }
        Ok(())
    }
}

/// The ROS 2 spelling of a message type: `pkg/Type` (ROS 1) becomes `pkg/msg/Type`.
pub fn ros2_type_name(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>()[..] {
        [pkg, ty] => format!("{pkg}/msg/{ty}"),
        _ => name.to_string(),
    }
}

/// A log time for messages: seconds with nine decimals, as `ros2 bag info` prints them.
pub fn log_time_text(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// The location part of an error about a message: `TOPIC at T s`.
pub fn at_message(topic: &str, log_time: u64) -> String {
    format!("{topic} at {} s", log_time_text(log_time))
}

fn read_head(path: &Path, head: &mut [u8]) -> std::io::Result<usize> {
    let mut file = std::fs::File::open(path)?;
    let mut n = 0;
    while n < head.len() {
        let got = file.read(&mut head[n..])?;
        if got == 0 {
            break;
        }
        n += got;
    }
    Ok(n)
}

fn open_error(name: &str, e: &std::io::Error) -> InputError {
    InputError::new(name, "", format!("cannot open: {e}"))
}

fn sqlite_error(name: String) -> InputError {
    InputError::new(
        name,
        "",
        "a rosbag2 bag with sqlite3 storage: levelscan reads MCAP storage \
         (convert it with `ros2 bag convert`, storage_id mcap)",
    )
}

/// The MCAP files of a rosbag2 directory, as its `metadata.yaml` lists them
/// (`relative_file_paths`), else every `.mcap` file in it by name.
fn rosbag2_files(dir: &Path, name: &str) -> Result<Vec<PathBuf>, InputError> {
    let meta_path = dir.join("metadata.yaml");
    let meta = std::fs::read_to_string(&meta_path).map_err(|_| {
        InputError::new(
            name,
            "",
            "a directory without metadata.yaml: not a rosbag2 bag (give a bag directory, \
             an .mcap file, a .bag file or a scan file)",
        )
    })?;
    let meta_name = meta_path.display().to_string();
    if let Some(storage) = yaml_value(&meta, "storage_identifier") {
        if storage == "sqlite3" {
            return Err(sqlite_error(meta_name));
        }
        if storage != "mcap" {
            return Err(InputError::new(
                meta_name,
                "",
                format!("storage_identifier is {storage:?}; levelscan reads mcap"),
            ));
        }
    }
    let mut files: Vec<PathBuf> = relative_file_paths(&meta)
        .into_iter()
        .map(|f| dir.join(f))
        .collect();
    if files.is_empty() {
        let entries = std::fs::read_dir(dir).map_err(|e| open_error(name, &e))?;
        files = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .collect();
        files.sort();
    }
    if files.is_empty() {
        return Err(InputError::new(meta_name, "", "the bag lists no MCAP file"));
    }
    for f in &files {
        if !f.is_file() {
            return Err(InputError::new(
                meta_name.clone(),
                "",
                format!("lists {} but the file is not there", f.display()),
            ));
        }
    }
    Ok(files)
}

/// The value of the first `key: value` line, unquoted (enough of YAML for metadata.yaml's
/// scalar fields).
fn yaml_value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines().find_map(|l| {
        let rest = l.trim_start().strip_prefix(key)?.strip_prefix(':')?;
        Some(rest.trim().trim_matches(|c| c == '"' || c == '\''))
    })
}

/// The entries of `relative_file_paths:`, a YAML block list of file names.
fn relative_file_paths(text: &str) -> Vec<String> {
    let mut lines = text
        .lines()
        .skip_while(|l| l.trim() != "relative_file_paths:");
    lines.next();
    lines
        .map(str::trim)
        .take_while(|l| l.starts_with("- "))
        .map(|l| {
            l[2..]
                .trim()
                .trim_matches(|c| c == '"' || c == '\'')
                .to_string()
        })
        .collect()
}

/// Where the reader is, for errors: the last message's topic and log time.
#[derive(Default)]
struct Position {
    topic: String,
    log_time: Option<u64>,
}

impl Position {
    fn error(&self, file: &str, message: impl Into<String>) -> InputError {
        let message = message.into();
        match self.log_time {
            Some(t) => InputError::new(
                file,
                "",
                format!("{message} (after {})", at_message(&self.topic, t)),
            ),
            None => InputError::new(file, "", format!("{message} (before the first message)")),
        }
    }
}

fn read_mcap(
    path: &Path,
    name: &str,
    f: &mut dyn FnMut(&BagMessage) -> Result<ControlFlow<()>, InputError>,
) -> Result<ControlFlow<()>, InputError> {
    let mut file = std::fs::File::open(path).map_err(|e| open_error(name, &e))?;
    let options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(true)
        .with_record_length_limit(RECORD_LIMIT);
    let mut reader = LinearReader::new_with_options(options);
    let mut schemas: HashMap<u16, (String, String, Vec<u8>)> = HashMap::new();
    let mut channels: HashMap<u16, Channel> = HashMap::new();
    let mut at = Position::default();
    while let Some(event) = reader.next_event() {
        let event = event.map_err(|e| at.error(name, mcap_error_text(&e)))?;
        let (opcode, data) = match event {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n.max(READ_SIZE));
                let got = file
                    .read(buf)
                    .map_err(|e| at.error(name, format!("cannot read: {e}")))?;
                reader.notify_read(got);
                continue;
            }
            LinearReadEvent::Record { opcode, data } => (opcode, data),
        };
        let record =
            mcap::parse_record(opcode, data).map_err(|e| at.error(name, mcap_error_text(&e)))?;
        match record {
            mcap::records::Record::Schema { header, data } => {
                schemas.insert(header.id, (header.name, header.encoding, data.into_owned()));
            }
            mcap::records::Record::Channel(c) => {
                let id = c.id;
                channels.insert(id, channel_of(c, &schemas, &at, name)?);
            }
            mcap::records::Record::Message { header, data } => {
                let Some(channel) = channels.get(&header.channel_id) else {
                    return Err(at.error(
                        name,
                        format!(
                            "a message at {} s on channel {}, which is not defined",
                            log_time_text(header.log_time),
                            header.channel_id
                        ),
                    ));
                };
                let message = BagMessage {
                    channel,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: &data,
                };
                if f(&message)?.is_break() {
                    return Ok(ControlFlow::Break(()));
                }
                at.topic.clone_from(&channel.topic);
                at.log_time = Some(header.log_time);
            }
            _ => {}
        }
    }
    Ok(ControlFlow::Continue(()))
}

/// An MCAP channel record with its schema (`schemas` by id: name, encoding, data); a schema
/// id that names no schema is an error.
fn channel_of(
    c: mcap::records::Channel,
    schemas: &HashMap<u16, (String, String, Vec<u8>)>,
    at: &Position,
    name: &str,
) -> Result<Channel, InputError> {
    let (schema_name, schema_encoding, schema_data) = match c.schema_id {
        0 => Default::default(),
        id => schemas.get(&id).cloned().ok_or_else(|| {
            at.error(
                name,
                format!(
                    "channel {} names schema {id}, which is not defined",
                    c.topic
                ),
            )
        })?,
    };
    Ok(Channel {
        message_type: ros2_type_name(&schema_name),
        topic: c.topic,
        schema_name,
        schema_encoding,
        schema_data,
        message_encoding: c.message_encoding,
    })
}

/// The mcap crate's errors, said for a user.
fn mcap_error_text(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::UnexpectedEof => {
            "the bag is truncated: it ends in the middle of a record".to_string()
        }
        mcap::McapError::BadMagic => "not an MCAP file (bad magic)".to_string(),
        other => format!("corrupt MCAP data: {other}"),
    }
}

fn read_ros1(
    path: &Path,
    name: &str,
    f: &mut dyn FnMut(&BagMessage) -> Result<ControlFlow<()>, InputError>,
) -> Result<ControlFlow<()>, InputError> {
    check_ros1_index(path, name)?;
    // The rosbag crate trusts the bag's record lengths (it slices the mapped file with them);
    // the index check above catches a cut file, and a panic on a corrupt record inside is
    // turned into an input error rather than a crash.
    let previous_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        read_ros1_records(path, name, f)
    }));
    std::panic::set_hook(previous_hook);
    result.unwrap_or_else(|_| {
        Err(InputError::new(
            name,
            "",
            "corrupt ROS 1 bag: a record's length points outside the file",
        ))
    })
}

/// A ROS 1 bag header's `index_pos` (ROS wiki, Bags/Format/2.0: the bag header record's
/// fields are `len name=value` pairs) must lie inside the file: a recording cut short has its
/// index missing (0, or beyond the end).
fn check_ros1_index(path: &Path, name: &str) -> Result<(), InputError> {
    let mut head = vec![0u8; 4096];
    let n = read_head(path, &mut head).map_err(|e| open_error(name, &e))?;
    let len = std::fs::metadata(path)
        .map_err(|e| open_error(name, &e))?
        .len();
    let head = &head[..n];
    let u32_at = |i: usize| -> Option<usize> {
        Some(u32::from_le_bytes(head.get(i..i + 4)?.try_into().ok()?) as usize)
    };
    let bad = |m: &str| Err(InputError::new(name, "", m.to_string()));
    let mut i = ROS1_MAGIC.len();
    let Some(header_len) = u32_at(i) else {
        return bad("a truncated ROS 1 bag: it ends inside its header");
    };
    i += 4;
    let end = i + header_len;
    let mut index_pos = None;
    while i + 4 <= end.min(head.len()) {
        let Some(field_len) = u32_at(i) else { break };
        let field = head.get(i + 4..i + 4 + field_len).unwrap_or(&[]);
        if let Some(v) = field.strip_prefix(b"index_pos=")
            && v.len() == 8
        {
            index_pos = Some(u64::from_le_bytes(v.try_into().expect("8 bytes")));
        }
        i += 4 + field_len;
    }
    match index_pos {
        None => bad("not a readable ROS 1 bag: its header has no index_pos"),
        Some(0) => bad(
            "a ROS 1 bag without its index (a recording cut short?): `rosbag reindex` repairs it",
        ),
        Some(p) if p > len || p < end as u64 => bad(&format!(
            "a truncated ROS 1 bag: its index is at byte {p} but the file has {len} bytes \
             (`rosbag reindex` may repair it)"
        )),
        Some(_) => Ok(()),
    }
}

fn read_ros1_records(
    path: &Path,
    name: &str,
    f: &mut dyn FnMut(&BagMessage) -> Result<ControlFlow<()>, InputError>,
) -> Result<ControlFlow<()>, InputError> {
    use rosbag::{ChunkRecord, MessageRecord, RosBag};
    let bag = RosBag::new(path)
        .map_err(|e| InputError::new(name, "", format!("not a readable ROS 1 bag: {e}")))?;
    let mut channels: HashMap<u32, Channel> = HashMap::new();
    let mut at = Position::default();
    let ros1_error = |at: &Position, e: rosbag::Error| {
        let text = e.to_string().replace("rosbag::Error: ", "");
        at.error(name, format!("corrupt or truncated ROS 1 bag: {text}"))
    };
    for record in bag.chunk_records() {
        let ChunkRecord::Chunk(chunk) = record.map_err(|e| ros1_error(&at, e))? else {
            continue;
        };
        for item in chunk.messages() {
            match item.map_err(|e| ros1_error(&at, e))? {
                MessageRecord::Connection(c) => {
                    channels.insert(
                        c.id,
                        Channel {
                            topic: c.topic.to_string(),
                            message_type: ros2_type_name(c.tp),
                            schema_name: c.tp.to_string(),
                            schema_encoding: "ros1msg".to_string(),
                            schema_data: c.message_definition.as_bytes().to_vec(),
                            message_encoding: "ros1".to_string(),
                        },
                    );
                }
                MessageRecord::MessageData(m) => {
                    let Some(channel) = channels.get(&m.conn_id) else {
                        return Err(at.error(
                            name,
                            format!(
                                "a message on connection {}, which is not defined",
                                m.conn_id
                            ),
                        ));
                    };
                    let message = BagMessage {
                        channel,
                        log_time: m.time,
                        publish_time: m.time,
                        data: m.data,
                    };
                    if f(&message)?.is_break() {
                        return Ok(ControlFlow::Break(()));
                    }
                    at.topic.clone_from(&channel.topic);
                    at.log_time = Some(m.time);
                }
            }
        }
    }
    Ok(ControlFlow::Continue(()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros1_type_names_get_the_msg_namespace() {
        assert_eq!(
            ros2_type_name("sensor_msgs/LaserScan"),
            "sensor_msgs/msg/LaserScan"
        );
        assert_eq!(
            ros2_type_name("sensor_msgs/msg/LaserScan"),
            "sensor_msgs/msg/LaserScan"
        );
    }

    #[test]
    fn log_times_print_with_nine_decimals() {
        assert_eq!(log_time_text(1_002_100_000_000), "1002.100000000");
        assert_eq!(at_message("/scan", 5), "/scan at 0.000000005 s");
    }

    #[test]
    fn metadata_yaml_gives_storage_and_files() {
        let meta = "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  \
                    relative_file_paths:\n    - run_0.mcap\n    - \"run_1.mcap\"\n  duration:\n";
        assert_eq!(yaml_value(meta, "storage_identifier"), Some("mcap"));
        assert_eq!(relative_file_paths(meta), vec!["run_0.mcap", "run_1.mcap"]);
    }
}
