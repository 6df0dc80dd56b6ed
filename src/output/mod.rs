//! Writing a command's output files all together or not at all, and CSV text fields.
//!
//! Every file lidarsim writes goes through an [`OutputSet`]: a command stages all its files,
//! then calls [`OutputSet::commit`]. Staged files are written into a hidden directory
//! (`.lidarsim-staging-<pid>-<n>`) and flushed to disk; nothing at the outputs' paths changes
//! before the commit. Dropping a set without committing it (any error, `?`) removes the staging
//! directory, so a failed command leaves no partial file, no temporary entry and no mix of old
//! and new outputs, whatever the failure (a full disk, a producer that fails, a directory where
//! a file should go).
//!
//! What the commit guarantees, per target directory:
//!
//! * **The directory does not exist yet**: the staging directory is renamed to it, one atomic
//!   step: it appears with all its files or not at all.
//! * **It exists** (and may hold an earlier run's outputs, which a new run replaces): one
//!   rename per file over the old one, so each file is at every moment whole, old or new. The
//!   renames start only when every file of the set is written and flushed and no name is
//!   blocked (a directory in the way is refused before anything is written, and checked again
//!   here), and each old file is first kept as a hard link (or a copy) in the staging
//!   directory. Then the earlier run's outputs this set does not rewrite
//!   ([`OutputSet::replaces`]: files with the names the command may write, never any other)
//!   are renamed into the staging directory, so that no stale file is left beside the new
//!   ones. If a rename fails midway, the renames done are undone: the old files come back,
//!   the new names go, and the error says that nothing changed. Only a crash or power loss in
//!   the instant of the renames, or an undo that fails too, can leave a mix; the error then
//!   names the files that are new.
//!
//! The staging directory sits inside the target directory when that exists, and in its nearest
//! existing ancestor otherwise, so that it is on the target's filesystem (a rename cannot cross
//! filesystems) even when the target is a mount point. A process that is killed can leave one
//! behind: it is hidden, and its name says what it is.
//!
//! **No `NaN` or `inf` in a CSV file.** A number that cannot be computed is an empty field
//! ([`csv_number`] formats one so), and every `.csv` file staged is checked: an unquoted field
//! that reads as a non-finite number (`NaN`, `inf`, `-inf`, `Infinity`, any case) refuses the
//! whole set with the file, line and column named ([`OutputError::NonFinite`]), so that a
//! writer that forgets [`csv_number`] fails loudly instead of writing it. Text fields that
//! would read so are quoted by [`csv_field`].

use std::borrow::Cow;
use std::ffi::OsString;
use std::fmt::Display;
use std::fs::{self, File};
use std::io;
use std::path::{Path, PathBuf};

/// Why output could not be written. Every variant names the output path the user gave.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutputError {
    /// An I/O operation failed (a full disk, no permission, ...).
    #[error("cannot write {}: {error}", path.display())]
    Io {
        /// The output.
        path: PathBuf,
        /// What the system reported.
        error: io::Error,
    },
    /// A directory has the name of an output file.
    #[error("cannot write {}: a directory of that name is in the way", .0.display())]
    DirectoryInTheWay(PathBuf),
    /// An output's path holds something that is not a file: a named pipe, a socket or a
    /// device, which a whole-or-nothing write would replace by a regular file (as root, even
    /// /dev/null).
    #[error(
        "cannot write {}: it is a pipe, socket or device, not a regular file (lidarsim writes each output whole and renames it into place; give a file or directory path)",
        .0.display()
    )]
    NotARegularFile(PathBuf),
    /// Something on the way to an output file is not a directory.
    #[error("cannot write {}: {} is not a directory", path.display(), dir.display())]
    NotADirectory {
        /// The output.
        path: PathBuf,
        /// What should be a directory.
        dir: PathBuf,
    },
    /// The path names no file (`..`, `/`).
    #[error("cannot write {}: it does not name a file", .0.display())]
    NotAFileName(PathBuf),
    /// A CSV file holds a non-finite number (a bug of its writer, which must write an empty
    /// field for a value that cannot be computed).
    #[error(
        "cannot write {}: line {line}, column {column} is `{value}`: a value that cannot be computed must be an empty field (a bug in lidarsim; please report it)",
        path.display()
    )]
    NonFinite {
        /// The output.
        path: PathBuf,
        /// Its line (1-based).
        line: usize,
        /// The column: its name from the header line, or its number.
        column: String,
        /// The field as written.
        value: String,
    },
    /// Two outputs of one command have the same path.
    #[error("{} is given for two outputs", .0.display())]
    Twice(PathBuf),
    /// The producer of a file (e.g. a plotting backend) failed.
    #[error("cannot write {}: {message}", path.display())]
    Produce {
        /// The output.
        path: PathBuf,
        /// The producer's error.
        message: String,
    },
    /// A file could not be moved into place during the commit; the moves done were undone.
    #[error(
        "cannot move {} into place: {error}; no output was changed",
        path.display()
    )]
    Commit {
        /// The output that could not be moved.
        path: PathBuf,
        /// What the system reported.
        error: io::Error,
    },
    /// A commit failed midway and could not be undone entirely.
    #[error(
        "cannot move {} into place: {error}; undoing the other moves failed too: {}{}, every other output is as it was",
        path.display(),
        partly_note(new, removed),
        kept_note(kept)
    )]
    PartlyCommitted {
        /// The output that could not be moved.
        path: PathBuf,
        /// What the system reported.
        error: io::Error,
        /// The outputs (files, or a whole new directory) that are now this run's.
        new: Box<[PathBuf]>,
        /// An earlier run's outputs that were removed ([`OutputSet::replaces`]) and could not
        /// be put back.
        removed: Box<[PathBuf]>,
        /// Where the previous versions of new files that replaced old ones are kept (and the
        /// earlier outputs that were removed and could not be put back).
        kept: Box<[PathBuf]>,
    },
}

