//! What every kind of shard shares when read as a set: its kind, the set's wholeness, the
//! scene its shards claim.

use super::*;

/// A shard file as the checks of a set see it: where it was read from, the lidarsim version
/// that wrote it, and which shard it is.
pub(crate) trait Sharded {
    /// The file.
    fn path(&self) -> &Path;
    /// The lidarsim version that wrote it.
    fn version(&self) -> &str;
    /// Which shard of how many.
    fn spec(&self) -> ShardSpec;
}

impl Sharded for (PathBuf, ShardHeader) {
    fn path(&self) -> &Path {
        &self.0
    }

    fn version(&self) -> &str {
        &self.1.lidarsim_version
    }

    fn spec(&self) -> ShardSpec {
        self.1.spec()
    }
}

/// Every shard of one run or study, in shard order: each of `paths` read by `read` and
/// refused if another lidarsim version wrote it or if `same` finds that it differs from the
/// first (naming both files); then the set refused if a shard is given twice or is missing.
pub(crate) fn whole_set<F: Sharded>(
    paths: &[PathBuf],
    read: impl Fn(&Path) -> Result<F, ShardError>,
    same: impl Fn(&F, &F) -> Result<(), ShardError>,
) -> Result<Vec<F>, ShardError> {
    let mut files: Vec<F> = Vec::with_capacity(paths.len());
    for p in paths {
        let f = read(p)?;
        if f.version() != VERSION {
            return Err(ShardError::Bad {
                path: p.clone(),
                what: format!(
                    "written by lidarsim {}; this is lidarsim {VERSION} (shard format {FORMAT}), whose numbers may differ",
                    f.version()
                ),
            });
        }
        if let Some(first) = files.first() {
            same(first, &f)?;
        }
        files.push(f);
    }
    files.sort_by_key(|f| f.spec().index);
    for w in files.windows(2) {
        if w[0].spec().index == w[1].spec().index {
            return Err(ShardError::Duplicate {
                spec: w[0].spec(),
                a: w[0].path().to_path_buf(),
                b: w[1].path().to_path_buf(),
            });
        }
    }
    let Some(first) = files.first() else {
        return Err(ShardError::NoShards(paths.to_vec()));
    };
    let count = first.spec().count;
    if files.len() != count {
        // In shard order, each once.
        let have: Vec<usize> = files.iter().map(|f| f.spec().index).collect();
        return Err(ShardError::Missing {
            count,
            missing: (0..count)
                .filter(|i| have.binary_search(i).is_err())
                .collect(),
            files: files.iter().map(|f| f.path().to_path_buf()).collect(),
        });
    }
    Ok(files)
}

/// What one shard says of its scene: the shard file, and its header's scene path, text and
/// digest.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SceneClaim<'a> {
    /// The shard file.
    pub(crate) file: &'a Path,
    /// The scene's path as the shard recorded it.
    pub(crate) path: &'a str,
    /// The scene's text stored in the shard.
    pub(crate) text: &'a str,
    /// The digest of the scene as the shard ran it.
    pub(crate) digest: &'a str,
}

