//! The framing every shard file shares, whatever its kind: magic, format, JSON header, body,
//! checksum; written by `FrameWriter`, read back by `Frame`, study bodies by `Body`.

use super::*;

/// The framing every shard file shares, whatever its kind: a writer that puts the magic, the
/// format and the JSON header first and hashes every byte that passes through it, so that
/// [`FrameWriter::finish`] can append the FNV-1a 64 checksum.
pub(crate) struct FrameWriter<W: Write> {
    inner: W,
    hash: Fnv,
}

impl<W: Write> FrameWriter<W> {
    /// Start a shard file on `inner` with the header `json`.
    pub(crate) fn start(inner: W, json: &[u8]) -> io::Result<Self> {
        let mut w = FrameWriter {
            inner,
            hash: Fnv::new(),
        };
        w.write_all(MAGIC)?;
        w.write_all(&FORMAT.to_le_bytes())?;
        w.write_all(&(json.len() as u64).to_le_bytes())?;
        w.write_all(json)?;
        Ok(w)
    }

    /// Append the checksum of every byte written and flush.
    pub(crate) fn finish(mut self) -> io::Result<()> {
        let sum = self.hash.0;
        self.inner.write_all(&sum.to_le_bytes())?;
        self.inner.flush()
    }
}

impl<W: Write> Write for FrameWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hash.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Write the study shard file `path` whole or not at all: the framing with `header` (JSON),
/// the body that `body` writes, the checksum.
pub(crate) fn write_frame(
    path: &Path,
    header: &impl Serialize,
    body: impl FnOnce(&mut FrameWriter<BufWriter<&mut fs::File>>) -> io::Result<()>,
) -> Result<(), ShardError> {
    let json = serde_json::to_vec(header).map_err(|e| ShardError::Bad {
        path: path.to_path_buf(),
        what: format!("cannot encode the header: {e}"),
    })?;
    let mut set = OutputSet::new();
    set.write_with(path, |file| {
        let mut w = FrameWriter::start(BufWriter::new(file), &json)?;
        body(&mut w)?;
        w.finish()
    })?;
    set.commit()?;
    Ok(())
}

/// Little-endian u64 at `at` (the caller has checked the length).
pub(super) fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// The framing of a shard file read back, whatever its kind: where its header and body lie,
/// its `kind`, and whether its checksum matches (checked last by the caller, so that a
/// truncation reads as one).
#[derive(Debug, Clone)]
pub(crate) struct Frame {
    /// The header's `kind` ([`KIND_RUN`] when it has none or cannot be read).
    pub(crate) kind: String,
    /// Offset of the header.
    header_at: usize,
    /// Offset of the body (one past the header).
    pub(crate) body_at: usize,
    /// Offset of the checksum (one past the body and any trailer).
    pub(crate) sum_at: usize,
    /// Whether the checksum matches.
    pub(crate) checksum_ok: bool,
    computed: u64,
    stored: u64,
}

impl Frame {
    /// Check the magic, format and header length of `bytes` (read from `path`), with
    /// `trailer` bytes before the checksum at the end, and compute the checksum.
    pub(crate) fn parse(path: &Path, bytes: &[u8], trailer: usize) -> Result<Frame, ShardError> {
        let bad = |what: String| ShardError::Bad {
            path: path.to_path_buf(),
            what,
        };
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(bad(
                "not a lidarsim shard file (no `lidarsim shard` magic at its start)".into(),
            ));
        }
        if bytes.len() < PREAMBLE_BYTES + trailer + 8 {
            return Err(bad(format!(
                "truncated: {} bytes, too short for a shard file",
                bytes.len()
            )));
        }
        let format = u32::from_le_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]);
        if format != FORMAT {
            return Err(bad(format!(
                "shard file format {format}; this lidarsim ({VERSION}) reads format {FORMAT}"
            )));
        }
        let header_len = u64_at(bytes, 20);
        let available = (bytes.len() - PREAMBLE_BYTES - trailer - 8) as u64;
        if header_len > MAX_HEADER_BYTES || header_len > available {
            return Err(bad(format!(
                "truncated or corrupt: a header of {header_len} bytes in a file of {} bytes",
                bytes.len()
            )));
        }
        let body_at = PREAMBLE_BYTES + header_len as usize;
        let sum_at = bytes.len() - 8;
        let mut h = Fnv::new();
        h.update(&bytes[..sum_at]);
        let stored = u64_at(bytes, sum_at);
        Ok(Frame {
            kind: header_kind(&bytes[PREAMBLE_BYTES..body_at]),
            header_at: PREAMBLE_BYTES,
            body_at,
            sum_at,
            checksum_ok: h.0 == stored,
            computed: h.0,
            stored,
        })
    }

    /// The header's bytes (JSON).
    pub(crate) fn header<'b>(&self, bytes: &'b [u8]) -> &'b [u8] {
        &bytes[self.header_at..self.body_at]
    }

    /// Refuse the file if its checksum does not match.
    pub(crate) fn check_sum(&self, path: &Path) -> Result<(), ShardError> {
        if self.checksum_ok {
            return Ok(());
        }
        Err(ShardError::Bad {
            path: path.to_path_buf(),
            what: format!(
                "corrupt: checksum {:016x} where the file records {:016x}",
                self.computed, self.stored
            ),
        })
    }
}

