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
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

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

/// `field` as one RFC 4180 CSV field: quoted, with its quotes doubled, when it holds a comma,
/// a double quote, a CR or a LF, or reads as a non-finite number (a profile named `NaN`, which
/// the check of staged CSV files would otherwise take for one); as it is otherwise. Every text
/// field of lidarsim's CSV files goes through it (names in scenes may hold any text).
pub fn csv_field(field: &str) -> Cow<'_, str> {
    if field.contains([',', '"', '\r', '\n']) || reads_non_finite(field) {
        Cow::Owned(format!("\"{}\"", field.replace('"', "\"\"")))
    } else {
        Cow::Borrowed(field)
    }
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

/// The files of one command, staged until [`Self::commit`]; see the module documentation.
/// Dropped without a commit, it removes everything it staged.
#[derive(Debug, Default)]
pub struct OutputSet {
    /// One staging directory per target directory.
    stages: Vec<Stage>,
    /// The outputs in the order they were staged.
    order: Vec<PathBuf>,
    /// Per directory (absolute), the names of the outputs an earlier run may have left there
    /// ([`Self::replaces`]).
    owned: Vec<(PathBuf, Vec<OsString>)>,
}

/// The files staged for one target directory.
#[derive(Debug)]
struct Stage {
    /// The directory the files go to, as the caller spelled it.
    target: PathBuf,
    /// The same, absolute: one directory spelled two ways is one stage.
    key: PathBuf,
    /// The hidden staging directory: `new/` holds the staged files, `old/` the files they
    /// replace during a commit.
    dir: PathBuf,
    /// Staged file names and their outputs as the caller spelled them.
    files: Vec<(OsString, PathBuf)>,
    /// Keep the staging directory: it holds the only copy of an old file that a failed undo
    /// could not put back.
    keep: bool,
}

impl Drop for Stage {
    fn drop(&mut self) {
        if !self.keep {
            let _ = fs::remove_dir_all(&self.dir);
        }
    }
}

static NEXT_STAGE: AtomicU64 = AtomicU64::new(0);

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

impl Stage {
    /// Create the staging directory for `target` (an output `path` names it in errors).
    fn open(target: PathBuf, key: PathBuf, path: &Path) -> Result<Stage, OutputError> {
        let base = locate(&target, path)?.unwrap_or_else(|| target.clone());
        let n = NEXT_STAGE.fetch_add(1, Ordering::Relaxed);
        let dir = base.join(format!(".lidarsim-staging-{}-{n}", std::process::id()));
        fs::create_dir(&dir).map_err(|e| OutputError::io(path, e))?;
        let stage = Stage {
            target,
            key,
            dir,
            files: Vec::new(),
            keep: false,
        };
        fs::create_dir(stage.dir.join("new")).map_err(|e| OutputError::io(path, e))?;
        Ok(stage)
    }
}

/// What a commit did, in order, to undo it.
enum Step {
    /// A staged directory became the target; `created` are the parents made for it.
    Dir { stage: usize, created: Vec<PathBuf> },
    /// A staged file was moved to `dest`, over the file kept at `prior` if any.
    File {
        stage: usize,
        path: PathBuf,
        dest: PathBuf,
        prior: Prior,
    },
    /// An earlier output this set does not rewrite was moved from `dest` to `kept`.
    Removed {
        stage: usize,
        dest: PathBuf,
        kept: PathBuf,
    },
}

/// An earlier output to move out of a target directory during a commit.
struct Stale {
    /// Where it is.
    dest: PathBuf,
    /// Where it goes: the staging directory's `old/`.
    kept: PathBuf,
}

/// One file's move into an existing target directory.
struct Move {
    /// The output as the caller spelled it.
    path: PathBuf,
    /// Its staged file.
    from: PathBuf,
    /// Where it goes.
    dest: PathBuf,
    /// What it replaces.
    prior: Prior,
}

/// What a file replaced.
enum Prior {
    /// Nothing: undo removes the new file.
    Absent,
    /// An old file, kept at this path (a hard link or a copy).
    Kept(PathBuf),
    /// An old file that could not be kept: the move cannot be undone.
    Lost,
}

