//! `--set KEY=VALUE`: a scene's values overridden from the command line before it is parsed, so
//! that an override passes every check a value in the file passes (parse, validate, resolve).
//!
//! The override is made on the TOML document (format-preserving, `toml_edit`), and the edited
//! text is then read exactly as a file is. Each line of the edited text keeps where it came
//! from ([`LineOrigin`]): a line of the file (its number there, which an error names), or an
//! override (an error on it names `--set KEY` instead of a line the user never wrote).

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::input::InputError;

/// One `--set KEY=VALUE`: a dotted key (`lidar.fov_full_angle_mrad`, `channel.0.wavenumber_cm1`
/// for the first `[[channel]]`) and a value in TOML (`[1, 2]`, `1e6`, `"x"`, `true`; a bare
/// word that is not TOML is taken as a string: `atmosphere.standard=tropical`).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneOverride {
    /// The dotted key as given.
    pub key: String,
    /// The value's text as given.
    pub value: String,
}

impl FromStr for SceneOverride {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (key, value) = s
            .split_once('=')
            .ok_or_else(|| format!("`{s}`: give KEY=VALUE (e.g. simulation.photons=1e6)"))?;
        let key = key.trim();
        let segments: Vec<&str> = key.split('.').map(str::trim).collect();
        if segments.iter().any(|k| k.is_empty()) {
            return Err(format!(
                "`{key}` is not a dotted key (e.g. lidar.fov_full_angle_mrad or channel.0.wavenumber_cm1)"
            ));
        }
        Ok(SceneOverride {
            key: segments.join("."),
            value: value.trim().to_string(),
        })
    }
}

impl std::fmt::Display for SceneOverride {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}={}", self.key, self.value)
    }
}

impl SceneOverride {
    /// The name an error about this override carries in place of FILE:LINE.
    pub fn origin_name(key: &str) -> String {
        format!("--set {key}")
    }

    /// The value as TOML: a TOML value, else (a bare word) the text as a string.
    fn toml_value(&self) -> toml_edit::Value {
        toml_edit::Value::from_str(&self.value)
            .unwrap_or_else(|_| toml_edit::Value::from(self.value.as_str()))
    }

    fn error(&self, message: impl Into<String>) -> InputError {
        InputError::file(Self::origin_name(&self.key), message)
    }
}

/// Where a line of an edited scene text came from.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum LineOrigin {
    /// Line N (1-based) of the file.
    File(usize),
    /// Written by the override of this key.
    Set(String),
}

/// A scene text with overrides applied, and where each of its lines came from.
#[derive(Debug, Clone)]
pub(super) struct Edited {
    pub text: String,
    pub origins: Vec<LineOrigin>,
}

impl Edited {
    /// The text unchanged.
    pub fn unchanged(text: &str) -> Edited {
        Edited {
            text: text.to_string(),
            origins: (1..=text.lines().count().max(1))
                .map(LineOrigin::File)
                .collect(),
        }
    }
}

/// An error at line `line` of the edited text of the scene `path`, named where that line came
/// from: the same line of the file, or the override that wrote it.
pub(super) fn remap(e: InputError, path: &Path, origins: &[LineOrigin]) -> InputError {
    if e.path != path {
        return e;
    }
    let Some(line) = e.line else { return e };
    match origins.get(line.wrapping_sub(1)) {
        Some(LineOrigin::File(n)) => InputError {
            line: Some(*n),
            ..e
        },
        Some(LineOrigin::Set(key)) => InputError {
            path: PathBuf::from(SceneOverride::origin_name(key)),
            line: None,
            // The key is in the name already; a field inside it (of an inline table) stays.
            field: e.field.filter(|f| {
                f != key && !key.ends_with(&format!(".{f}")) && !key.starts_with(&format!("{f}."))
            }),
            message: e.message,
        },
        None => e,
    }
}