fn list(paths: &[PathBuf]) -> String {
    let v: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    v.join(", ")
}

fn partly_note(new: &[PathBuf], removed: &[PathBuf]) -> String {
    let mut parts = Vec::new();
    if !new.is_empty() {
        let verb = if new.len() == 1 { "is" } else { "are" };
        parts.push(format!("{} {verb} from this run", list(new)));
    }
    if !removed.is_empty() {
        let verb = if removed.len() == 1 { "was" } else { "were" };
        parts.push(format!("{} {verb} removed", list(removed)));
    }
    parts.join(" and ")
}

fn kept_note(kept: &[PathBuf]) -> String {
    if kept.is_empty() {
        String::new()
    } else {
        format!(" (the previous versions are kept as {})", list(kept))
    }
}

impl OutputError {
    fn io(path: &Path, error: io::Error) -> Self {
        OutputError::Io {
            path: path.to_path_buf(),
            error,
        }
    }
}

/// `field` as one CSV text field: the house rule for every text column (names of channels,
/// profiles, line pairs, classes, lines, failure reasons) of every CSV file lidarsim writes,
/// so that a reader never takes a name for a number:
///
/// * a non-empty text that a reader would not load as text (it parses as a number, `1064`,
///   `-2.5e3`, `inf`, `NaN`; it is a boolean, `True`, `false`; or it is one of pandas'
///   missing-value words, `NA`, `null`, `None`, `n/a`, …), and a text that starts with an
///   apostrophe, is written with one apostrophe in front (`'1064`, `'NA`, `''x`), the
///   spreadsheets' mark of text: pandas, R and a spreadsheet then read a string, whatever the
///   other rows hold (quoting alone does not do it: pandas reads `"1064"` as the integer 1064).
///   A reader gets the name back by removing one leading apostrophe ([`csv_text_value`]);
/// * then, RFC 4180: quoted, with its quotes doubled, when it holds a comma, a double quote,
///   a CR or a LF.
///
/// An empty text stays empty (a missing value). lidarsim's own labels (`mc`, `total`, `ipda`, …)
/// never need the apostrophe; scattering-order bins are ordinals (`1st`, `2nd`, `3rd+`,
/// `total`; [`crate::returns::Order::label`]), text in every run, and written as they are.
pub fn csv_field(field: &str) -> Cow<'_, str> {
    let marked: Cow<'_, str> =
        if !field.is_empty() && (field.starts_with('\'') || reads_as_non_text(field)) {
            Cow::Owned(format!("'{field}"))
        } else {
            Cow::Borrowed(field)
        };
    if marked.contains([',', '"', '\r', '\n']) {
        Cow::Owned(format!("\"{}\"", marked.replace('"', "\"\"")))
    } else {
        marked
    }
}

/// The text a field written by [`csv_field`] holds (RFC 4180 unquoting already done by the
/// CSV reader): one leading apostrophe removed.
pub fn csv_text_value(field: &str) -> &str {
    field.strip_prefix('\'').unwrap_or(field)
}

