//! What kind of file a user gave, told from its first bytes, so that a command given the wrong
//! kind says what it got and what it wants instead of a parser's complaint about column 1
//! (`level office.wall`, `simulate scans.jsonl`, `level` on a 2D CARMEN log).

/// The kinds of input levelscan knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// Scan JSON Lines: a first line that is one JSON object with `nrays`, `readings` or
    /// `theta`.
    ScanJsonLines,
    /// A `.wall` floor plan: a JSON object with `walls` or `wallheight`.
    FloorPlan,
    /// A CARMEN log: text lines of words (`FLASER ...`, `# comment`, `PARAM ...`).
    Carmen,
    Mcap,
    Ros1Bag,
    /// An SQLite database (rosbag2's sqlite3 storage).
    Sqlite,
    Gzip,
    /// Nothing but white space.
    Empty,
    /// Binary or text of no kind above.
    Unknown,
}

impl FileKind {
    /// How a message names the kind: "a floor plan (.wall)", ...
    pub fn described(self) -> &'static str {
        match self {
            FileKind::ScanJsonLines => "a scan file (JSON Lines)",
            FileKind::FloorPlan => "a floor plan (.wall)",
            FileKind::Carmen => "a CARMEN log (2D scans)",
            FileKind::Mcap => "an MCAP bag",
            FileKind::Ros1Bag => "a ROS 1 bag",
            FileKind::Sqlite => "an SQLite database (a rosbag2 sqlite3 bag?)",
            FileKind::Gzip => "a gzip file",
            FileKind::Empty => "empty",
            FileKind::Unknown => {
                "a file of unknown kind (binary, or text in no format levelscan reads)"
            }
        }
    }
}

/// The error for a file of the wrong kind: what it is, and what the command wants.
pub fn wrong_kind(file: &str, kind: FileKind, wanted: &str) -> super::InputError {
    let hint = match kind {
        FileKind::FloorPlan => "; `levelscan simulate PLAN` makes scans from a floor plan",
        FileKind::Sqlite => "; convert a sqlite3 bag with `ros2 bag convert` (storage mcap)",
        _ => "",
    };
    super::InputError::new(
        file,
        "",
        format!("this is {}, but {wanted}{hint}", kind.described()),
    )
}

/// The kind of a file from its first bytes (a few KiB are plenty; a UTF-8 byte order mark is
/// skipped). A JSON object spread over several lines (a pretty-printed plan) counts as a floor
/// plan when its keys say so.
pub fn sniff(head: &[u8]) -> FileKind {
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(head);
    if head.starts_with(super::bag::source::MCAP_MAGIC) {
        return FileKind::Mcap;
    }
    if head.starts_with(b"#ROSBAG") {
        return FileKind::Ros1Bag;
    }
    if head.starts_with(b"SQLite format 3\0") {
        return FileKind::Sqlite;
    }
    if head.starts_with(&[0x1f, 0x8b]) {
        return FileKind::Gzip;
    }
    let text = String::from_utf8_lossy(head);
    // `//` comment lines are allowed in floor plans.
    let mut lines = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with("//"));
    let Some(first) = lines.next() else {
        return if head.iter().all(u8::is_ascii_whitespace) {
            FileKind::Empty
        } else {
            FileKind::Unknown
        };
    };
    if first.starts_with('{') {
        let has = |key: &str| text.contains(&format!("\"{key}\""));
        if let Ok(serde_json::Value::Object(m)) = serde_json::from_str(first) {
            if m.contains_key("walls") || m.contains_key("wallheight") {
                return FileKind::FloorPlan;
            }
            return FileKind::ScanJsonLines;
        }
        if has("walls") || has("wallheight") {
            return FileKind::FloorPlan;
        }
        return FileKind::ScanJsonLines;
    }
    let binary = looks_binary(head);
    let word = first.split_whitespace().next().unwrap_or("");
    if !binary
        && (word.starts_with('#')
            || word
                .chars()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_'))
    {
        return FileKind::Carmen;
    }
    FileKind::Unknown
}

/// Whether the first bytes hold control characters no text file has (an image, an archive,
/// an executable): such a file is of no kind levelscan reads, whatever follows.
pub fn looks_binary(head: &[u8]) -> bool {
    head.iter()
        .take(512)
        .any(|&b| b == 0 || (b < 0x09) || (0x0e..0x20).contains(&b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_are_told_by_their_first_bytes() {
        let cases: &[(&[u8], FileKind)] = &[
            (
                b"{\"nrays\": 2, \"readings\": [1, 2]}\n",
                FileKind::ScanJsonLines,
            ),
            (
                b"{\n  \"wallheight\": 2.5,\n  \"walls\": [[0, 0, 1, 0]]\n}\n",
                FileKind::FloorPlan,
            ),
            (
                b"// office\n{\"walls\": [], \"wallheight\": 2}\n",
                FileKind::FloorPlan,
            ),
            (
                b"# CARMEN Laser Message Log\nFLASER 2 1 1 0 0 0 0 0 0 1 h 1\n",
                FileKind::Carmen,
            ),
            (b"FLASER 2 1 1 0 0 0 0 0 0 1 h 1\n", FileKind::Carmen),
            (b"\x89MCAP0\r\n\x01", FileKind::Mcap),
            (b"#ROSBAG V2.0\n", FileKind::Ros1Bag),
            (b"SQLite format 3\0....", FileKind::Sqlite),
            (b"\x1f\x8b\x08", FileKind::Gzip),
            (b"  \n\n", FileKind::Empty),
            (b"\x00\x01\x02binary", FileKind::Unknown),
            (b"hello world, this is prose\n", FileKind::Unknown),
        ];
        for (bytes, kind) in cases {
            assert_eq!(sniff(bytes), *kind, "{:?}", String::from_utf8_lossy(bytes));
        }
    }
}
