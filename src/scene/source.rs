//! Where a scene's values came from, and how a problem with one is named: at the line and key
//! of a TOML file, or at the field path of a description built in code.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::input::{Bounds, InputError, check_finite_range};

use super::description::PerChannel;
use super::overrides::{Edited, LineOrigin, remap};

/// The origin of a description: a TOML text (errors name its lines) or code (errors name
/// field paths). `path` names the file, or a pseudo-path, in every error.
#[derive(Clone)]
pub(super) struct Source {
    pub path: PathBuf,
    /// The scene text: the file's as read, or the description written as TOML.
    pub text: Arc<str>,
    /// Whether `text` is what the user wrote (so its lines can be named).
    pub has_lines: bool,
    /// With `--set` overrides: where each line of `text` came from (a line of the file, or an
    /// override, which an error then names instead of a line).
    pub origins: Option<Arc<[LineOrigin]>>,
}

/// Without `origins`: the scene's digest (shards, `crate::shard::scene_digest`, a digest of
/// its `Debug` form) is that of its text, so that a scene read with `--set` overrides and the
/// same edited text read again (as `merge` reads it from the shards) agree.
impl std::fmt::Debug for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Source")
            .field("path", &self.path)
            .field("text", &self.text)
            .field("has_lines", &self.has_lines)
            .finish()
    }
}

impl Source {
    /// A scene file's text.
    pub fn toml(path: &Path, text: &str) -> Self {
        Source {
            path: path.to_path_buf(),
            text: Arc::from(text),
            has_lines: true,
            origins: None,
        }
    }

    /// A scene file's text after `--set` overrides ([`super::overrides`]).
    pub fn edited(path: &Path, edited: Edited) -> Self {
        Source {
            path: path.to_path_buf(),
            text: Arc::from(edited.text),
            has_lines: true,
            origins: Some(Arc::from(edited.origins)),
        }
    }

    /// A description built in code; `text` is its TOML form (for the shard digests).
    pub fn code(path: &Path, text: String) -> Self {
        Source {
            path: path.to_path_buf(),
            text: Arc::from(text),
            has_lines: false,
            origins: None,
        }
    }

    /// An error at a key: at its line in a file, at its field path otherwise.
    pub fn err(&self, at: &KeyPath, message: impl Into<String>) -> InputError {
        let (line, field) = if self.has_lines {
            (Some(at.line(&self.text)), at.dotted())
        } else {
            (None, at.field_path())
        };
        let e = InputError {
            path: self.path.clone(),
            line,
            field: Some(field),
            message: message.into(),
        };
        match &self.origins {
            Some(o) => remap(e, &self.path, o),
            None => e,
        }
    }

    /// `v` if it is finite and inside `bounds` (in the unit of the key's name), else an error
    /// at the key: the one check of every number in a scene.
    pub fn range(&self, at: &KeyPath, v: f64, bounds: Bounds) -> Result<f64, InputError> {
        check_finite_range(v, bounds).map_err(|m| self.err(at, m))
    }

    /// Every value of a per-channel list inside `bounds`.
    pub fn range_all(&self, at: &KeyPath, v: &[f64], bounds: Bounds) -> Result<(), InputError> {
        for x in v {
            self.range(at, *x, bounds)?;
        }
        Ok(())
    }

    /// Exactly one of two alternative keys, each checked against its own bounds in its own
    /// unit, then scaled to a common unit.
    pub fn one_of(
        &self,
        section: &KeyPath,
        a: (&str, Option<f64>, f64, Bounds),
        b: (&str, Option<f64>, f64, Bounds),
    ) -> Result<(KeyPath, f64), InputError> {
        let pick = |(name, v, scale, bounds): (&str, f64, f64, Bounds)| {
            let at = section.key(name);
            let v = self.range(&at, v, bounds)?;
            Ok((at, v * scale))
        };
        match (a.1, b.1) {
            (Some(x), None) => pick((a.0, x, a.2, a.3)),
            (None, Some(x)) => pick((b.0, x, b.2, b.3)),
            (Some(_), Some(_)) => Err(self.err(
                &section.key(b.0),
                format!("give `{}` or `{}`, not both", a.0, b.0),
            )),
            (None, None) => Err(self.err(section, format!("needs `{}` or `{}`", a.0, b.0))),
        }
    }

    /// A per-channel value as one value per channel.
    pub fn per_channel(
        &self,
        at: &KeyPath,
        v: &PerChannel,
        n_channels: usize,
    ) -> Result<Vec<f64>, InputError> {
        match v {
            PerChannel::One(x) => Ok(vec![*x; n_channels]),
            PerChannel::Many(xs) if xs.len() == n_channels => Ok(xs.clone()),
            PerChannel::Many(xs) => Err(self.err(
                at,
                format!(
                    "has {} values; give one value or one per channel ({n_channels})",
                    xs.len()
                ),
            )),
        }
    }
}

/// Where a value sits in the file: a section (`[name]`, or the i-th `[[name]]`) and a key.
#[derive(Debug, Clone)]
pub(super) struct KeyPath {
    section: Option<(String, Option<usize>)>,
    key: Option<String>,
}