/// Apply `overrides` in order to the scene text `text`. A key that cannot be set (an index
/// past the end of an array, a key inside a number) is refused naming `--set KEY`; a text that
/// is not TOML is left for the parser to report at its line.
pub(super) fn apply(text: &str, overrides: &[SceneOverride]) -> Result<Edited, InputError> {
    let mut edited = Edited::unchanged(text);
    if overrides.is_empty() {
        return Ok(edited);
    }
    let Ok(mut doc) = text.parse::<toml_edit::DocumentMut>() else {
        // The parser names the line of the problem in the file.
        return Ok(edited);
    };
    for o in overrides {
        let segments: Vec<&str> = o.key.split('.').collect();
        set_in_item(doc.as_item_mut(), &segments, &[], o)?;
        let new_text = doc.to_string();
        edited = Edited {
            origins: map_lines(&edited, &new_text, &o.key),
            text: new_text,
        };
    }
    Ok(edited)
}

/// `a.b.c` of the first `n` segments, for messages.
fn dotted(done: &[&str]) -> String {
    done.join(".")
}

fn set_in_item(
    item: &mut toml_edit::Item,
    rest: &[&str],
    done: &[&str],
    o: &SceneOverride,
) -> Result<(), InputError> {
    use toml_edit::Item;
    let (seg, tail) = (rest[0], &rest[1..]);
    let here: Vec<&str> = done.iter().copied().chain([seg]).collect();
    match item {
        Item::Table(t) => {
            if tail.is_empty() {
                let mut v = o.toml_value();
                match t.get_mut(seg) {
                    Some(Item::Value(old)) => {
                        *v.decor_mut() = old.decor().clone();
                        *old = v;
                    }
                    Some(other) => *other = Item::Value(v),
                    None => {
                        t.insert(seg, Item::Value(v));
                    }
                }
                return Ok(());
            }
            if t.get(seg).is_none() {
                // A new section, written as its own `[a.b]` table.
                if tail[0].parse::<usize>().is_ok() {
                    return Err(o.error(format!(
                        "the scene has no `{}`: an index addresses an existing array",
                        dotted(&here)
                    )));
                }
                t.insert(seg, Item::Table(toml_edit::Table::new()));
            }
            let next = t.get_mut(seg).expect("inserted");
            set_in_item(next, tail, &here, o)
        }
        Item::ArrayOfTables(a) => {
            let len = a.len();
            let i = index(seg, done, len, "tables", o)?;
            let t = a.get_mut(i).expect("in range");
            if tail.is_empty() {
                return Err(o.error(format!(
                    "`{}` is a table: set one of its keys ({}.KEY)",
                    dotted(&here),
                    dotted(&here)
                )));
            }
            set_in_table(t, tail, &here, o)
        }
        Item::Value(v) => set_in_value(v, rest, done, o),
        Item::None => Err(o.error(format!("the scene has no `{}`", dotted(done)))),
    }
}

fn set_in_table(
    t: &mut toml_edit::Table,
    rest: &[&str],
    done: &[&str],
    o: &SceneOverride,
) -> Result<(), InputError> {
    let mut item = toml_edit::Item::Table(std::mem::take(t));
    let r = set_in_item(&mut item, rest, done, o);
    if let toml_edit::Item::Table(back) = item {
        *t = back;
    }
    r
}

fn set_in_value(
    v: &mut toml_edit::Value,
    rest: &[&str],
    done: &[&str],
    o: &SceneOverride,
) -> Result<(), InputError> {
    use toml_edit::Value;
    let (seg, tail) = (rest[0], &rest[1..]);
    let here: Vec<&str> = done.iter().copied().chain([seg]).collect();
    let slot: &mut Value = match v {
        Value::InlineTable(t) => {
            if t.get(seg).is_none() {
                if tail.is_empty() {
                    t.insert(seg, o.toml_value());
                    return Ok(());
                }
                t.insert(seg, Value::InlineTable(toml_edit::InlineTable::new()));
            }
            t.get_mut(seg).expect("inserted")
        }
        Value::Array(a) => {
            let i = index(seg, done, a.len(), "values", o)?;
            a.get_mut(i).expect("in range")
        }
        _ => {
            return Err(o.error(format!(
                "`{}` is a single value, not a table or an array: it has no `{seg}`",
                dotted(done)
            )));
        }
    };
    if tail.is_empty() {
        let mut new = o.toml_value();
        *new.decor_mut() = slot.decor().clone();
        *slot = new;
        Ok(())
    } else {
        set_in_value(slot, tail, &here, o)
    }
}

