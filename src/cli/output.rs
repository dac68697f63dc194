//! Where the commands write: standard output, or a file given with `-o`.
//!
//! A file is written through a temporary file in the same directory, flushed, synced and
//! renamed over the target by [`Output::finish`]: a run that fails (bad input half way, a full
//! disk, a broken pipe) leaves the target as it was, never half a file. Devices and pipes
//! (`/dev/null`, `/dev/stdout`, a FIFO) are written directly. An output that is one of the
//! run's inputs, or standard output redirected into one, is refused before anything is
//! written. Every write error names the output (`FILE: cannot write: ...`, `<stdout>: ...`).
//! A file name ending in `.gz` is written gzip-compressed, as the readers read such files.

use anyhow::{Context, bail};
use flate2::write::GzEncoder;
use std::fs::{self, File, Metadata};
use std::io::{self, BufWriter, StdoutLock, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// The display name of standard output in messages.
pub const STDOUT: &str = "<stdout>";

/// An open output; write to it, then call [`Output::finish`]. Dropped without `finish`, a
/// file output removes its temporary file and leaves the target untouched.
pub struct Output {
    name: String,
    sink: Sink,
    /// For a `.gz` name: the compressor, whose output collects in its `Vec` and is moved to
    /// `sink` a block at a time (so that the sink keeps its own error handling and staging).
    /// Boxed: the compressor's state is large, and most outputs have none.
    gzip: Option<Box<GzEncoder<Vec<u8>>>>,
}

/// Compressed bytes collected before they are passed to the sink.
const GZIP_BLOCK: usize = 1 << 16;

enum Sink {
    Stdout(BufWriter<StdoutLock<'static>>),
    /// A device or pipe, written in place.
    Direct(BufWriter<File>),
    /// A temporary file renamed to `target` by `finish`.
    Staged {
        file: BufWriter<File>,
        temp: PathBuf,
        target: PathBuf,
    },
    Finished,
}

/// Opens standard output (for `None` or `-`) or the file `path`. `inputs` are the files the
/// run reads (`None` or `-` for standard input): an output that is one of them is an error,
/// and so is standard output redirected into one of them.
pub fn open_output(path: Option<&Path>, inputs: &[Option<&Path>]) -> anyhow::Result<Output> {
    let path = path.filter(|p| p.as_os_str() != "-");
    let Some(path) = path else {
        check_stdout(inputs)?;
        return Ok(Output {
            name: STDOUT.to_string(),
            sink: Sink::Stdout(BufWriter::with_capacity(1 << 16, io::stdout().lock())),
            gzip: None,
        });
    };
    let name = path.display().to_string();
    for input in inputs {
        if same_file(path, *input) {
            bail!(
                "{name}: the output is also an input of this run ({}); writing it would destroy \
                 what is being read: give another output file",
                input.map_or("<stdin>".to_string(), |p| p.display().to_string())
            );
        }
    }
    let sink = match fs::metadata(path) {
        Ok(m) if !m.is_file() && !m.is_dir() => {
            let file = fs::OpenOptions::new()
                .write(true)
                .open(path)
                .with_context(|| format!("{name}: cannot open for writing"))?;
            Sink::Direct(BufWriter::with_capacity(1 << 16, file))
        }
        Ok(m) if m.is_dir() => bail!("{name}: is a directory, not an output file"),
        existing => {
            stage(path, existing.ok().as_ref()).with_context(|| format!("{name}: cannot create"))?
        }
    };
    let gzip = path.extension().is_some_and(|e| e == "gz").then(|| {
        Box::new(GzEncoder::new(
            Vec::with_capacity(GZIP_BLOCK),
            flate2::Compression::default(),
        ))
    });
    Ok(Output { name, sink, gzip })
}

/// A temporary file next to `path` (next to its target when `path` is a symbolic link), with
/// the permissions of the file it will replace.
fn stage(path: &Path, existing: Option<&Metadata>) -> io::Result<Sink> {
    let target = match existing {
        Some(_) => fs::canonicalize(path)?,
        None => path.to_path_buf(),
    };
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "not a file name"))?;
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(".{file_name}.{}-{n}.tmp", std::process::id()));
        match File::options().write(true).create_new(true).open(&temp) {
            Ok(file) => {
                if let Some(m) = existing {
                    fs::set_permissions(&temp, m.permissions())?;
                }
                return Ok(Sink::Staged {
                    file: BufWriter::with_capacity(1 << 16, file),
                    temp,
                    target,
                });
            }
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && n < 1000 => continue,
            Err(e) => return Err(e),
        }
    }
}

impl Output {
    /// Flushes everything; a file is synced to disk and renamed over its target. Errors name
    /// the output.
    pub fn finish(mut self) -> anyhow::Result<()> {
        if let Some(mut gz) = self.gzip.take() {
            gz.try_finish().map_err(|e| named(&self.name, "write", e))?;
            let rest = std::mem::take(gz.get_mut());
            self.writer()
                .write_all(&rest)
                .map_err(|e| named(&self.name, "write", e))?;
        }
        match std::mem::replace(&mut self.sink, Sink::Finished) {
            Sink::Stdout(mut w) => w.flush().map_err(|e| named(&self.name, "write", e))?,
            Sink::Direct(mut w) => w.flush().map_err(|e| named(&self.name, "write", e))?,
            Sink::Staged { file, temp, target } => {
                let done = file
                    .into_inner()
                    .map_err(|e| e.into_error())
                    .and_then(|f| f.sync_all())
                    .map_err(|e| named(&self.name, "write", e))
                    .and_then(|()| {
                        fs::rename(&temp, &target).map_err(|e| named(&self.name, "replace", e))
                    });
                if done.is_err() {
                    let _ = fs::remove_file(&temp);
                }
                done?;
                // The rename itself is durable once the directory is synced; best effort.
                if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
                    let _ = File::open(dir).and_then(|d| d.sync_all());
                }
            }
            Sink::Finished => {}
        }
        Ok(())
    }

    fn writer(&mut self) -> &mut dyn Write {
        match &mut self.sink {
            Sink::Stdout(w) => w,
            Sink::Direct(w) => w,
            Sink::Staged { file, .. } => file,
            Sink::Finished => unreachable!("finish consumes the output"),
        }
    }
}