impl KeyPath {
    pub fn root() -> Self {
        KeyPath {
            section: None,
            key: None,
        }
    }
    pub fn table(name: &str) -> Self {
        KeyPath {
            section: Some((name.into(), None)),
            key: None,
        }
    }
    pub fn array(name: &str, index: usize) -> Self {
        KeyPath {
            section: Some((name.into(), Some(index))),
            key: None,
        }
    }
    pub fn key(&self, key: &str) -> Self {
        KeyPath {
            section: self.section.clone(),
            key: Some(key.into()),
        }
    }

    /// `lidar.pulse_energy_j`, `layer.top_m`, `channel` …
    pub fn dotted(&self) -> String {
        match (&self.section, &self.key) {
            (Some((s, _)), Some(k)) => format!("{s}.{k}"),
            (Some((s, _)), None) => s.clone(),
            (None, Some(k)) => k.clone(),
            (None, None) => "(scene)".into(),
        }
    }

    /// `lidar.pulse_energy_j`, `layer[2].top_m`, `channel[0]` …: the field of a
    /// [`super::SceneDescription`] built in code.
    pub fn field_path(&self) -> String {
        let section = self.section.as_ref().map(|(s, i)| match i {
            Some(i) => format!("{s}[{i}]"),
            None => s.clone(),
        });
        match (section, &self.key) {
            (Some(s), Some(k)) => format!("{s}.{k}"),
            (Some(s), None) => s,
            (None, Some(k)) => k.clone(),
            (None, None) => "(scene)".into(),
        }
    }

    /// 1-based line of the key (or of its section header when the key is absent).
    pub fn line(&self, text: &str) -> usize {
        let mut in_section = self.section.is_none();
        let mut header_line = 1;
        let mut seen = 0usize;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.starts_with('[') {
                let (name, is_array) = if let Some(n) = line.strip_prefix("[[") {
                    (n.split("]]").next().unwrap_or("").trim(), true)
                } else {
                    (
                        line.trim_start_matches('[')
                            .split(']')
                            .next()
                            .unwrap_or("")
                            .trim(),
                        false,
                    )
                };
                in_section = match &self.section {
                    Some((s, None)) => !is_array && name == s,
                    Some((s, Some(idx))) => {
                        let hit = is_array && name == s && seen == *idx;
                        if is_array && name == s {
                            seen += 1;
                        }
                        hit
                    }
                    None => false,
                };
                if in_section {
                    header_line = i + 1;
                }
                continue;
            }
            if in_section
                && let Some(k) = &self.key
                && let Some(rest) = line.strip_prefix(k.as_str())
                && rest.trim_start().starts_with('=')
            {
                return i + 1;
            }
        }
        header_line
    }
}

/// The first float in the scene text that is not finite (`nan`, `inf`, or a literal beyond
/// the f64 range such as `1e400`), as an error at its own line and key: a NaN must be named
/// where it stands, not where a later comparison with it first fails.
pub(super) fn non_finite_value(path: &Path, text: &str) -> Result<(), InputError> {
    use toml::de::{DeTable, DeValue};
    type Found = (String, std::ops::Range<usize>, String);
    fn walk(key: &str, v: &toml::Spanned<DeValue<'_>>, out: &mut Vec<Found>) {
        match v.get_ref() {
            DeValue::Float(f) => {
                let raw = f.as_str().to_string();
                let finite = raw
                    .replace('_', "")
                    .parse::<f64>()
                    .is_ok_and(f64::is_finite);
                if !finite {
                    out.push((key.to_string(), v.span(), raw));
                }
            }
            DeValue::Array(items) => items.iter().for_each(|i| walk(key, i, out)),
            DeValue::Table(t) => {
                for (k, v) in t.iter() {
                    let name = if key.is_empty() {
                        k.get_ref().to_string()
                    } else {
                        format!("{key}.{}", k.get_ref())
                    };
                    walk(&name, v, out);
                }
            }
            _ => {}
        }
    }
    // The text has already been parsed by serde; a failure here cannot add anything.
    let Ok(doc) = DeTable::parse(text) else {
        return Ok(());
    };
    let mut all = Vec::new();
    for (k, v) in doc.get_ref().iter() {
        walk(k.get_ref(), v, &mut all);
    }
    // The table is sorted by key; report the first in the file.
    let found = all.into_iter().min_by_key(|(_, span, _)| span.start);
    match found {
        None => Ok(()),
        Some((key, span, raw)) => Err(InputError {
            path: path.to_path_buf(),
            line: Some(text[..span.start.min(text.len())].matches('\n').count() + 1),
            field: Some(key),
            message: format!("`{raw}` is not a finite number"),
        }),
    }
}

/// Turn a TOML/serde error into an [`InputError`] with the line and the key.
pub(super) fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> InputError {
    // One line: serde adds the inner key of an inline table on a line of its own
    // ("unknown variant `x`, expected …\nin `kind`").
    let message = e
        .message()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    // The key: quoted in messages about unknown or missing fields, otherwise the key of the
    // line the span starts on (an unknown variant quotes the value, not the key).
    let quoted = ["unknown field `", "missing field `"]
        .iter()
        .find_map(|p| message.split(p).nth(1).and_then(|r| r.split('`').next()))
        .map(str::to_string);
    let field = quoted.or_else(|| {
        line.and_then(|l| text.lines().nth(l - 1)).and_then(|l| {
            l.split_once('=')
                .map(|(k, _)| k.trim().to_string())
                .filter(|k| !k.is_empty())
        })
    });
    InputError {
        path: path.to_path_buf(),
        line,
        field,
        message,
    }
}