/// Whether pandas' `read_csv` (its defaults), R's `read.csv` or a spreadsheet would load
/// `field` as something other than text: a number (surrounding blanks ignored; Rust's float
/// syntax, which covers theirs: sign, decimals, exponent, `inf`, `infinity`, `nan`), a
/// boolean, or a missing value (pandas' default `na_values`).
fn reads_as_non_text(field: &str) -> bool {
    const WORDS: [&str; 24] = [
        "#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "-nan", "1.#IND", "1.#QNAN",
        "<NA>", "N/A", "NA", "NULL", "NaN", "None", "n/a", "nan", "null", "True", "TRUE", "true",
        "False", "FALSE", "false",
    ];
    let t = field.trim();
    t.is_empty() || t.parse::<f64>().is_ok() || reads_non_finite(t) || WORDS.contains(&t)
}

/// A number as a CSV field: written with the format it is given (`{}`, `{:.9e}`, `{:.6}`) when
/// it is finite, as nothing (an empty field) when it is not: the contract's "a value that
/// cannot be computed is an empty field, never `NaN` or `inf`".
pub fn csv_number(x: f64) -> CsvNumber {
    CsvNumber(x)
}

/// A number that formats as an empty field when it is not finite ([`csv_number`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsvNumber(pub f64);

impl Display for CsvNumber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_finite() {
            Display::fmt(&self.0, f)
        } else {
            Ok(())
        }
    }
}

impl std::fmt::LowerExp for CsvNumber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_finite() {
            std::fmt::LowerExp::fmt(&self.0, f)
        } else {
            Ok(())
        }
    }
}

/// Whether `field` (unquoted, surrounding blanks ignored) reads as a non-finite number to
/// Rust, pandas or a spreadsheet: `nan`, `inf` or `infinity`, any case, with an optional sign.
fn reads_non_finite(field: &str) -> bool {
    let t = field.trim();
    let t = t.strip_prefix(['+', '-']).unwrap_or(t);
    ["nan", "inf", "infinity"]
        .iter()
        .any(|w| t.eq_ignore_ascii_case(w))
}