/// The scene a set of shards ran, read again from the text every shard stores (each distinct
/// text once), made ready by `prepare` (a run shard's photons and seed) and refused unless its
/// digest (by `digest`) is the one that shard recorded; the shards' headers have been found to
/// agree on the path and the digest ([`whole_set`]).
///
/// A text that does not parse, or whose digest is not its shard's while another shard's text
/// differs from it, was damaged in that shard: the error names the shard file. When every
/// shard holds the same text and its digest is not theirs, a file the scene reads has changed
/// since (or the text was changed in every shard alike): [`ShardError::SceneChanged`], naming
/// the shards.
pub(crate) fn scene_of(
    claims: &[SceneClaim],
    prepare: impl Fn(&mut Scene) -> Result<(), String>,
    digest: impl Fn(&Scene) -> String,
) -> Result<Scene, ShardError> {
    let Some(first) = claims.first() else {
        return Err(ShardError::NoShards(Vec::new()));
    };
    let all_alike = claims.iter().all(|c| c.text == first.text);
    let bad = |c: &SceneClaim, what: String| ShardError::Bad {
        path: c.file.to_path_buf(),
        what,
    };
    let mut scene: Option<Scene> = None;
    let mut seen = std::collections::HashSet::new();
    for c in claims {
        if !seen.insert(c.text) {
            continue;
        }
        let mut s = Scene::from_toml(Path::new(c.path), c.text).map_err(|e| {
            if e.path == Path::new(c.path) {
                bad(c, format!("its scene text does not parse: {e}"))
            } else {
                bad(c, format!("its scene cannot be built again: {e}"))
            }
        })?;
        prepare(&mut s).map_err(|what| bad(c, what))?;
        let now = digest(&s);
        if now != c.digest {
            if !all_alike {
                return Err(bad(
                    c,
                    format!(
                        "its scene text does not match its digest (digest {now} of the text, {} recorded): the text has been changed since the shard was written",
                        c.digest
                    ),
                ));
            }
            return Err(ShardError::SceneChanged {
                path: c.path.to_string(),
                shards: claims.iter().map(|c| c.file.to_path_buf()).collect(),
                now,
                recorded: c.digest.to_string(),
            });
        }
        scene.get_or_insert(s);
    }
    // Every distinct text has its shard's digest, and the digests agree, so the texts do
    // (the digest holds the text): unless two texts collide in FNV-1a.
    if let Some(c) = claims.iter().find(|c| c.text != first.text) {
        return Err(bad(
            c,
            format!(
                "its scene text differs from that of {} under the same digest",
                first.file.display()
            ),
        ));
    }
    scene.ok_or_else(|| ShardError::NoShards(Vec::new()))
}

/// The `kind` of a shard header (JSON): [`KIND_RUN`] when it names none or cannot be read.
pub(super) fn header_kind(json: &[u8]) -> String {
    serde_json::from_slice::<serde_json::Value>(json)
        .ok()
        .and_then(|v| v.get("kind").and_then(|k| k.as_str()).map(String::from))
        .unwrap_or_else(run_kind)
}

/// The kind of the shard file `path` ([`KIND_RUN`], [`KIND_DIAL`] or [`KIND_SELECT`]), from its
/// header only.
pub fn shard_kind(path: &Path) -> Result<String, ShardError> {
    use std::io::Read;
    let io_err = |error| ShardError::Io {
        path: path.to_path_buf(),
        error,
    };
    let bad = |what: String| ShardError::Bad {
        path: path.to_path_buf(),
        what,
    };
    let mut f = fs::File::open(path).map_err(io_err)?;
    let mut pre = [0u8; PREAMBLE_BYTES];
    let mut got = 0;
    while got < PREAMBLE_BYTES {
        match f.read(&mut pre[got..]).map_err(io_err)? {
            0 => break,
            n => got += n,
        }
    }
    if got < MAGIC.len() || &pre[..MAGIC.len()] != MAGIC {
        return Err(bad(
            "not a lidarsim shard file (no `lidarsim shard` magic at its start)".into(),
        ));
    }
    if got < PREAMBLE_BYTES {
        return Err(bad(format!(
            "truncated: {got} bytes, too short for a shard file"
        )));
    }
    let len = u64_at(&pre, 20);
    let size = f.metadata().map_err(io_err)?.len();
    if len > MAX_HEADER_BYTES || len > size.saturating_sub(PREAMBLE_BYTES as u64) {
        return Err(bad(format!(
            "truncated or corrupt: a header of {len} bytes in a file of {size} bytes"
        )));
    }
    let mut json = vec![0u8; len as usize];
    f.read_exact(&mut json).map_err(io_err)?;
    Ok(header_kind(&json))
}

/// The one kind of every shard file in `paths`; shards of different kinds are refused, naming
/// a file of each.
pub fn common_kind(paths: &[PathBuf]) -> Result<String, ShardError> {
    let mut first: Option<(&PathBuf, String)> = None;
    for p in paths {
        let k = shard_kind(p)?;
        match &first {
            None => first = Some((p, k)),
            Some((a, ka)) if *ka != k => {
                return Err(ShardError::Mismatch {
                    a: (*a).clone(),
                    b: p.clone(),
                    what: "the kind of shard (`run --shard`, `dial --shard` or `select-lines --shard`)",
                    first: ka.clone(),
                    second: k,
                });
            }
            Some(_) => {}
        }
    }
    first
        .map(|(_, k)| k)
        .ok_or_else(|| ShardError::NoShards(paths.to_vec()))
}