impl OutputSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Have the commit remove from `dir`, if it exists, every file named in `names` that this
    /// set does not write into it: the outputs of an earlier run that this one did not rewrite
    /// (a `retrieval.csv` of a scene with a retrieval, where this one has none), which would
    /// otherwise stay beside the new ones with nothing to say they are stale. Only those names
    /// are touched (a command gives the names of every file it may write there); a directory
    /// of such a name is left alone. The removal is part of the commit: the files are moved
    /// into the staging directory and come back if the commit fails.
    pub fn replaces(&mut self, dir: impl AsRef<Path>, names: &[&str]) -> Result<(), OutputError> {
        let dir = dir.as_ref();
        let key = absolute(dir, dir)?;
        let names = names.iter().map(OsString::from);
        match self.owned.iter_mut().find(|(k, _)| *k == key) {
            Some((_, v)) => v.extend(names),
            None => self.owned.push((key, names.collect())),
        }
        Ok(())
    }

    /// Stage `bytes` as the file `path`.
    pub fn write(
        &mut self,
        path: impl AsRef<Path>,
        bytes: impl AsRef<[u8]>,
    ) -> Result<(), OutputError> {
        let (path, bytes) = (path.as_ref(), bytes.as_ref());
        // A CSV file is checked here, in memory, rather than read back once staged.
        if is_csv(path) {
            check_csv(path, bytes)?;
        }
        self.stage(path, false, |staged| {
            let mut f = File::create(staged).map_err(|e| OutputError::io(path, e))?;
            f.write_all(bytes).map_err(|e| OutputError::io(path, e))?;
            f.sync_all().map_err(|e| OutputError::io(path, e))
        })
    }

    /// Stage the file `path`, written by `write` into the file it is given.
    pub fn write_with(
        &mut self,
        path: impl AsRef<Path>,
        write: impl FnOnce(&mut File) -> io::Result<()>,
    ) -> Result<(), OutputError> {
        let path = path.as_ref();
        self.stage(path, true, |staged| {
            let mut f = File::create(staged).map_err(|e| OutputError::io(path, e))?;
            write(&mut f).map_err(|e| OutputError::io(path, e))?;
            f.sync_all().map_err(|e| OutputError::io(path, e))
        })
    }

    /// Stage the file `path`, written by `produce` to the path it is given (which keeps the
    /// output's extension: plotting backends choose the format by it).
    pub fn write_via<E: Display>(
        &mut self,
        path: impl AsRef<Path>,
        produce: impl FnOnce(&Path) -> Result<(), E>,
    ) -> Result<(), OutputError> {
        let path = path.as_ref();
        self.stage(path, true, |staged| {
            produce(staged).map_err(|e| OutputError::Produce {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
            let f = File::open(staged).map_err(|e| OutputError::io(path, e))?;
            f.sync_all().map_err(|e| OutputError::io(path, e))
        })
    }

    /// Check `path`, have `write` write its staged file, and record it. With
    /// `check_csv_file`, a CSV file is read back and checked (module documentation).
    fn stage(
        &mut self,
        path: &Path,
        check_csv_file: bool,
        write: impl FnOnce(&Path) -> Result<(), OutputError>,
    ) -> Result<(), OutputError> {
        let (target, name) = split(path)?;
        let key = absolute(&target, path)?;
        let i = match self.stages.iter().position(|s| s.key == key) {
            Some(i) => i,
            None => {
                let s = Stage::open(target.clone(), key, path)?;
                self.stages.push(s);
                self.stages.len() - 1
            }
        };
        let stage = &mut self.stages[i];
        if stage.files.iter().any(|(n, _)| *n == name) {
            return Err(OutputError::Twice(path.to_path_buf()));
        }
        refuse_directory(&target.join(&name), path)?;
        let staged = stage.dir.join("new").join(&name);
        // However it was written, a CSV file is checked (module documentation).
        let checked = write(&staged).and_then(|()| {
            if check_csv_file && is_csv(path) {
                let bytes = fs::read(&staged).map_err(|e| OutputError::io(path, e))?;
                check_csv(path, &bytes)?;
            }
            Ok(())
        });
        if let Err(e) = checked {
            // The set may still be committed: a failed file must not be part of it.
            let _ = fs::remove_file(&staged);
            return Err(e);
        }
        stage.files.push((name, path.to_path_buf()));
        self.order.push(path.to_path_buf());
        Ok(())
    }

    /// Move every staged file into place (see the module documentation for the guarantee);
    /// returns the outputs in the order they were staged.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, OutputError> {
        self.commit_with(&mut |from, to| fs::rename(from, to))?;
        Ok(std::mem::take(&mut self.order))
    }

    /// [`Self::commit`] with the rename it uses given, so that tests can make it fail.
    fn commit_with(
        &mut self,
        rename: &mut dyn FnMut(&Path, &Path) -> io::Result<()>,
    ) -> Result<(), OutputError> {
        // Parents first: a new directory must exist before a directory inside it moves in.
        self.stages.sort_by_key(|s| s.key.components().count());
        for s in &self.stages {
            sync_dir(&s.dir.join("new"));
        }
        // Every check and every copy of an old file before the first rename.
        let mut plan = Vec::new();
        let mut stale = Vec::new();
        for s in &self.stages {
            let p = Self::prepare(s)?;
            let owned = self.owned.iter().find(|(k, _)| *k == s.key);
            stale.push(match (&p, owned) {
                (Some(_), Some((_, names))) => Self::stale(s, names)?,
                _ => Vec::new(),
            });
            plan.push(p);
        }
        let mut done: Vec<Step> = Vec::new();
        for (i, p) in plan.into_iter().enumerate() {
            match p {
                None => {
                    let target = self.stages[i].target.clone();
                    let created = missing_parents(&target);
                    let r = created
                        .iter()
                        .rev()
                        .try_for_each(fs::create_dir)
                        .and_then(|()| rename(&self.stages[i].dir.join("new"), &target));
                    if let Err(e) = r {
                        remove_created(&created);
                        return Err(self.undo(done, &target, e, rename));
                    }
                    done.push(Step::Dir { stage: i, created });
                }
                Some(moves) => {
                    for m in moves {
                        if let Err(e) = rename(&m.from, &m.dest) {
                            return Err(self.undo(done, &m.path, e, rename));
                        }
                        done.push(Step::File {
                            stage: i,
                            path: m.path,
                            dest: m.dest,
                            prior: m.prior,
                        });
                    }
                }
            }
        }
        // The earlier outputs not rewritten, once every new file is in place.
        for (i, files) in stale.into_iter().enumerate() {
            for f in files {
                if let Err(e) = rename(&f.dest, &f.kept) {
                    return Err(self.undo(done, &f.dest, e, rename));
                }
                done.push(Step::Removed {
                    stage: i,
                    dest: f.dest,
                    kept: f.kept,
                });
            }
        }
        for s in &self.stages {
            sync_dir(&s.target);
            if let Some(parent) = s.target.parent() {
                sync_dir(parent);
            }
        }
        Ok(())
    }

    /// The files of `names` in the existing target of `s` that `s` does not write: an earlier
    /// run's outputs, to be moved into the staging directory's `old/`.
    fn stale(s: &Stage, names: &[OsString]) -> Result<Vec<Stale>, OutputError> {
        let old = s.dir.join("old");
        let mut out = Vec::new();
        for name in names {
            if s.files.iter().any(|(n, _)| n == name)
                || out.iter().any(|f: &Stale| f.kept.file_name() == Some(name))
            {
                continue;
            }
            let dest = s.target.join(name);
            match fs::symlink_metadata(&dest) {
                // Only a file (or a link) an earlier run may have left; never a pipe or device.
                Ok(m) if m.is_file() || m.is_symlink() => {
                    if !old.exists() {
                        fs::create_dir(&old).map_err(|e| OutputError::io(&dest, e))?;
                    }
                    out.push(Stale {
                        dest,
                        kept: old.join(name),
                    });
                }
                _ => {}
            }
        }
        Ok(out)
    }

    /// For a target that does not exist: `None` (the staging directory will be renamed to it).
    /// For one that exists: the move of each file, the old files kept in the staging
    /// directory's `old/`.
    fn prepare(s: &Stage) -> Result<Option<Vec<Move>>, OutputError> {
        let first = s.files.first().map_or(&s.target, |(_, p)| p);
        match fs::metadata(&s.target) {
            Ok(m) if m.is_dir() => {}
            Ok(_) => {
                return Err(OutputError::NotADirectory {
                    path: first.clone(),
                    dir: s.target.clone(),
                });
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(OutputError::io(first, e)),
        }
        let old = s.dir.join("old");
        let mut files = Vec::new();
        for (name, path) in &s.files {
            let dest = s.target.join(name);
            let prior = match fs::symlink_metadata(&dest) {
                Ok(m) if m.is_dir() => return Err(OutputError::DirectoryInTheWay(path.clone())),
                Ok(m) if !(m.is_file() || m.is_symlink()) => {
                    return Err(OutputError::NotARegularFile(path.clone()));
                }
                Ok(_) => {
                    if !old.exists() {
                        fs::create_dir(&old).map_err(|e| OutputError::io(path, e))?;
                    }
                    let keep = old.join(name);
                    // A hard link costs nothing; a copy serves filesystems without links.
                    match fs::hard_link(&dest, &keep).or_else(|_| fs::copy(&dest, &keep).map(drop))
                    {
                        Ok(()) => Prior::Kept(keep),
                        Err(_) => Prior::Lost,
                    }
                }
                Err(_) => Prior::Absent,
            };
            files.push(Move {
                path: path.clone(),
                from: s.dir.join("new").join(name),
                dest,
                prior,
            });
        }
        Ok(Some(files))
    }

    /// Undo the steps `done` after moving `path` failed with `error`; the error to report.
    fn undo(
        &mut self,
        done: Vec<Step>,
        path: &Path,
        error: io::Error,
        rename: &mut dyn FnMut(&Path, &Path) -> io::Result<()>,
    ) -> OutputError {
        let mut new = Vec::new();
        let mut kept = Vec::new();
        let mut removed = Vec::new();
        for step in done.into_iter().rev() {
            match step {
                Step::Dir { stage, created } => {
                    let s = &self.stages[stage];
                    if rename(&s.target, &s.dir.join("new")).is_ok() {
                        remove_created(&created);
                    } else {
                        new.push(s.target.clone());
                    }
                }
                Step::Removed {
                    stage,
                    dest,
                    kept: k,
                } => {
                    if rename(&k, &dest).is_err() {
                        self.stages[stage].keep = true;
                        kept.push(k);
                        removed.push(dest);
                    }
                }
                Step::File {
                    stage,
                    path,
                    dest,
                    prior,
                } => {
                    let ok = match &prior {
                        Prior::Absent => fs::remove_file(&dest).is_ok(),
                        Prior::Kept(k) => rename(k, &dest).is_ok(),
                        Prior::Lost => false,
                    };
                    if !ok {
                        if let Prior::Kept(k) = prior {
                            self.stages[stage].keep = true;
                            kept.push(k);
                        }
                        new.push(path);
                    }
                }
            }
        }
        if new.is_empty() && removed.is_empty() {
            OutputError::Commit {
                path: path.to_path_buf(),
                error,
            }
        } else {
            new.reverse();
            removed.reverse();
            OutputError::PartlyCommitted {
                path: path.to_path_buf(),
                error,
                new: new.into(),
                removed: removed.into(),
                kept: kept.into(),
            }
        }
    }
}

/// The parents of `dir` that do not exist, innermost first.
fn missing_parents(dir: &Path) -> Vec<PathBuf> {
    dir.ancestors()
        .skip(1)
        .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
        .map(Path::to_path_buf)
        .collect()
}

/// Remove the parents made for a new directory (innermost first), if they are empty.
fn remove_created(created: &[PathBuf]) {
    for d in created {
        let _ = fs::remove_dir(d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every entry under `dir`, recursively, with the contents of files: what a test compares
    /// before and after.
    fn snapshot(dir: &Path) -> Vec<(PathBuf, Option<Vec<u8>>)> {
        let mut out = Vec::new();
        let mut todo = vec![dir.to_path_buf()];
        while let Some(d) = todo.pop() {
            for e in fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    todo.push(p.clone());
                    out.push((p, None));
                } else {
                    out.push((p.clone(), Some(fs::read(&p).unwrap())));
                }
            }
        }
        out.sort();
        out
    }

    fn hidden(dir: &Path) -> Vec<PathBuf> {
        snapshot(dir)
            .into_iter()
            .map(|(p, _)| p)
            .filter(|p| p.to_string_lossy().contains(".lidarsim-staging"))
            .collect()
    }

    /// A target directory holding an earlier run's two outputs and a file of the user's.
    fn earlier_run(root: &Path) -> PathBuf {
        earlier_run_in(&root.join("out"))
    }

    fn earlier_run_in(out: &Path) -> PathBuf {
        let out = out.to_path_buf();
        fs::create_dir_all(&out).unwrap();
        fs::write(out.join("a.csv"), "old a\n").unwrap();
        fs::write(out.join("b.csv"), "old b\n").unwrap();
        fs::write(out.join("notes.txt"), "mine\n").unwrap();
        out
    }

    /// Staged CSV files never hold a non-finite number: `csv_number` writes an empty field, and
    /// a file with `NaN` or `inf` in an unquoted field is refused, naming line and column;
    /// text that reads so is quoted by `csv_field`, and quoted fields are text.
    #[test]
    fn csv_files_with_non_finite_numbers_are_refused() {
        assert_eq!(format!("{}", csv_number(0.25)), "0.25");
        assert_eq!(format!("{:.3e}", csv_number(1234.5)), "1.234e3");
        assert_eq!(format!("{:.2}", csv_number(-1.0 / 3.0)), "-0.33");
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(
                format!(
                    "{}|{:.9e}|{:.4}",
                    csv_number(x),
                    csv_number(x),
                    csv_number(x)
                ),
                "||"
            );
        }
        for text in ["NaN", "nan", "-inf", "+Infinity", " inf"] {
            assert!(reads_non_finite(text), "{text}");
            assert_eq!(csv_field(text), format!("\"{text}\""));
        }
        for text in ["info", "nano", "in", "1e308", ""] {
            assert!(!reads_non_finite(text), "{text}");
        }
        let ok = "# a comment, with nan\nname,x\n\"NaN\",1\n\"two\nlines, inf\",2\ninfo,3\n\"say \"\"inf\"\",\",4\n";
        assert_eq!(non_finite_field(ok.as_bytes()), None);
        let bad = "name,x,y\r\n\"a\nb\",1,2\r\nc,-inf,3\r\n";
        assert_eq!(
            non_finite_field(bad.as_bytes()),
            Some((4, "`x`".into(), "-inf".into()))
        );
        // A row wider than the header: its column by number.
        assert_eq!(
            non_finite_field(b"a\n3,NaN"),
            Some((2, "2".into(), "NaN".into()))
        );
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        let before = snapshot(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        let e = set.write(out.join("b.csv"), bad).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "cannot write {}: line 4, column `x` is `-inf`: a value that cannot be computed must be an empty field (a bug in lidarsim; please report it)",
                out.join("b.csv").display()
            )
        );
        // However the file is written.
        let e = set
            .write_via(out.join("c.csv"), |p| fs::write(p, "x\nNaN\n"))
            .unwrap_err();
        assert!(matches!(e, OutputError::NonFinite { line: 2, .. }), "{e}");
        drop(set);
        assert_eq!(snapshot(root.path()), before);
        // Other files are not CSV.
        let mut set = OutputSet::new();
        set.write(out.join("notes.json"), "{\"x\": NaN}").unwrap();
    }

    #[test]
    fn csv_field_quotes_only_what_needs_it() {
        assert_eq!(csv_field("on-line 1"), "on-line 1");
        assert_eq!(csv_field(""), "");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
        assert_eq!(csv_field("cr\r"), "\"cr\r\"");
    }

    #[test]
    fn a_new_directory_appears_with_all_its_files() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("deep/new/out");
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "a\n").unwrap();
        set.write_via(out.join("b.png"), |p| fs::write(p, "png"))
            .unwrap();
        assert!(
            !root.path().join("deep").exists(),
            "nothing before the commit"
        );
        let paths = set.commit().unwrap();
        assert_eq!(paths, [out.join("a.csv"), out.join("b.png")]);
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "a\n");
        assert_eq!(fs::read_to_string(out.join("b.png")).unwrap(), "png");
        assert_eq!(fs::read_dir(&out).unwrap().count(), 2);
        assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
    }

    #[test]
    fn a_commit_replaces_an_earlier_runs_files_and_keeps_the_others() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        set.write(out.join("c.csv"), "new c\n").unwrap();
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "old a\n");
        set.commit().unwrap();
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
        assert_eq!(fs::read_to_string(out.join("b.csv")).unwrap(), "old b\n");
        assert_eq!(fs::read_to_string(out.join("c.csv")).unwrap(), "new c\n");
        assert_eq!(fs::read_to_string(out.join("notes.txt")).unwrap(), "mine\n");
        assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
    }

    #[test]
    fn a_failed_file_leaves_everything_as_it_was() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        let before = snapshot(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        // A plotting backend that fails after writing part of its file.
        let e = set
            .write_via(out.join("b.png"), |p| {
                fs::write(p, "half").unwrap();
                Err("out of fonts")
            })
            .unwrap_err();
        assert!(matches!(e, OutputError::Produce { .. }), "{e}");
        assert!(e.to_string().contains("b.png") && e.to_string().contains("out of fonts"));
        drop(set);
        assert_eq!(snapshot(root.path()), before);
    }

    #[test]
    fn a_full_disk_leaves_everything_as_it_was() {
        for fresh in [false, true] {
            let root = tempfile::tempdir().unwrap();
            let out = if fresh {
                root.path().join("new")
            } else {
                earlier_run(root.path())
            };
            let before = snapshot(root.path());
            let mut set = OutputSet::new();
            set.write(out.join("a.csv"), "new a\n").unwrap();
            // What a full disk does to a writer: part of the bytes, then ENOSPC.
            let e = set
                .write_with(out.join("b.csv"), |f| {
                    f.write_all(b"new b, first half")?;
                    Err(io::Error::from(io::ErrorKind::StorageFull))
                })
                .unwrap_err();
            match &e {
                OutputError::Io { path, error } => {
                    assert_eq!(path, &out.join("b.csv"));
                    assert_eq!(error.kind(), io::ErrorKind::StorageFull);
                }
                other => panic!("{other}"),
            }
            drop(set);
            assert_eq!(snapshot(root.path()), before);
        }
    }

    #[test]
    fn a_failed_file_is_not_committed() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("out");
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "a").unwrap();
        assert!(set.write_via(out.join("b.png"), |_| Err("no")).is_err());
        set.commit().unwrap();
        assert_eq!(fs::read_dir(&out).unwrap().count(), 1);
        assert!(out.join("a.csv").is_file());
    }

    #[test]
    fn a_directory_named_like_an_output_is_refused_before_writing() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        fs::create_dir(out.join("d.csv")).unwrap();
        let before = snapshot(root.path());
        let e = check_paths(&[out.join("a.csv"), out.join("d.csv")]).unwrap_err();
        assert!(matches!(&e, OutputError::DirectoryInTheWay(p) if p == &out.join("d.csv")));
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        let mut called = false;
        let e = set
            .write_with(out.join("d.csv"), |_| {
                called = true;
                Ok(())
            })
            .unwrap_err();
        assert!(!called, "nothing is written for a blocked name");
        assert_eq!(
            e.to_string(),
            format!(
                "cannot write {}: a directory of that name is in the way",
                out.join("d.csv").display()
            )
        );
        drop(set);
        assert_eq!(snapshot(root.path()), before);
    }

    #[test]
    fn a_directory_that_appears_before_the_commit_is_refused_by_it() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        set.write(out.join("c.csv"), "new c\n").unwrap();
        fs::create_dir(out.join("c.csv")).unwrap();
        let before: Vec<_> = snapshot(root.path())
            .into_iter()
            .filter(|(p, _)| !p.to_string_lossy().contains(".lidarsim-staging"))
            .collect();
        let e = set.commit().unwrap_err();
        assert!(matches!(&e, OutputError::DirectoryInTheWay(p) if p == &out.join("c.csv")));
        assert_eq!(snapshot(root.path()), before);
    }

    #[test]
    fn paths_that_cannot_be_files_are_refused() {
        let root = tempfile::tempdir().unwrap();
        let file = root.path().join("file");
        fs::write(&file, "x").unwrap();
        let e = check_paths(&[file.join("sub/a.csv")]).unwrap_err();
        assert!(
            matches!(&e, OutputError::NotADirectory { dir, .. } if dir == &file),
            "{e}"
        );
        let mut set = OutputSet::new();
        assert!(matches!(
            set.write(file.join("a.csv"), "a"),
            Err(OutputError::NotADirectory { .. })
        ));
        assert!(matches!(
            check_paths(&[Path::new("..")]),
            Err(OutputError::NotAFileName(_))
        ));
        let a = root.path().join("out/a.csv");
        let again = root.path().join("out/./a.csv");
        assert!(matches!(
            check_paths(&[&a, &again]),
            Err(OutputError::Twice(_))
        ));
        set.write(&a, "a").unwrap();
        assert!(matches!(set.write(&again, "b"), Err(OutputError::Twice(_))));
        drop(set);
        assert_eq!(fs::read_dir(root.path()).unwrap().count(), 1);
    }

    /// A named pipe where an output goes is refused before writing and at the commit, and is
    /// left as it was: a whole-or-nothing write would replace it by a regular file (fuzz
    /// finding F12: `--out /dev/null` replaced the machine's /dev/null).
    #[cfg(unix)]
    #[test]
    fn a_pipe_or_device_is_never_replaced() {
        use std::os::unix::fs::FileTypeExt;
        let root = tempfile::tempdir().unwrap();
        let fifo = root.path().join("a.csv");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if !made.is_ok_and(|s| s.success()) {
            println!("skipped: mkfifo is not available");
            return;
        }
        assert!(matches!(
            check_paths(&[&fifo]),
            Err(OutputError::NotARegularFile(_))
        ));
        let mut set = OutputSet::new();
        assert!(matches!(
            set.write(&fifo, "a\n"),
            Err(OutputError::NotARegularFile(_))
        ));
        // A pipe that appears between staging and the commit.
        let late = root.path().join("c.csv");
        set.write(&late, "c\n").unwrap();
        std::process::Command::new("mkfifo")
            .arg(&late)
            .status()
            .unwrap();
        assert!(matches!(set.commit(), Err(OutputError::NotARegularFile(_))));
        for p in [&fifo, &late] {
            assert!(fs::symlink_metadata(p).unwrap().file_type().is_fifo());
        }
        fs::remove_file(&late).unwrap();
        // And an earlier run's name held by a pipe is not removed as stale.
        let mut set = OutputSet::new();
        set.replaces(root.path(), &["a.csv"]).unwrap();
        set.write(root.path().join("b.csv"), "b\n").unwrap();
        set.commit().unwrap();
        assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        // /dev/null itself, where it exists, is refused before any work.
        if Path::new("/dev/null").exists() {
            assert!(matches!(
                check_paths(&[Path::new("/dev/null")]),
                Err(OutputError::NotARegularFile(_))
            ));
        }
    }

    #[test]
    fn a_rename_that_fails_midway_is_undone() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        let before = snapshot(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("c.csv"), "new c\n").unwrap();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        set.write(out.join("b.csv"), "new b\n").unwrap();
        let mut n = 0;
        let e = set
            .commit_with(&mut |from, to| {
                n += 1;
                if n == 3 {
                    return Err(io::ErrorKind::StorageFull.into());
                }
                fs::rename(from, to)
            })
            .unwrap_err();
        assert!(matches!(&e, OutputError::Commit { path, .. } if path == &out.join("b.csv")));
        assert!(e.to_string().ends_with("no output was changed"), "{e}");
        drop(set);
        assert_eq!(snapshot(root.path()), before);
    }

    #[test]
    fn a_new_directory_is_taken_back_when_a_later_one_fails() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run_in(&root.path().join("runs/2026/out"));
        // Shallower, so committed first; its parent `new` is made for it.
        let fresh = root.path().join("new/figures");
        let before = snapshot(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        set.write(fresh.join("f.png"), "png").unwrap();
        let mut moved_fresh = false;
        let e = set
            .commit_with(&mut |from, to| {
                if to.starts_with(&out) {
                    return Err(io::ErrorKind::PermissionDenied.into());
                }
                moved_fresh |= to == fresh;
                fs::rename(from, to)
            })
            .unwrap_err();
        assert!(
            moved_fresh,
            "the new directory was moved before the failure"
        );
        assert!(matches!(e, OutputError::Commit { .. }), "{e}");
        drop(set);
        assert_eq!(snapshot(root.path()), before);
    }

    #[test]
    fn an_undo_that_fails_names_the_new_files_and_keeps_the_old_ones() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        set.write(out.join("b.csv"), "new b\n").unwrap();
        let mut n = 0;
        // The second move fails, and so does putting the old a.csv back.
        let e = set
            .commit_with(&mut |from, to| {
                n += 1;
                if n >= 2 {
                    return Err(io::ErrorKind::StorageFull.into());
                }
                fs::rename(from, to)
            })
            .unwrap_err();
        let OutputError::PartlyCommitted {
            path, new, kept, ..
        } = &e
        else {
            panic!("{e}");
        };
        assert_eq!(path, &out.join("b.csv"));
        assert_eq!(&**new, &[out.join("a.csv")]);
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
        assert_eq!(fs::read_to_string(out.join("b.csv")).unwrap(), "old b\n");
        let msg = e.to_string();
        assert!(msg.contains(&format!("{} is from this run", out.join("a.csv").display())));
        drop(set);
        // The only copy of the old a.csv is not deleted.
        assert_eq!(fs::read_to_string(&kept[0]).unwrap(), "old a\n");
    }

    /// An earlier run's outputs that this set does not rewrite are removed by the commit; files
    /// of other names (the user's), and a directory of an output's name, are left alone.
    #[test]
    fn a_commit_removes_the_earlier_outputs_it_does_not_rewrite() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        fs::create_dir(out.join("d.png")).unwrap();
        let mut set = OutputSet::new();
        set.replaces(&out, &["a.csv", "b.csv", "c.csv", "d.png"])
            .unwrap();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        assert_eq!(fs::read_to_string(out.join("b.csv")).unwrap(), "old b\n");
        set.commit().unwrap();
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
        assert!(!out.join("b.csv").exists(), "the stale b.csv is gone");
        assert_eq!(fs::read_to_string(out.join("notes.txt")).unwrap(), "mine\n");
        assert!(out.join("d.png").is_dir());
        assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
        // Into a new directory there is nothing to remove.
        let fresh = root.path().join("fresh");
        let mut set = OutputSet::new();
        set.replaces(&fresh, &["a.csv", "b.csv"]).unwrap();
        set.write(fresh.join("a.csv"), "a").unwrap();
        set.commit().unwrap();
        assert_eq!(fs::read_dir(&fresh).unwrap().count(), 1);
    }

    /// A commit that fails after a stale file went (the removal of the next fails) puts it
    /// back, and the new files go: nothing changed.
    #[test]
    fn a_failed_commit_puts_the_stale_outputs_back() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        fs::write(out.join("c.csv"), "old c\n").unwrap();
        let fresh = root.path().join("fresh");
        let before = snapshot(root.path());
        let mut set = OutputSet::new();
        set.replaces(&out, &["a.csv", "b.csv", "c.csv"]).unwrap();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        set.write(fresh.join("f.csv"), "f\n").unwrap();
        let mut removed_b = false;
        let e = set
            .commit_with(&mut |from, to| {
                if from == out.join("c.csv") {
                    assert!(removed_b, "b.csv went first");
                    return Err(io::ErrorKind::StorageFull.into());
                }
                removed_b |= from == out.join("b.csv");
                fs::rename(from, to)
            })
            .unwrap_err();
        assert!(
            matches!(&e, OutputError::Commit { path, .. } if path == &out.join("c.csv")),
            "{e}"
        );
        drop(set);
        assert_eq!(snapshot(root.path()), before);
    }

    /// If a stale file cannot be put back, the error says it was removed and where it is kept.
    #[test]
    fn a_stale_output_that_cannot_be_put_back_is_named() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        fs::write(out.join("c.csv"), "old c\n").unwrap();
        let mut set = OutputSet::new();
        set.replaces(&out, &["a.csv", "b.csv", "c.csv"]).unwrap();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        let e = set
            .commit_with(&mut |from, to| {
                if from == out.join("c.csv") || to == out.join("b.csv") {
                    return Err(io::ErrorKind::StorageFull.into());
                }
                fs::rename(from, to)
            })
            .unwrap_err();
        let OutputError::PartlyCommitted {
            new, removed, kept, ..
        } = &e
        else {
            panic!("{e}");
        };
        assert!(new.is_empty(), "a.csv was put back: {new:?}");
        assert_eq!(&**removed, &[out.join("b.csv")]);
        assert!(
            e.to_string().contains(&format!(
                "{} was removed (the previous versions are kept as {})",
                out.join("b.csv").display(),
                kept[0].display()
            )),
            "{e}"
        );
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "old a\n");
        assert_eq!(fs::read_to_string(out.join("c.csv")).unwrap(), "old c\n");
        drop(set);
        assert_eq!(fs::read_to_string(&kept[0]).unwrap(), "old b\n");
    }

    #[test]
    fn write_file_replaces_one_file() {
        let root = tempfile::tempdir().unwrap();
        let out = earlier_run(root.path());
        write_file(out.join("a.csv"), b"new a\n").unwrap();
        assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
        assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
    }
}