/// Check the framing of `bytes` (read from `path`, with `trailer` bytes before the checksum)
/// and read its JSON header as a shard of `kind`. The checksum is the caller's to check
/// ([`Frame::check_sum`]), after any check of the body's length, so that a truncation reads
/// as one.
pub(crate) fn read_header<H: DeserializeOwned>(
    path: &Path,
    bytes: &[u8],
    trailer: usize,
    kind: &str,
) -> Result<(Frame, H), ShardError> {
    let bad = |what: String| ShardError::Bad {
        path: path.to_path_buf(),
        what,
    };
    let frame = Frame::parse(path, bytes, trailer)?;
    if frame.kind != kind {
        return Err(bad(format!(
            "a `{}` shard (from `lidarsim {} --shard`), not a {kind} shard",
            frame.kind,
            command_of(&frame.kind)
        )));
    }
    match serde_json::from_slice(frame.header(bytes)) {
        Ok(h) => Ok((frame, h)),
        Err(e) if frame.checksum_ok => Err(bad(format!("its header cannot be read: {e}"))),
        Err(_) => Err(bad(
            "corrupt or truncated: its header cannot be read and its checksum does not match"
                .into(),
        )),
    }
}

/// Write a string as its length (u64) and its UTF-8 bytes ([`Body::string`] reads it).
pub(crate) fn write_str(w: &mut impl Write, s: &str) -> io::Result<()> {
    w.write_all(&(s.len() as u64).to_le_bytes())?;
    w.write_all(s.as_bytes())
}

/// A reader of a study shard's body (little-endian) that refuses to read past its end; its
/// errors say what is wrong, the caller names the file.
#[derive(Debug)]
pub struct Body<'b> {
    bytes: &'b [u8],
    at: usize,
}

impl<'b> Body<'b> {
    /// A reader at the start of `bytes`.
    pub fn new(bytes: &'b [u8]) -> Self {
        Body { bytes, at: 0 }
    }

    /// Bytes not read yet.
    pub fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn take(&mut self, n: usize) -> Result<&'b [u8], String> {
        if n > self.left() {
            return Err(format!(
                "truncated or corrupt: its records end {} bytes early",
                n - self.left()
            ));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }

    /// One byte.
    pub fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }

    /// A u64.
    pub fn u64(&mut self) -> Result<u64, String> {
        let mut a = [0u8; 8];
        a.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(a))
    }

    /// An f64 from its bits.
    pub fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_bits(self.u64()?))
    }

    /// A string: its length (u64), then its UTF-8 bytes.
    pub fn string(&mut self) -> Result<String, String> {
        let n = self.u64()?;
        let n = usize::try_from(n).map_err(|_| format!("corrupt: a string of {n} bytes"))?;
        String::from_utf8(self.take(n)?.to_vec())
            .map_err(|_| "corrupt: a string that is not UTF-8".to_string())
    }

    /// A count (u64) of `what`, each at least `min_bytes` long: refused if the rest of the
    /// body cannot hold them, so that nothing is allocated on a corrupt count.
    pub fn count(&mut self, min_bytes: usize, what: &str) -> Result<usize, String> {
        let n = self.u64()?;
        let left = self.left();
        if n > (left / min_bytes.max(1)) as u64 {
            return Err(format!("truncated or corrupt: {n} {what} in {left} bytes"));
        }
        Ok(n as usize)
    }

    /// A count (u64) of f64 and the values.
    pub fn f64s(&mut self, what: &str) -> Result<Vec<f64>, String> {
        let n = self.count(8, what)?;
        (0..n).map(|_| self.f64()).collect()
    }
}