/// The index `seg` into an array of `len` items at `done`, or the error saying which exist.
fn index(
    seg: &str,
    done: &[&str],
    len: usize,
    what: &str,
    o: &SceneOverride,
) -> Result<usize, InputError> {
    let name = dotted(done);
    let i: usize = seg.parse().map_err(|_| {
        o.error(format!(
            "`{name}` is an array of {len} {what}: address one by its index ({name}.0 … {name}.{})",
            len.saturating_sub(1)
        ))
    })?;
    if i >= len {
        return Err(o.error(format!(
            "`{name}` has {len} {what} (indices 0 to {}): there is no `{name}.{i}`",
            len.saturating_sub(1)
        )));
    }
    Ok(i)
}

/// The origins of the lines of `new`, the text of `old` after one override of `key`: the lines
/// `new` shares with `old` (a longest common subsequence of lines) keep their origin, the other
/// lines were written by the override.
fn map_lines(old: &Edited, new: &str, key: &str) -> Vec<LineOrigin> {
    let a: Vec<&str> = old.text.lines().collect();
    let b: Vec<&str> = new.lines().collect();
    // lcs[i][j]: length of the LCS of a[i..] and b[j..] (scenes are hundreds of lines).
    let (n, m) = (a.len(), b.len());
    let mut lcs = vec![vec![0u32; m + 1]; n + 1];
    for i in (0..n).rev() {
        for j in (0..m).rev() {
            lcs[i][j] = if a[i] == b[j] {
                lcs[i + 1][j + 1] + 1
            } else {
                lcs[i + 1][j].max(lcs[i][j + 1])
            };
        }
    }
    let mut out = vec![LineOrigin::Set(key.to_string()); m.max(1)];
    let (mut i, mut j) = (0, 0);
    while i < n && j < m {
        if a[i] == b[j] {
            out[j] = old
                .origins
                .get(i)
                .cloned()
                .unwrap_or(LineOrigin::Set(key.to_string()));
            i += 1;
            j += 1;
        } else if lcs[i + 1][j] >= lcs[i][j + 1] {
            i += 1;
        } else {
            j += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(text: &str, sets: &[&str]) -> Result<Edited, InputError> {
        let o: Vec<SceneOverride> = sets.iter().map(|s| s.parse().unwrap()).collect();
        apply(text, &o)
    }

    const TEXT: &str = "\
description = \"x\"

[lidar]
altitude_m = 0.0
fov_full_angle_mrad = [1.0]  # two
optics = { a = 1, b = [2, 3] }

[simulation]
photons = 100

[[channel]]
name = \"on\"
wavenumber_cm1 = 6000.0

[[channel]]
name = \"off\"
wavenumber_cm1 = 6001.0
";

    fn value(e: &Edited, key: &str) -> toml::Value {
        let v: toml::Table = e.text.parse().unwrap();
        let mut cur = toml::Value::Table(v);
        for k in key.split('.') {
            cur = match cur {
                toml::Value::Table(mut t) => t.remove(k).unwrap(),
                toml::Value::Array(mut a) => a.remove(k.parse().unwrap()),
                other => panic!("{other:?}"),
            };
        }
        cur
    }

    #[test]
    fn an_override_parses_key_and_value() {
        let o: SceneOverride = "lidar.fov_full_angle_mrad=[1,2]".parse().unwrap();
        assert_eq!(o.key, "lidar.fov_full_angle_mrad");
        assert_eq!(o.value, "[1,2]");
        assert!("lidar".parse::<SceneOverride>().is_err());
        assert!("a..b=1".parse::<SceneOverride>().is_err());
        assert!("=1".parse::<SceneOverride>().is_err());
    }

    #[test]
    fn values_are_toml_and_bare_words_strings() {
        let e = set(
            TEXT,
            &[
                "lidar.fov_full_angle_mrad=[1,2]",
                "simulation.photons=1e6",
                "atmosphere.standard=tropical",
                "atmosphere.co2_ppm=410",
                "channel.1.wavenumber_cm1=6360",
                "lidar.optics.b.1=7",
                "lidar.optics.c=true",
                "description=\"a b\"",
            ],
        )
        .unwrap();
        assert_eq!(
            value(&e, "lidar.fov_full_angle_mrad"),
            toml::Value::Array(vec![1.into(), 2.into()])
        );
        assert_eq!(value(&e, "simulation.photons"), toml::Value::Float(1e6));
        assert_eq!(value(&e, "atmosphere.standard"), "tropical".into());
        assert_eq!(value(&e, "atmosphere.co2_ppm"), 410.into());
        assert_eq!(value(&e, "channel.1.wavenumber_cm1"), 6360.into());
        assert_eq!(value(&e, "channel.0.wavenumber_cm1"), 6000.0.into());
        assert_eq!(value(&e, "lidar.optics.b.1"), 7.into());
        assert_eq!(value(&e, "lidar.optics.c"), true.into());
        assert_eq!(value(&e, "description"), "a b".into());
        // Every line of the file that is still there keeps its number.
        let file: Vec<&str> = TEXT.lines().collect();
        for (line, origin) in e.text.lines().zip(&e.origins) {
            if let LineOrigin::File(n) = origin {
                assert_eq!(file[n - 1], line);
            }
        }
        let at = |needle: &str| {
            let i = e.text.lines().position(|l| l.contains(needle)).unwrap();
            e.origins[i].clone()
        };
        assert_eq!(at("name = \"off\""), LineOrigin::File(16));
        assert_eq!(at("photons"), LineOrigin::Set("simulation.photons".into()));
        assert_eq!(at("co2_ppm"), LineOrigin::Set("atmosphere.co2_ppm".into()));
    }

    #[test]
    fn keys_that_cannot_be_set_are_refused_naming_the_override() {
        for (s, want) in [
            (
                "channel.2.name=x",
                "`channel` has 2 tables (indices 0 to 1)",
            ),
            ("channel.name=x", "address one by its index"),
            ("channel.0=1", "is a table"),
            ("simulation.photons.x=1", "is a single value"),
            ("lidar.fov_full_angle_mrad.3=1", "has 1 values"),
            ("nothing.0.x=1", "the scene has no `nothing`"),
        ] {
            let e = set(TEXT, &[s]).unwrap_err();
            let key = s.split('=').next().unwrap();
            assert_eq!(e.path, PathBuf::from(format!("--set {key}")), "{s}");
            assert!(e.message.contains(want), "{s}: {e}");
        }
    }

    #[test]
    fn an_error_on_an_overridden_line_names_the_override() {
        let e = set(TEXT, &["simulation.photons=1.5"]).unwrap();
        let line = e.text.lines().position(|l| l.contains("photons")).unwrap() + 1;
        let err = InputError::at("s.toml", line, "simulation.photons", "bad");
        assert_eq!(
            remap(err, Path::new("s.toml"), &e.origins).to_string(),
            "--set simulation.photons: bad"
        );
        let err = InputError::at("s.toml", e.origins.len(), "channel.wavenumber_cm1", "bad");
        assert_eq!(
            remap(err, Path::new("s.toml"), &e.origins).to_string(),
            "s.toml:17: `channel.wavenumber_cm1`: bad"
        );
    }

    /// Every shipped scene reads back through the editor unchanged (no line moved).
    #[test]
    fn shipped_scenes_pass_through_the_editor_unchanged() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        for f in std::fs::read_dir(dir).unwrap() {
            let p = f.unwrap().path();
            if p.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&p).unwrap();
                let doc: toml_edit::DocumentMut = text.parse().unwrap();
                assert_eq!(doc.to_string(), text, "{}", p.display());
            }
        }
    }
}