/// The first unquoted field of the CSV text `bytes` that reads as a non-finite number: (line,
/// column, field). The column is named by the header, the first line that is not a `#`
/// comment, when it has that many fields. Quoted fields (RFC 4180) are text and are skipped.
fn non_finite_field(bytes: &[u8]) -> Option<(usize, String, String)> {
    // Most files hold neither word anywhere: no need to parse them.
    let has = |word: &[u8]| {
        bytes
            .windows(word.len())
            .any(|w| w.eq_ignore_ascii_case(word))
    };
    if !has(b"nan") && !has(b"inf") {
        return None;
    }
    // One pass over the bytes; a field is a range of them (quoted ones are text, never read
    // as numbers, and only the header's are unquoted for its names).
    let text = |f: &[u8]| {
        String::from_utf8_lossy(f)
            .trim_end_matches('\r')
            .to_string()
    };
    let unquote = |f: &[u8]| {
        text(
            f.strip_prefix(b"\"")
                .and_then(|f| f.strip_suffix(b"\""))
                .unwrap_or(f),
        )
        .replace("\"\"", "\"")
    };
    let mut header: Option<Vec<String>> = None;
    let mut fields: Vec<(usize, usize, bool)> = Vec::new();
    let (mut start, mut quoted, mut in_quotes) = (0, false, false);
    let (mut line, mut record_line) = (1usize, 1usize);
    let mut i = 0;
    while i <= bytes.len() {
        let b = bytes.get(i).copied();
        if in_quotes {
            match b {
                // A doubled quote is one quote inside the field; a single one ends it.
                Some(b'"') if bytes.get(i + 1) == Some(&b'"') => i += 1,
                Some(b'"') => in_quotes = false,
                Some(b'\n') => line += 1,
                Some(_) => {}
                // An unterminated quote: the field ends with the text.
                None => {
                    in_quotes = false;
                    continue;
                }
            }
            i += 1;
            continue;
        }
        match b {
            Some(b'"') if i == start => {
                in_quotes = true;
                quoted = true;
            }
            Some(b',') => {
                fields.push((start, i, quoted));
                (start, quoted) = (i + 1, false);
            }
            Some(b'\n') | None => {
                if b.is_some() || i > start || !fields.is_empty() {
                    fields.push((start, i, quoted));
                }
                let comment = fields
                    .first()
                    .is_some_and(|&(a, _, q)| !q && bytes.get(a) == Some(&b'#'));
                if !comment && !fields.is_empty() {
                    for (k, &(a, z, q)) in fields.iter().enumerate() {
                        let f = &bytes[a..z];
                        let f = f.strip_suffix(b"\r").unwrap_or(f);
                        if !q && f.len() <= 12 && reads_non_finite(&String::from_utf8_lossy(f)) {
                            let column = header
                                .as_ref()
                                .and_then(|h| h.get(k))
                                .map_or(format!("{}", k + 1), |name| format!("`{name}`"));
                            return Some((record_line, column, text(f)));
                        }
                    }
                    if header.is_none() {
                        header = Some(
                            fields
                                .iter()
                                .map(|&(a, z, _)| unquote(&bytes[a..z]))
                                .collect(),
                        );
                    }
                }
                fields.clear();
                (start, quoted) = (i + 1, false);
                line += 1;
                record_line = line;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// Refuse the staged CSV text `bytes` of `path` if it holds a non-finite number.
fn check_csv(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    match non_finite_field(bytes) {
        None => Ok(()),
        Some((line, column, value)) => Err(OutputError::NonFinite {
            path: path.to_path_buf(),
            line,
            column,
            value,
        }),
    }
}

fn is_csv(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
}

/// Write one file whole or not at all (an [`OutputSet`] of one file).
pub fn write_file(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> Result<(), OutputError> {
    let mut set = OutputSet::new();
    set.write(path, bytes)?;
    set.commit().map(|_| ())
}

/// Refuse, before any work, output paths that could not be written: a path that names no
/// file, a directory where a file should go, a file where a directory should be, the same path
/// twice. Commands call it first with every path they may write, so that a long run does not
/// fail at its end; the [`OutputSet`] checks the same again.
pub fn check_paths<P: AsRef<Path>>(paths: &[P]) -> Result<(), OutputError> {
    let mut seen = Vec::new();
    for p in paths {
        let path = p.as_ref();
        let (dir, name) = split(path)?;
        let key = absolute(&dir, path)?.join(&name);
        if seen.contains(&key) {
            return Err(OutputError::Twice(path.to_path_buf()));
        }
        if locate(&dir, path)?.is_none() {
            refuse_directory(&dir.join(&name), path)?;
        }
        seen.push(key);
    }
    Ok(())
}

/// The directory and file name of an output path.
fn split(path: &Path) -> Result<(PathBuf, OsString), OutputError> {
    let name = path
        .file_name()
        .ok_or_else(|| OutputError::NotAFileName(path.to_path_buf()))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((dir, name.to_os_string()))
}

fn absolute(dir: &Path, path: &Path) -> Result<PathBuf, OutputError> {
    std::path::absolute(dir).map_err(|e| OutputError::io(path, e))
}

/// `None` if `dir` is a directory; else its nearest existing ancestor, which must be one.
fn locate(dir: &Path, path: &Path) -> Result<Option<PathBuf>, OutputError> {
    let absent = |e: &io::Error| {
        matches!(
            e.kind(),
            io::ErrorKind::NotFound | io::ErrorKind::NotADirectory
        )
    };
    for (i, a) in dir.ancestors().enumerate() {
        let a = if a.as_os_str().is_empty() {
            Path::new(".")
        } else {
            a
        };
        match fs::metadata(a) {
            Ok(m) if m.is_dir() => return Ok((i > 0).then(|| a.to_path_buf())),
            Ok(_) => {
                return Err(OutputError::NotADirectory {
                    path: path.to_path_buf(),
                    dir: a.to_path_buf(),
                });
            }
            Err(e) if absent(&e) => {}
            Err(e) => return Err(OutputError::io(path, e)),
        }
    }
    Err(OutputError::io(path, io::ErrorKind::NotFound.into()))
}

/// Refuse what an output must not replace at `file`: a directory, or anything that is not a
/// regular file or a symbolic link (a pipe, socket or device; renaming the staged file over
/// `--out /dev/null` replaced the machine's /dev/null). A link is replaced, not followed.
fn refuse_directory(file: &Path, path: &Path) -> Result<(), OutputError> {
    match fs::symlink_metadata(file) {
        Ok(m) if m.is_dir() => Err(OutputError::DirectoryInTheWay(path.to_path_buf())),
        Ok(m) if !(m.is_file() || m.is_symlink()) => {
            Err(OutputError::NotARegularFile(path.to_path_buf()))
        }
        _ => Ok(()),
    }
}

/// Flush a directory's entries to disk, where the platform can (not on Windows): a rename is
/// durable only once its directory is.
fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

mod set;
pub use set::OutputSet;

#[cfg(test)]
mod tests;
