//! Writing output files whole or not at all.
//!
//! Every file lidarsim writes goes through [`write_atomically`]: a temporary file in the same
//! folder, flushed to disk, then renamed over the target, so that a failure (full disk, killed
//! run) never leaves a half-written file or a mix of old and new contents behind.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// The temporary name next to `path` that [`write_atomically`] writes first: hidden, marked
/// with the process id, and with the same extension (writers such as image encoders choose the
/// format by it).
pub fn temporary_path(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    path.with_file_name(format!(".{stem}.tmp{}{ext}", std::process::id()))
}

/// Write `bytes` to `path` through a temporary file and a rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let tmp = temporary_path(path);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Produce a file with `write` (which writes to the path it is given, e.g. a plotting backend)
/// and move it into place only if that succeeds.
pub fn write_via<E: From<io::Error>>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let tmp = temporary_path(path);
    let result = write(&tmp).and_then(|()| std::fs::rename(&tmp, path).map_err(E::from));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
