//! [`OutputSet`]: the files of one command, staged in hidden directories beside their targets
//! and committed together by renames, or none of them (the module documentation of
//! [`crate::output`]).

use std::ffi::OsString;
use std::fmt::Display;
use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::*;

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
    pub(super) fn commit_with(
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