impl Output {
    /// Moves the compressed bytes collected so far to the sink (all of them with `all`, else
    /// only once a block has gathered).
    fn pass_compressed(&mut self, all: bool) -> io::Result<()> {
        let Some(gz) = self.gzip.as_mut() else {
            return Ok(());
        };
        if !all && gz.get_ref().len() < GZIP_BLOCK {
            return Ok(());
        }
        let bytes = std::mem::take(gz.get_mut());
        self.writer().write_all(&bytes)
    }
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let r = match self.gzip.as_mut() {
            Some(gz) => gz
                .write(buf)
                .and_then(|n| self.pass_compressed(false).map(|()| n)),
            None => self.writer().write(buf),
        };
        r.map_err(|e| named(&self.name, "write", e))
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        let r = match self.gzip.as_mut() {
            Some(gz) => gz.write_all(buf).and_then(|()| self.pass_compressed(false)),
            None => self.writer().write_all(buf),
        };
        r.map_err(|e| named(&self.name, "write", e))
    }

    fn flush(&mut self) -> io::Result<()> {
        let r = match self.gzip.as_mut() {
            Some(gz) => gz.flush().and_then(|()| self.pass_compressed(true)),
            None => Ok(()),
        }
        .and_then(|()| self.writer().flush());
        r.map_err(|e| named(&self.name, "write", e))
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        if let Sink::Staged { temp, .. } = &self.sink {
            let _ = fs::remove_file(temp);
        }
    }
}

/// The error `FILE: cannot VERB: why`, keeping the kind (a broken pipe stays one). An error
/// that already names an output is passed on as it is.
fn named(name: &str, verb: &str, e: io::Error) -> io::Error {
    if e.get_ref().is_some_and(|inner| inner.is::<NamedError>()) {
        return e;
    }
    let message = format!("{name}: cannot {verb}: {e}");
    io::Error::new(e.kind(), NamedError(message))
}

/// An I/O error's message with the output's name in front.
#[derive(Debug)]
struct NamedError(String);

impl std::fmt::Display for NamedError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NamedError {}

/// Writes `bytes` to the file `path` through [`open_output`] (no inputs to check): the file
/// is complete or left as it was.
pub fn write_file(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let mut out = open_output(Some(path), &[])?;
    out.write_all(bytes)?;
    out.finish()
}

/// Whether `output` is the same file as `input` (`None` or `-`: standard input): the same
/// device and inode (which catches hard and symbolic links), or, for a file not written yet,
/// the same place. Devices and pipes are never the same file: writing them destroys nothing.
fn same_file(output: &Path, input: Option<&Path>) -> bool {
    let out = fs::metadata(output).ok();
    if out.as_ref().is_some_and(|m| !m.is_file()) {
        return false;
    }
    match input.filter(|p| p.as_os_str() != "-") {
        Some(p) => {
            same_identity(out.as_ref(), fs::metadata(p).ok().as_ref())
                || resolved(output).is_some_and(|o| resolved(p) == Some(o))
        }
        None => same_identity(out.as_ref(), stdio_metadata(Stdio::In).as_ref()),
    }
}

fn same_identity(a: Option<&Metadata>, b: Option<&Metadata>) -> bool {
    match (a.and_then(identity), b.and_then(identity)) {
        (Some(a), Some(b)) => a == b,
        _ => false,
    }
}

/// The absolute place of `p`, whether it exists or not (its directory must).
fn resolved(p: &Path) -> Option<PathBuf> {
    fs::canonicalize(p).ok().or_else(|| {
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        Some(fs::canonicalize(dir).ok()?.join(p.file_name()?))
    })
}

/// Standard output redirected into one of the inputs (`> in.jsonl` has already emptied it,
/// `>> in.jsonl` would read what it writes) is refused.
fn check_stdout(inputs: &[Option<&Path>]) -> anyhow::Result<()> {
    let Some(out) = stdio_metadata(Stdio::Out).filter(Metadata::is_file) else {
        return Ok(());
    };
    for input in inputs.iter().flatten().filter(|p| p.as_os_str() != "-") {
        if same_identity(Some(&out), fs::metadata(input).ok().as_ref()) {
            bail!(
                "{STDOUT}: is the input file {} (redirected with > or >>); write to another \
                 file",
                input.display()
            );
        }
    }
    Ok(())
}

enum Stdio {
    In,
    Out,
}

#[cfg(unix)]
fn stdio_metadata(which: Stdio) -> Option<Metadata> {
    use std::os::fd::AsFd;
    let fd = match which {
        Stdio::In => io::stdin().as_fd().try_clone_to_owned(),
        Stdio::Out => io::stdout().as_fd().try_clone_to_owned(),
    };
    File::from(fd.ok()?).metadata().ok()
}

#[cfg(not(unix))]
fn stdio_metadata(_: Stdio) -> Option<Metadata> {
    None
}

#[cfg(unix)]
fn identity(m: &Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn identity(_: &Metadata) -> Option<(u64, u64)> {
    None
}
