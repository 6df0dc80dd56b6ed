//! Issue 37 item 6: every subcommand fuzzed through the binary, not only `run` with mutated
//! scenes (`tests/fuzz.rs`): `dial`, `select-lines`, `lbl`, `profiles
//! generate/plot/convert/info`, `mie`, `merge`, `bench`, and `run`'s options, phase tables,
//! matrix tables and shards.
//!
//! Each subcommand has a few valid invocations ([`Template`]s) with small, fast inputs. A case
//! takes one and changes its option values (the mutations of `tests/fuzz.rs` on the value's
//! text: `nan`, `±inf`, `±1e308`, `0`, `-0`, huge integers, empty, `1e`, powers of ten, a sign,
//! a digit), its input files (the same mutator on profile sets, line lists, phase and error
//! tables, scenes; shard files damaged as a disk, a network or a hand would damage them:
//! truncated, a bit flipped with and without the checksum recomputed, header fields changed,
//! tallies set to NaN, ±inf, −1e300, 1e300 with the checksum recomputed, a shard missing or
//! twice), or both; then runs it as `lidarsim …` on two worker threads, each case in a fresh
//! directory, within a time and memory bound. What every case owes:
//!
//! * exit code 0 or 2, never a panic, a signal or a hang;
//! * on 2, an error that names what was changed: the option, or the file (clap's own
//!   "unexpected argument 'X'" names the value), and nothing written;
//! * on 0, every CSV, JSON and NetCDF file written parses and holds no `NaN` or `inf`
//!   (energies, cross-sections and optical depths non-negative), nothing on stdout is `NaN` or
//!   `inf`, no staging directory is left, and what lidarsim has a reader for reads back (a
//!   profile set, a covariance, a phase or matrix table, a gas optical-depth table); a study
//!   that ran has at least one profile that did not fail (item 5).
//!
//! Deterministic: [`crate::fuzz::SEED`] (`LIDARSIM_FUZZ_SEED` to change it), each case from its
//! own index; `LIDARSIM_FUZZ_SCALE=K` multiplies every case count; `LIDARSIM_FUZZ_CASE=N` runs
//! case N of a subcommand alone and shows it, `LIDARSIM_FUZZ_SHOW=1` shows every case (README,
//! "Fuzzing"). A failing case keeps its inputs and command line in
//! `target/tmp/fuzz_cli/<subcommand>/case-N/`.
//!
//! What this does not test: requests that are valid and large by design (a billion photons, a
//! million-point grid) are redrawn, not run (the Limits table of the README bounds them, and
//! `tests/validation_inputs.rs` checks the limits): each template says what is too large.
//!
//! Bugs found and reported (FUZZ_FINDINGS.md) but not fixed here are in [`KNOWN`]:
//! their cases are counted apart, so that the fuzz keeps running in CI and fails on anything
//! new; a default run in which one no longer occurs fails until its entry is removed. Each has
//! a test of its own in [`findings`], ignored until its fix is merged.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::fuzz::{self, Format, KINDS, Mutation};
use crate::util::{
    absolute_paths, check_csv_text, check_json_text_allowing, check_written, file_names,
    lidarsim_bounded, lidarsim_ok, non_finite_word, project_root, shard_header, tree,
    with_checksum, with_shard_header,
};

/// A case that takes longer has hung (the templates take at most about 0.5 s unmutated).
const TIME_LIMIT: Duration = Duration::from_secs(20);

// ---------------------------------------------------------------------------------------------
// Cases.

/// A value on a command line.
#[derive(Debug, Clone)]
enum Value {
    /// A number or a comma-separated list of numbers: mutated as numbers.
    Num(String),
    /// A word (a name, a choice, a path-like text): mutated as bytes.
    Word(String),
    /// An input file: the case's file of this name, written into its input directory.
    In(&'static str),
    /// An output path under the case's (empty) work directory.
    Out(&'static str),
}

/// One argument: `flag value` (or `flag=value` when `joined`), a bare `flag`, or (flag "") a
/// positional value; nothing when both are empty (an option left out).
#[derive(Debug, Clone)]
struct Arg {
    flag: &'static str,
    value: Option<Value>,
    joined: bool,
}

/// How an input file is damaged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// Text in one of the mutator's formats.
    Text(Format),
    /// A shard file (`*.lshard`).
    Shard,
}

/// An input file of a case.
#[derive(Debug, Clone)]
struct Input {
    /// Its name in the case's input directory (may hold one `/`).
    name: &'static str,
    bytes: Vec<u8>,
    kind: Kind,
}

/// A valid invocation of a subcommand.
#[derive(Debug, Clone)]
struct Template {
    /// The subcommand's words (`["profiles", "generate"]`).
    command: &'static [&'static str],
    args: Vec<Arg>,
    inputs: Vec<Input>,
    /// Options whose refusals may name one another (a grid's start, end and step): a change
    /// of one is reported well by a message naming another of the group.
    groups: &'static [&'static [&'static str]],
    /// Whether a case asks for valid but large work (redrawn).
    too_large: fn(&Case) -> bool,
    /// Checks of a case that ran, beyond those of every case.
    after: fn(&Case, &Path) -> Result<(), String>,
}

fn never(_: &Case) -> bool {
    false
}

fn nothing(_: &Case, _: &Path) -> Result<(), String> {
    Ok(())
}

/// A template made into a case: its arguments and files as they will be run.
#[derive(Debug, Clone)]
struct Case {
    template: Template,
    /// What was changed, for the report.
    changes: Vec<String>,
    /// What an error must name (at least one of): options, file names, values.
    culprits: Vec<String>,
    /// Whether a changed value holds a line break (an error that shows it spans lines).
    line_break: bool,
}

impl Case {
    /// The value of option `flag` as text, if it has one.
    fn text(&self, flag: &str) -> Option<&str> {
        self.template
            .args
            .iter()
            .find(|a| a.flag == flag)
            .and_then(|a| match &a.value {
                Some(Value::Num(t) | Value::Word(t)) => Some(t.as_str()),
                _ => None,
            })
    }

    /// The value of option `flag` as a number (the first of a list), if it is one.
    fn num(&self, flag: &str) -> Option<f64> {
        self.text(flag)
            .and_then(|t| t.split(',').next())
            .and_then(|t| t.trim().parse().ok())
    }

    /// Option `flag`'s number if it parses and is finite, else `default` (what a refusal
    /// would not run anyway).
    fn num_or(&self, flag: &str, default: f64) -> f64 {
        self.num(flag).filter(|v| v.is_finite()).unwrap_or(default)
    }

    /// The command line, with inputs under `inputs` and outputs under `work`.
    fn args(&self, inputs: &Path, work: &Path) -> Vec<OsString> {
        let mut out: Vec<OsString> = self.template.command.iter().map(OsString::from).collect();
        for a in &self.template.args {
            if let (true, Some(Value::Num(t) | Value::Word(t))) = (a.joined, &a.value) {
                out.push(format!("{}={t}", a.flag).into());
                continue;
            }
            if !a.flag.is_empty() {
                out.push(a.flag.into());
            }
            match &a.value {
                None => {}
                Some(Value::Num(t) | Value::Word(t)) => out.push(t.into()),
                Some(Value::In(name)) => out.push(inputs.join(name).into()),
                Some(Value::Out(name)) => out.push(work.join(name).into()),
            }
        }
        out
    }

    /// The command line as text, for the report.
    fn shown(&self) -> String {
        self.args(Path::new("IN"), Path::new("WORK"))
            .iter()
            .map(|a| {
                let a = a.to_string_lossy();
                if a.is_empty() || a.contains([' ', '"', '\'', '\n']) {
                    format!("{a:?}")
                } else {
                    a.into_owned()
                }
            })
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// A random generator for case `index` of subcommand `salt`: independent of the others, so
/// that one case can be run alone.
fn rng_for(seed: u64, salt: u64, index: usize) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(
        seed ^ salt.wrapping_mul(0xbf58_476d_1ce4_e5b9)
            ^ (index as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15),
    )
}

fn mutation(rng: &mut Xoshiro256PlusPlus, kind: u8) -> Mutation {
    Mutation {
        kind,
        a: rng.random(),
        b: rng.random(),
    }
}

/// A number's text changed as the scene fuzz changes numbers: a hostile value (a third), a
/// power of ten, a sign or a nudge (a half), a digit.
fn mutate_number(text: &str, rng: &mut Xoshiro256PlusPlus) -> String {
    let kind = match rng.random_range(0..100) {
        0..35 => 0,
        35..85 => 1,
        _ => 2,
    };
    let m = mutation(rng, kind);
    String::from_utf8_lossy(&fuzz::mutate(text.as_bytes(), Format::Csv, &[m])).into_owned()
}

/// A word damaged: cut, a byte changed, a character inserted, or another word.
fn mutate_word(text: &str, rng: &mut Xoshiro256PlusPlus) -> String {
    const OTHERS: [&str; 6] = ["", "x", "all", "-", "none", "1"];
    if rng.random_range(0..4) == 0 {
        return OTHERS[rng.random_range(0..OTHERS.len())].to_string();
    }
    let kind = rng.random_range(9..KINDS);
    let m = mutation(rng, kind);
    // Arguments are OS strings: a NUL cannot be passed, so it is dropped.
    String::from_utf8_lossy(&fuzz::mutate(text.as_bytes(), Format::Csv, &[m])).replace('\0', "")
}

/// A text file damaged as the scene fuzz damages scenes: mostly numbers, some hostile values,
/// some keys, lines and bytes.
fn mutate_text(bytes: &[u8], format: Format, rng: &mut Xoshiro256PlusPlus) -> Vec<u8> {
    let kinds: Vec<u8> = match rng.random_range(0..100) {
        0..55 => (0..rng.random_range(1..=3))
            .map(|_| if rng.random_range(0..4) == 0 { 2 } else { 1 })
            .collect(),
        55..80 => vec![0],
        _ => (0..rng.random_range(1..=2))
            .map(|_| rng.random_range(3..KINDS))
            .collect(),
    };
    let ms: Vec<Mutation> = kinds.into_iter().map(|k| mutation(rng, k)).collect();
    fuzz::mutate(bytes, format, &ms)
}

/// A case of template `t`: its option values, its input files or both changed, redrawn while
/// it asks for large work (at most a few times; then the template as it is).
fn make_case(t: &Template, rng: &mut Xoshiro256PlusPlus) -> Case {
    for _ in 0..20 {
        let c = draw_case(t, rng);
        if !(t.too_large)(&c) {
            return c;
        }
    }
    Case {
        template: t.clone(),
        changes: vec!["none (every draw asked for large work)".into()],
        culprits: Vec::new(),
        line_break: false,
    }
}

fn draw_case(t: &Template, rng: &mut Xoshiro256PlusPlus) -> Case {
    let mut c = Case {
        template: t.clone(),
        changes: Vec::new(),
        culprits: Vec::new(),
        line_break: false,
    };
    let mutable: Vec<usize> = (0..t.args.len())
        .filter(|&i| matches!(t.args[i].value, Some(Value::Num(_) | Value::Word(_))))
        .collect();
    // Half the cases change options, a third files, the rest both (what the template has).
    let roll = rng.random_range(0..100);
    let options = t.inputs.is_empty() || !(50..88).contains(&roll);
    let files = !t.inputs.is_empty() && (roll >= 50 || mutable.is_empty());
    if options && !mutable.is_empty() {
        for _ in 0..rng.random_range(1..=2) {
            let i = mutable[rng.random_range(0..mutable.len())];
            mutate_arg(&mut c, i, rng);
        }
    }
    if files {
        let k = rng.random_range(0..t.inputs.len());
        let input = &mut c.template.inputs[k];
        let name = input.name;
        match input.kind {
            Kind::Text(format) => {
                let new = mutate_text(&input.bytes, format, rng);
                let diff = changed_lines(&input.bytes, &new);
                input.bytes = new;
                c.changes.push(format!("file {name}: {diff}"));
                c.culprits.push(file_name(name));
            }
            Kind::Shard => mutate_shards(&mut c, k, rng),
        }
    }
    c
}

/// The lines a mutation changed (at most three), for the report.
fn changed_lines(old: &[u8], new: &[u8]) -> String {
    let (old, new) = (String::from_utf8_lossy(old), String::from_utf8_lossy(new));
    let (a, b): (Vec<&str>, Vec<&str>) = (old.lines().collect(), new.lines().collect());
    let mut out = Vec::new();
    for i in 0..a.len().max(b.len()) {
        let (x, y) = (
            a.get(i).copied().unwrap_or(""),
            b.get(i).copied().unwrap_or(""),
        );
        if x != y {
            let cut = |t: &str| t.chars().take(120).collect::<String>();
            out.push(format!("line {}: {:?} → {:?}", i + 1, cut(x), cut(y)));
        }
        if out.len() == 3 {
            out.push("…".into());
            break;
        }
    }
    if out.is_empty() {
        "unchanged".into()
    } else {
        out.join("; ")
    }
}

fn file_name(name: &str) -> String {
    name.rsplit('/').next().unwrap_or(name).to_string()
}

/// Change argument `i` of a case: its value mutated (most often), left without a value, or
/// the option left out.
fn mutate_arg(c: &mut Case, i: usize, rng: &mut Xoshiro256PlusPlus) {
    let flag = c.template.args[i].flag;
    let roll = rng.random_range(0..100);
    let shown = if flag.is_empty() {
        "the positional value"
    } else {
        flag
    };
    if roll < 4 && !flag.is_empty() {
        c.template.args[i].value = None;
        c.changes.push(format!("{flag} without its value"));
    } else if roll < 8 && !flag.is_empty() {
        // Only a required option's absence is an error: clap names it.
        c.template.args[i] = Arg {
            flag: "",
            value: None,
            joined: false,
        };
        c.changes.push(format!("{flag} left out"));
    } else {
        let Some(Value::Num(old) | Value::Word(old)) = &c.template.args[i].value else {
            return;
        };
        let new = match &c.template.args[i].value {
            Some(Value::Num(_)) => mutate_number(old, rng),
            _ => mutate_word(old, rng),
        };
        c.changes.push(format!("{shown} {old:?} → {new:?}"));
        // clap's "unexpected argument '-x'" names the value (or its first two characters, a
        // short flag to clap), not the option: clap reads `-1.5e3` as a negative number but
        // `-1e-3`, `-inf` and `-1,2` as flags (test `negative_values_in_any_notation`).
        if new.starts_with('-') {
            c.culprits.push(format!("'{new}'"));
            c.culprits
                .push(format!("'{}'", new.chars().take(2).collect::<String>()));
        }
        c.line_break |= new.contains(['\n', '\r']);
        match &mut c.template.args[i].value {
            Some(Value::Num(t) | Value::Word(t)) => *t = new,
            _ => unreachable!(),
        }
    }
    if flag.is_empty() {
        return;
    }
    c.culprits.push(flag.to_string());
    for g in c.template.groups {
        if g.contains(&flag) {
            c.culprits.extend(g.iter().map(|s| s.to_string()));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Shard files.

/// Values put in a shard's numbers: not finite, negative, huge, tiny.
const HOSTILE_F64: [f64; 11] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    -1.0,
    -1e300,
    1e300,
    f64::MAX,
    -0.0,
    5e-324,
    -5e-324,
    1e-300,
];

/// The same for the header's numbers and a run shard's counters.
const HOSTILE_U64: [u64; 6] = [0, 1, 3, u64::MAX, 1 << 53, 1 << 32];

/// Where the floating-point words of a run shard are: (tally words, trailer wall time at),
/// from its header (`src/shard/`: per batch an index, nine counters, the tallies and four
/// flux parts; then the wall time, the threads, the checksum).
fn run_shard_words(
    h: &serde_json::Value,
    body: usize,
    len: usize,
) -> Option<(Vec<usize>, Vec<usize>, usize)> {
    let bins = h["bins_per_batch"].as_u64()? as usize;
    let ch = h["channels"].as_u64()? as usize;
    let n = (h["end_batch"].as_u64()? - h["first_batch"].as_u64()?) as usize;
    let rec = 8 * (10 + bins + 4 * ch);
    if body + n * rec + 24 != len {
        return None;
    }
    let mut floats = Vec::new();
    let mut counters = Vec::new();
    for r in 0..n {
        let at = body + r * rec;
        counters.extend((0..10).map(|k| at + 8 * k));
        floats.extend((0..bins + 4 * ch).map(|k| at + 80 + 8 * k));
    }
    Some((floats, counters, len - 24))
}

/// Damage shard file `k` of a case (or the set: one missing, one twice).
fn mutate_shards(c: &mut Case, k: usize, rng: &mut Xoshiro256PlusPlus) {
    let inputs = &mut c.template.inputs;
    let name = inputs[k].name;
    let shown = file_name(name);
    let bytes = inputs[k].bytes.clone();
    let header = shard_header(&bytes);
    let kind = header
        .as_ref()
        .and_then(|(h, _)| h["kind"].as_str().map(str::to_string))
        .unwrap_or_else(|| "run".into());
    // A header text with a line break shows in the error as it is.
    let mut line_break = false;
    let (what, new): (String, Option<Vec<u8>>) = match rng.random_range(0..100) {
        0..10 => {
            let n = rng.random_range(0..=bytes.len());
            (
                format!("truncated to {n} of {} bytes", bytes.len()),
                Some(bytes[..n].to_vec()),
            )
        }
        10..20 => {
            let at = rng.random_range(0..bytes.len());
            let bit = rng.random_range(0..8);
            let mut b = bytes.clone();
            b[at] ^= 1 << bit;
            (format!("bit {bit} of byte {at} flipped"), Some(b))
        }
        20..30 => {
            let at = rng.random_range(0..bytes.len().saturating_sub(8).max(1));
            let bit = rng.random_range(0..8);
            let mut b = bytes.clone();
            b[at] ^= 1 << bit;
            (
                format!("bit {bit} of byte {at} flipped, checksum recomputed"),
                Some(with_checksum(b)),
            )
        }
        30..50 => {
            let Some((mut h, _)) = header.clone() else {
                return;
            };
            let keys: Vec<String> = h
                .as_object()
                .map(|o| o.keys().cloned().collect())
                .unwrap_or_default();
            if keys.is_empty() {
                return;
            }
            let key = keys[rng.random_range(0..keys.len())].clone();
            let old = h[&key].clone();
            let new: serde_json::Value = match &old {
                serde_json::Value::Number(_) if rng.random_range(0..3) > 0 => {
                    HOSTILE_U64[rng.random_range(0..HOSTILE_U64.len())].into()
                }
                serde_json::Value::Number(_) => (-1).into(),
                serde_json::Value::String(s) if rng.random_range(0..2) == 0 && !s.is_empty() => {
                    let mut s = s.clone();
                    s.truncate(rng.random_range(0..s.len()));
                    s.into()
                }
                serde_json::Value::String(_) => "\u{0}x,\"\n".into(),
                serde_json::Value::Bool(b) => (!b).into(),
                _ => serde_json::Value::Null,
            };
            h[&key] = new.clone();
            line_break = new.as_str().is_some_and(|t| t.contains('\n'));
            (
                format!("header `{key}` {old} → {new}, checksum recomputed"),
                Some(with_shard_header(&bytes, &h)),
            )
        }
        50..85 => {
            // A number of the body set to a hostile value, checksum recomputed.
            let Some((h, body)) = &header else {
                return;
            };
            let layout = (kind == "run")
                .then(|| run_shard_words(h, *body, bytes.len()))
                .flatten();
            let mut b = bytes.clone();
            let what = match (layout, rng.random_range(0..10)) {
                (Some((floats, _, _)), 0..6) if !floats.is_empty() => {
                    let at = floats[rng.random_range(0..floats.len())];
                    let v = HOSTILE_F64[rng.random_range(0..HOSTILE_F64.len())];
                    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
                    format!("the tally at byte {at} set to {v:e}")
                }
                (Some((_, counters, _)), 6..8) => {
                    let at = counters[rng.random_range(0..counters.len())];
                    let v = HOSTILE_U64[rng.random_range(0..HOSTILE_U64.len())];
                    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
                    format!("the counter at byte {at} set to {v}")
                }
                (Some((_, _, wall)), _) => {
                    let v = HOSTILE_F64[rng.random_range(0..HOSTILE_F64.len())];
                    b[wall..wall + 8].copy_from_slice(&v.to_le_bytes());
                    format!("the wall time set to {v:e}")
                }
                (None, _) => {
                    // A study shard: its records hold every float as its bits, among counts
                    // and texts; any 8 bytes of the body.
                    let end = bytes.len().saturating_sub(16);
                    if end <= *body {
                        return;
                    }
                    let at = rng.random_range(*body..end);
                    let v = HOSTILE_F64[rng.random_range(0..HOSTILE_F64.len())];
                    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
                    format!("8 bytes of the body at {at} set to {v:e}")
                }
            };
            (
                format!("{what}, checksum recomputed"),
                Some(with_checksum(b)),
            )
        }
        85..90 => {
            let mut b = bytes.clone();
            b.extend_from_slice(&[0u8; 8]);
            if rng.random_range(0..2) == 0 {
                ("8 zero bytes appended".into(), Some(b))
            } else {
                b.extend_from_slice(&[0u8; 8]);
                (
                    "16 bytes appended, checksum recomputed".into(),
                    Some(with_checksum(b)),
                )
            }
        }
        90..95 => ("left out (a shard missing)".into(), None),
        _ => {
            // The same shard twice, under another name.
            let mut copy = inputs[k].clone();
            copy.name = if name.contains("/") {
                "shards/copy.lshard"
            } else {
                "copy.lshard"
            };
            inputs.push(copy);
            c.changes.push(format!("{shown} given twice"));
            c.culprits.extend([shown, "copy.lshard".to_string()]);
            return;
        }
    };
    match new {
        Some(b) => inputs[k].bytes = b,
        None => {
            inputs.remove(k);
        }
    }
    c.changes.push(format!("{shown}: {what}"));
    c.culprits.push(shown);
    c.line_break |= line_break;
    // A missing shard is named by the ones that are there.
    if what.starts_with("left out") {
        c.culprits.extend(inputs.iter().map(|i| file_name(i.name)));
        c.culprits.push("missing".into());
    }
}

// ---------------------------------------------------------------------------------------------
// Running a case.

/// How a case ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Ran,
    Refused,
}

type CaseResult = Result<(Outcome, Duration), String>;

fn short(s: &str) -> String {
    s.trim().chars().take(700).collect()
}

/// Write a case's inputs into `dir`.
fn write_inputs(c: &Case, dir: &Path) -> Result<(), String> {
    for i in &c.template.inputs {
        let p = dir.join(i.name);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).map_err(|e| e.to_string())?;
        }
        std::fs::write(&p, &i.bytes).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Run a case and check what it owes (module docs).
fn run_case(c: &Case) -> CaseResult {
    let root = tempfile::tempdir().map_err(|e| e.to_string())?;
    let inputs = root.path().join("in");
    let work = root.path().join("work");
    std::fs::create_dir(&inputs).map_err(|e| e.to_string())?;
    std::fs::create_dir(&work).map_err(|e| e.to_string())?;
    write_inputs(c, &inputs)?;
    let ran = lidarsim_bounded(
        &c.args(&inputs, &work),
        root.path(),
        root.path(),
        TIME_LIMIT,
    )?;
    if ran.stderr.contains("panicked") {
        return Err(format!("panicked: {}", short(&ran.stderr)));
    }
    let written = tree(&work);
    match ran.code {
        Some(0) => {
            check_written(&work)?;
            if let Some(w) = non_finite_word(&ran.stdout) {
                let line = ran.stdout.lines().find(|l| l.contains(&w)).unwrap_or("");
                return Err(format!("exit 0 printed `{w}`: {}", short(line)));
            }
            (c.template.after)(c, &work).map_err(|e| format!("exit 0, but {e}"))?;
            if c.template.command == ["profiles", "info"] {
                check_csv_text("stdout", &ran.stdout)?;
            }
            if c.template.command == ["mie"] {
                // `table` and `matrix_table` are null when not written.
                check_json_text_allowing("stdout", &ran.stdout, &[".table", ".matrix_table"])?;
                check_mie_json(&ran.stdout)?;
            }
            Ok((Outcome::Ran, ran.took))
        }
        Some(2) => {
            let first = ran
                .stderr
                .lines()
                .find(|l| l.starts_with("lidarsim: error: ") || l.starts_with("error: "))
                .ok_or_else(|| format!("exit 2 without an error line: {:?}", short(&ran.stderr)))?;
            let ours = ran
                .stderr
                .lines()
                .filter(|l| l.starts_with("lidarsim: error: "))
                .count();
            let lines = ran.stderr.trim_end().lines().count();
            if first.starts_with("lidarsim: ") && (ours != 1 || (lines != 1 && !c.line_break)) {
                return Err(format!(
                    "exit 2 with more than one line: {:?}",
                    short(&ran.stderr)
                ));
            }
            if c.culprits.is_empty() {
                return Err(format!(
                    "the unchanged template was refused: {}",
                    short(first)
                ));
            }
            // clap's usage lines name every required option: only the message counts.
            let message: String = ran
                .stderr
                .lines()
                .take_while(|l| !l.starts_with("Usage:"))
                .collect::<Vec<_>>()
                .join("\n");
            if !c.culprits.iter().any(|w| message.contains(w.as_str())) {
                return Err(format!(
                    "exit 2 names none of {:?}: {}",
                    c.culprits,
                    short(first)
                ));
            }
            if !written.is_empty() {
                return Err(format!("exit 2 left {written:?} behind ({})", short(first)));
            }
            Ok((Outcome::Refused, ran.took))
        }
        code => Err(format!(
            "exit status {} (code {code:?}), expected 0 or 2: {}",
            ran.status,
            short(&ran.stderr)
        )),
    }
}

/// `mie`'s JSON: efficiencies and cross-sections non-negative, albedo in [0, 1], asymmetry in
/// [−1, 1].
fn check_mie_json(text: &str) -> Result<(), String> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("stdout: {e}"))?;
    let Some(o) = v.as_object() else {
        return Ok(());
    };
    for (k, x) in o {
        let Some(x) = x.as_f64() else { continue };
        let ok = match k.as_str() {
            "qext" | "qsca" | "qback" | "lidar_ratio_sr" | "phase_180" | "effective_radius_um" => {
                x >= 0.0
            }
            "ssa" | "single_scattering_albedo" => (0.0..=1.0).contains(&x),
            "g" | "asymmetry" => (-1.0..=1.0).contains(&x),
            k if k.ends_with("cross_section_um2") || k.starts_with("extinction_per") => x >= 0.0,
            _ => true,
        };
        if !ok {
            return Err(format!("mie printed `{k}` = {x}"));
        }
    }
    Ok(())
}

/// A failure's reason without its numbers and the case's paths, to count failures by kind.
fn signature(why: &str) -> String {
    let mut out = String::new();
    let mut last = ' ';
    for ch in why.chars() {
        let c = if ch.is_ascii_digit() { '#' } else { ch };
        if !(c == '#' && last == '#') {
            out.push(c);
        }
        last = c;
    }
    let out = match (out.find("/tmp/"), out.find("/in/")) {
        (Some(a), Some(b)) if a < b => format!("{}…{}", &out[..a], &out[b + 4..]),
        _ => out,
    };
    out.chars().take(110).collect()
}

/// Run `n` cases of a subcommand (times `LIDARSIM_FUZZ_SCALE`; one with `LIDARSIM_FUZZ_CASE`)
/// on two worker threads; fail listing every case that broke a promise.
fn fuzz_subcommand(name: &str, salt: u64, n: u32, templates: &[Template]) {
    assert!(!templates.is_empty());
    let seed = fuzz::seed();
    let only: Option<usize> = std::env::var("LIDARSIM_FUZZ_CASE")
        .ok()
        .and_then(|s| s.trim().parse().ok());
    let indices: Vec<usize> = match only {
        Some(i) => vec![i],
        None => (0..fuzz::cases(n) as usize).collect(),
    };
    let case = |i: usize| {
        let mut rng = rng_for(seed, salt, i);
        make_case(&templates[i % templates.len()], &mut rng)
    };
    let next = AtomicUsize::new(0);
    let started = Instant::now();
    let mut results: Vec<(usize, CaseResult)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..2)
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&i) = indices.get(k) else { break };
                        done.push((i, run_case(&case(i))));
                    }
                    done
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().expect("a fuzz worker"))
            .collect()
    });
    results.sort_by_key(|(i, _)| *i);
    let count = |o: Outcome| {
        results
            .iter()
            .filter(|(_, r)| matches!(r, Ok((x, _)) if *x == o))
            .count()
    };
    let (slowest, slowest_case) = results
        .iter()
        .filter_map(|(i, r)| r.as_ref().ok().map(|(_, t)| (*t, *i)))
        .max()
        .unwrap_or_default();
    println!(
        "{name}: {} cases (seed {seed}): {} ran, {} refused, {} failed; {:.1} s, slowest case {:.2} s (case {slowest_case})",
        results.len(),
        count(Outcome::Ran),
        count(Outcome::Refused),
        results.iter().filter(|(_, r)| r.is_err()).count(),
        started.elapsed().as_secs_f64(),
        slowest.as_secs_f64()
    );
    let keep = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("fuzz_cli")
        .join(name);
    let show_all = std::env::var_os("LIDARSIM_FUZZ_SHOW").is_some();
    let mut failures = Vec::new();
    // Failures by kind (the reason with its numbers and paths left out), most frequent first:
    // one bug can break many cases. Known findings are counted apart.
    let mut kinds: Vec<(String, usize)> = Vec::new();
    let mut known_seen: Vec<(&Known, usize)> = KNOWN
        .iter()
        .filter(|k| k.command == name)
        .map(|k| (k, 0))
        .collect();
    for (i, r) in &results {
        if only.is_none() && !show_all && r.is_ok() {
            continue;
        }
        let c = case(*i);
        let why = match r {
            Ok((o, t)) => format!("{o:?} in {:.2} s", t.as_secs_f64()),
            Err(why) => why.clone(),
        };
        let changes = c.changes.join("; ");
        let known = match r {
            Err(why) => known_seen
                .iter_mut()
                .find(|(k, _)| (k.matches)(why, &changes))
                .map(|(k, n)| {
                    *n += 1;
                    k.id
                }),
            Ok(_) => None,
        };
        let dir = keep.join(format!("case-{i}"));
        if r.is_err() || only.is_some() {
            let _ = std::fs::remove_dir_all(&dir);
            let _ = std::fs::create_dir_all(dir.join("in"));
            let _ = write_inputs(&c, &dir.join("in"));
            let _ = std::fs::write(dir.join("command"), c.shown() + "\n");
        }
        let report = format!(
            "case {i}: {why}\n    changed: {changes}\n    {}\n    inputs: {}",
            c.shown(),
            dir.join("in").display()
        );
        match (r, known) {
            (Ok(_), _) => println!("{report}"),
            (Err(_), Some(id)) => println!("known finding {id}: {report}"),
            (Err(why), None) => {
                let k = signature(why);
                match kinds.iter_mut().find(|(s, _)| *s == k) {
                    Some((_, n)) => *n += 1,
                    None => kinds.push((k, 1)),
                }
                failures.push(report);
            }
        }
    }
    kinds.sort_by_key(|k| std::cmp::Reverse(k.1));
    let kinds: Vec<String> = kinds
        .iter()
        .map(|(k, n)| format!("  {n:>4} × {k}"))
        .collect();
    for (k, n) in &known_seen {
        println!("{name}: known finding {} ({}): {n} cases", k.id, k.what);
    }
    assert!(
        failures.is_empty(),
        "{name}: {} of {} cases broke a promise (rerun one with LIDARSIM_FUZZ_CASE=N):\n{}\n{}",
        failures.len(),
        results.len(),
        kinds.join("\n"),
        failures.join("\n")
    );
    // A known finding that the default run no longer meets has been fixed: its entry goes
    // (and its test in `findings` is no longer ignored).
    let default_run = seed == fuzz::SEED && fuzz::cases(n) == n && only.is_none();
    let gone: Vec<String> = known_seen
        .iter()
        .filter(|(k, n)| *n == 0 && k.always)
        .map(|(k, _)| format!("{} ({})", k.id, k.what))
        .collect();
    assert!(
        !default_run || gone.is_empty(),
        "{name}: known findings no longer met, fixed? Remove them from KNOWN and un-ignore their tests: {}",
        gone.join(", ")
    );
}

/// A bug the fuzz finds that is reported (FUZZ_FINDINGS.md) and left to its owner: a failing
/// case that `matches` (its reason, its changes) is counted, not failed, until it is fixed.
struct Known {
    command: &'static str,
    id: &'static str,
    what: &'static str,
    matches: fn(&str, &str) -> bool,
    /// Whether every default run meets it: not one met through the time limit (a fast machine
    /// may finish the case) or with the "tests only" files of ../shared (absent on some
    /// machines); only then does its absence mean it is fixed.
    always: bool,
}

const KNOWN: &[Known] = &[];

// ---------------------------------------------------------------------------------------------
// Inputs the templates start from.

fn arg(flag: &'static str, value: Option<Value>) -> Arg {
    Arg {
        flag,
        value,
        joined: false,
    }
}

fn num(flag: &'static str, v: &str) -> Arg {
    arg(flag, Some(Value::Num(v.into())))
}

/// `flag=v`: a list whose first number may be negative (clap takes `-1,1` for a flag).
fn num_joined(flag: &'static str, v: &str) -> Arg {
    Arg {
        joined: true,
        ..num(flag, v)
    }
}

fn word(flag: &'static str, v: &str) -> Arg {
    arg(flag, Some(Value::Word(v.into())))
}

fn input(flag: &'static str, name: &'static str) -> Arg {
    arg(flag, Some(Value::In(name)))
}

fn out(flag: &'static str, name: &'static str) -> Arg {
    arg(flag, Some(Value::Out(name)))
}

fn flag(flag: &'static str) -> Arg {
    arg(flag, None)
}

fn text_file(name: &'static str, text: &str, format: Format) -> Input {
    Input {
        name,
        bytes: text.as_bytes().to_vec(),
        kind: Kind::Text(format),
    }
}

fn read(relative: &str) -> String {
    std::fs::read_to_string(project_root().join(relative))
        .unwrap_or_else(|e| panic!("{relative}: {e}"))
}

/// A shipped scene with its relative paths made absolute (as the scene fuzz does), so that it
/// can be written anywhere.
fn scene(name: &str) -> String {
    absolute_paths(&read(&format!("scenes/{name}")))
}

/// Files made once by the binary for the templates: profile sets and a covariance written by
/// `profiles generate`, shard files of `run`, `dial` and `select-lines`, the plain estimate of
/// `bench --write-plain`. Kept for the test process's lifetime (the merges read their scenes
/// by absolute path).
struct Fixtures {
    dir: PathBuf,
}

impl Fixtures {
    fn get() -> &'static Fixtures {
        static F: OnceLock<Fixtures> = OnceLock::new();
        F.get_or_init(|| {
            // One directory per test process (cargo-nextest runs each test in its own), under
            // target/tmp; those of earlier processes are removed.
            let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz_cli");
            let mine = format!("fixtures-{}", std::process::id());
            for e in std::fs::read_dir(&base).into_iter().flatten().flatten() {
                let old = e.file_name().to_string_lossy().into_owned();
                let stale = e
                    .metadata()
                    .and_then(|m| m.modified())
                    .ok()
                    .and_then(|t| t.elapsed().ok())
                    .is_some_and(|age| age > Duration::from_secs(3600));
                if old.starts_with("fixtures-") && old != mine && stale {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
            let dir = base.join(mine);
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).expect("a fixture directory");
            let d = |p: &str| dir.join(p).to_string_lossy().into_owned();
            let ok = |args: &[&str]| {
                lidarsim_ok(args);
            };
            for (class, seed, out) in [
                ("tropical", "1", "set.csv"),
                ("mid", "2", "forecast.csv"),
                ("mid", "3", "analysis.csv"),
            ] {
                ok(&[
                    "profiles",
                    "generate",
                    "--class",
                    class,
                    "--n",
                    "2",
                    "--seed",
                    seed,
                    "--out",
                    &d(out),
                    "--covariance-out",
                    &d(&format!("cov-{out}")),
                ]);
            }
            // A run shard set of a small scene (4 batches, 2 fields of view, 5 gates).
            std::fs::write(dir.join("mini.toml"), MINI_SCENE).unwrap();
            std::fs::write(dir.join("study.toml"), scene("study_co2_ipda.toml")).unwrap();
            for s in ["0/2", "1/2"] {
                ok(&[
                    "run",
                    &d("mini.toml"),
                    "--shard",
                    s,
                    // Given: shards run with the scene's own photons do not merge (finding).
                    "--photons",
                    "400",
                    "--out",
                    &d("run_shards"),
                    "--threads",
                    "1",
                ]);
                ok(&[
                    "dial",
                    &d("study.toml"),
                    "--ensemble",
                    "2",
                    "--class",
                    "tropical",
                    "--shard",
                    s,
                    "--threads",
                    "1",
                    "--out",
                    &d("dial_shards"),
                ]);
                ok(&[
                    "select-lines",
                    "--ensemble",
                    "2",
                    "--class",
                    "tropical",
                    "--on-cm1",
                    "6360.04",
                    "--off-cm1",
                    "6360.61",
                    "--co2-ppm",
                    "420",
                    "--top-km",
                    "30",
                    "--layer-m",
                    "1000",
                    "--shard",
                    s,
                    "--threads",
                    "1",
                    "--no-plots",
                    "--out",
                    &d("select_shards"),
                ]);
            }
            // A phase table and a matrix table of a small-particle aerosol, every 2° (enough
            // for its smooth phase function; a few hundred numbers for the mutator).
            ok(&[
                "mie",
                "--distribution",
                "lognormal",
                "--refractive-index",
                "1.5+0.01i",
                "--wavelength-nm",
                "1064",
                "--median-radius-um",
                "0.3",
                "--sigma-g",
                "1.6",
                "--out",
                &d("phase_full.txt"),
                "--matrix-out",
                &d("matrix_full.txt"),
            ]);
            for name in ["phase", "matrix"] {
                let full = std::fs::read_to_string(dir.join(format!("{name}_full.txt"))).unwrap();
                let thin: String = full
                    .lines()
                    .filter(|l| {
                        l.split(',')
                            .next()
                            .and_then(|t| t.parse::<f64>().ok())
                            .is_none_or(|t| t % 2.0 == 0.0)
                    })
                    .map(|l| format!("{l}\n"))
                    .collect();
                std::fs::write(dir.join(format!("{name}.txt")), thin).unwrap();
                let _ = std::fs::remove_file(dir.join(format!("{name}_full.txt")));
            }
            ok(&[
                "bench",
                "--write-plain",
                &d("plain.csv"),
                "--photons",
                "2000",
                "--threads",
                "1",
                "--batches",
                "10",
            ]);
            Fixtures { dir }
        })
    }

    fn text(&self, name: &str) -> String {
        std::fs::read_to_string(self.dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
    }

    fn bytes(&self, name: &str) -> Vec<u8> {
        std::fs::read(self.dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
    }
}

/// C.1, small: 2 fields of view, 5 gates, 3 orders, 400 photons in 4 batches (the shards of
/// the merge fuzz: a few kilobytes each).
const MINI_SCENE: &str = r#"description = "C.1, small: the merge fuzz's shards"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 5.0]

[[channel]]
name = "1064"
wavelength_nm = 1064.0

[gates]
start_m = 1000.0
end_m = 1100.0
width_m = 20.0

[[layer]]
name = "C.1 cloud"
base_m = 1000.0
top_m = 1300.0
extinction_per_km = 17.23
single_scattering_albedo = 0.999908
phase = { kind = "table", builtin = "bissonnette_c1_1064nm" }

[simulation]
photons = 400
batches = 4
seed = 1
max_order = 3
"#;

// ---------------------------------------------------------------------------------------------
// The subcommands.

/// Every profile set, covariance, phase and matrix table, and gas optical-depth table a case
/// wrote reads back with lidarsim's own reader.
fn reads_back(_: &Case, work: &Path) -> Result<(), String> {
    use lidarsim::atmosphere::covariance::Covariance;
    use lidarsim::particles::matrix_table::MatrixTable;
    use lidarsim::particles::table::PhaseTable;
    for rel in tree(work) {
        let p = work.join(&rel);
        let name = rel.to_string_lossy();
        let r = if name.starts_with("set") && name.ends_with(".csv") {
            lidarsim::atmosphere::read_profile_set(&p).map(|_| ())
        } else if name.starts_with("cov") {
            Covariance::read(&p).map(|_| ())
        } else if name.starts_with("phase") {
            PhaseTable::read(&p).map(|_| ())
        } else if name.starts_with("matrix") {
            MatrixTable::read(&p).map(|_| ())
        } else if name.ends_with(".bin") {
            lidarsim::spectroscopy::GasOpticalDepthTable::load(&p)
                .map(|_| ())
                .map_err(|e| lidarsim::input::InputError::file(&p, e.to_string()))
        } else {
            continue;
        };
        r.map_err(|e| format!("lidarsim cannot read back what it wrote: {e}"))?;
    }
    Ok(())
}

const LBL_GROUPS: &[&[&str]] = &[
    &["--start-cm1", "--end-cm1", "--step-cm1", "--wing-cm1"],
    &[
        "--sensor-altitude-m",
        "--zenith-deg",
        "--surface-altitude-m",
        "--layer-m",
    ],
];

/// `lbl` rows (wavenumbers × layers) above this are valid but large work.
const LBL_ROWS: f64 = 2e5;

fn lbl_too_large(c: &Case) -> bool {
    let start = c.num_or("--start-cm1", 6359.0);
    let end = c.num_or("--end-cm1", 6361.0);
    let step = c.num_or("--step-cm1", 0.01);
    let layers = if c.text("--zenith-deg").is_some() {
        let top = c.num_or("--sensor-altitude-m", 8000.0).abs().min(1.2e5);
        (top / c.num_or("--layer-m", 1000.0).abs().max(1e-9)).max(1.0)
    } else {
        1.0
    };
    step > 0.0 && ((end - start) / step).abs() * layers > LBL_ROWS
}

fn lbl_templates() -> Vec<Template> {
    let base = |args: Vec<Arg>, inputs: Vec<Input>| Template {
        command: &["lbl"],
        args,
        inputs,
        groups: LBL_GROUPS,
        too_large: lbl_too_large,
        after: reads_back,
    };
    let grid = |a: &str, b: &str, s: &str| {
        vec![
            num("--start-cm1", a),
            num("--end-cm1", b),
            num("--step-cm1", s),
            num("--wing-cm1", "25"),
        ]
    };
    let afgl = read("data/afgl/afgl_tropical.csv");
    vec![
        // Cross-sections of the built-in band model.
        base(
            [
                vec![
                    num("--pressure-atm", "1"),
                    num("--temperature-k", "296"),
                    num("--vmr", "0.0004"),
                    out("--out", "x.csv"),
                ],
                grid("6359", "6361", "0.01"),
            ]
            .concat(),
            vec![],
        ),
        // Of a HITRAN file, with a figure.
        base(
            [
                vec![
                    input("--lines", "lines.par"),
                    num("--pressure-atm", "0.5"),
                    num("--temperature-k", "250"),
                    out("--out", "x.csv"),
                    out("--plot", "x.png"),
                ],
                grid("6355", "6365", "0.02"),
            ]
            .concat(),
            vec![text_file("lines.par", fuzz::PAR, Format::Par)],
        ),
        // Of a CSV list with the Hartmann-Tran profile and line mixing.
        base(
            [
                vec![
                    input("--lines", "lines.csv"),
                    word("--line-shape", "ht"),
                    flag("--line-mixing"),
                    num("--pressure-atm", "1"),
                    num("--temperature-k", "296"),
                    num("--vmr", "0.01"),
                    out("--out", "x.csv"),
                ],
                grid("6316", "6320", "0.01"),
            ]
            .concat(),
            vec![text_file("lines.csv", fuzz::LINES_HT, Format::Csv)],
        ),
        // Layer optical depths through an AFGL atmosphere, the table saved.
        base(
            [
                vec![
                    word("--atmosphere", "us_standard"),
                    num("--co2-ppmv", "420"),
                    num("--sensor-altitude-m", "8000"),
                    num("--zenith-deg", "180"),
                    num("--surface-altitude-m", "0"),
                    num("--layer-m", "1000"),
                    out("--out", "t.csv"),
                    out("--save-table", "t.bin"),
                ],
                grid("6359.5", "6360.5", "0.01"),
            ]
            .concat(),
            vec![],
        ),
        // Through a profile file, looking up, with a Voigt CSV list.
        base(
            [
                vec![
                    input("--lines", "lines.csv"),
                    input("--profile", "afgl.csv"),
                    num("--sensor-altitude-m", "500"),
                    num("--zenith-deg", "30"),
                    num("--layer-m", "2000"),
                    out("--out", "t.csv"),
                    out("--plot", "t.png"),
                ],
                grid("6359", "6361", "0.02"),
            ]
            .concat(),
            vec![
                text_file("lines.csv", fuzz::LINES_VOIGT, Format::Csv),
                text_file("afgl.csv", &afgl, Format::Csv),
            ],
        ),
    ]
}

/// Profiles of a generated ensemble above this are valid but large work.
fn profiles_too_large(c: &Case) -> bool {
    c.num_or("--n", 1.0) > 20.0
}

fn profiles_templates() -> Vec<Template> {
    let f = Fixtures::get();
    let set = f.text("set.csv");
    let base = |command, args, inputs| Template {
        command,
        args,
        inputs,
        // A profile id not in the set: the set is named.
        groups: &[&["--profile-id", "set.csv"]],
        too_large: profiles_too_large,
        after: reads_back,
    };
    let mut t = vec![
        // The AFGL class mean with the representative error model, the covariance written.
        base(
            &["profiles", "generate"],
            vec![
                word("--class", "tropical"),
                num("--n", "3"),
                num("--seed", "1"),
                num("--co2-ppm", "410"),
                num("--max-rh-percent", "100"),
                word("--rh-over", "ice"),
                out("--out", "set.csv"),
                out("--covariance-out", "cov.csv"),
            ],
            vec![],
        ),
        // Around the mean of a set, with an error-model file and every error-model option.
        base(
            &["profiles", "generate"],
            vec![
                input("--set", "set.csv"),
                num("--n", "2"),
                num("--seed", "7"),
                input("--error-model", "error.csv"),
                num("--t-corr-length", "0.35"),
                num("--q-corr-length", "0.25"),
                num("--ps-std-hpa", "0.7"),
                num("--co2-std-ppm", "1"),
                num("--co2-corr-length", "0.35"),
                flag("--no-class-scaling"),
                out("--out", "set.csv"),
            ],
            vec![
                text_file("set.csv", &set, Format::Csv),
                text_file(
                    "error.csv",
                    &read("data/nwp_error/bg_error_representative.csv"),
                    Format::Csv,
                ),
            ],
        ),
        // One profile of a set with a covariance file.
        base(
            &["profiles", "generate"],
            vec![
                input("--mean-profile", "set.csv"),
                word("--profile-id", "tropical-0002"),
                input("--covariance", "cov.csv"),
                num("--n", "2"),
                num("--seed", "3"),
                flag("--repair-covariance"),
                out("--out", "set.csv"),
            ],
            vec![
                text_file("set.csv", &set, Format::Csv),
                text_file("cov.csv", &f.text("cov-set.csv"), Format::Csv),
            ],
        ),
        // From forecast and analysis pairs.
        base(
            &["profiles", "generate"],
            vec![
                input("--pairs", "forecast.csv"),
                input("", "analysis.csv"),
                num("--localization-lnp", "1"),
                input("--set", "forecast.csv"),
                num("--n", "2"),
                num("--seed", "5"),
                flag("--repair-covariance"),
                out("--out", "set.csv"),
            ],
            vec![
                text_file("forecast.csv", &f.text("forecast.csv"), Format::Csv),
                text_file("analysis.csv", &f.text("analysis.csv"), Format::Csv),
            ],
        ),
        base(
            &["profiles", "info"],
            vec![input("", "set.csv")],
            vec![text_file("set.csv", fuzz::PROFILES_A, Format::Csv)],
        ),
        base(
            &["profiles", "info"],
            vec![input("", "set.csv")],
            vec![text_file("set.csv", fuzz::PROFILES_B, Format::Csv)],
        ),
        base(
            &["profiles", "plot"],
            vec![
                input("", "set.csv"),
                out("--out", "p.png"),
                num("--top-hpa", "10"),
            ],
            vec![text_file("set.csv", &set, Format::Csv)],
        ),
    ];
    // `profiles convert` of the first profiles of the "tests only" sets.
    for (format, levels, meta, key) in [
        (
            "ecmwf83",
            "data/profiles/ecmwf83_matricardi2008_101L.csv",
            "data/profiles/ecmwf83_matricardi2008_meta.csv",
            2,
        ),
        (
            "ecmwf52",
            "data/profiles/ecmwf52_chevallier_101L.csv",
            "data/profiles/ecmwf52_chevallier_meta.csv",
            2,
        ),
        (
            "rfmip",
            "data/profiles/rfmip_era_interim_100sites_layers.csv",
            "data/profiles/rfmip_era_interim_100sites_meta.csv",
            1,
        ),
    ] {
        let (Some(l), Some(m)) = (
            crate::util::shared_file(levels),
            crate::util::shared_file(meta),
        ) else {
            continue;
        };
        let first = |p: &Path| {
            // Comments, the header, and the rows of the first two profiles (sites 0 and 1).
            let keep = |row: &str| {
                row.split(',')
                    .next()
                    .and_then(|id| id.trim().parse::<u32>().ok())
                    .is_some_and(|id| id < key + 1 && id + 1 >= key)
            };
            let text = std::fs::read_to_string(p).unwrap();
            let mut out = String::new();
            for (n, row) in text.lines().enumerate() {
                let header = !row.starts_with('#')
                    && row
                        .split(',')
                        .next()
                        .is_some_and(|f| f.parse::<u32>().is_err());
                if row.starts_with('#') || header || n == 0 || keep(row) {
                    out.push_str(row);
                    out.push('\n');
                }
            }
            out
        };
        t.push(base(
            &["profiles", "convert"],
            vec![
                word("--format", format),
                input("--levels", "levels.csv"),
                input("--meta", "meta.csv"),
                out("--out", "set.csv"),
            ],
            vec![
                text_file("levels.csv", &first(&l), Format::Csv),
                text_file("meta.csv", &first(&m), Format::Csv),
            ],
        ));
    }
    t
}

fn mie_templates() -> Vec<Template> {
    let base = |args| Template {
        command: &["mie"],
        args,
        inputs: vec![],
        groups: &[],
        too_large: never,
        after: reads_back,
    };
    vec![
        base(vec![
            word("--refractive-index", "1.33+0.01i"),
            num("--size-parameter", "10"),
            num("--angles-deg", "0,90,180"),
        ]),
        base(vec![
            word("--distribution", "lognormal"),
            word("--refractive-index", "1.45+0.001i"),
            num("--wavelength-nm", "532"),
            num("--number-density-per-cm3", "100"),
            num("--median-radius-um", "0.1"),
            num("--sigma-g", "1.5"),
            num("--tail-fraction", "1e-5"),
            num("--rel-tol", "1e-3"),
            out("--out", "phase.txt"),
            out("--matrix-out", "matrix.txt"),
            word("--meta", "origin=fuzz, \"quoted\""),
        ]),
        base(vec![
            word("--distribution", "lognormal"),
            word("--refractive-index", "1.5+0.01i"),
            num("--wavelength-nm", "1064"),
            num("--mode", "100,0.05,1.6"),
            num("--mode", "1,0.5,2"),
            num("--r-min-um", "0.01"),
            num("--r-max-um", "5"),
            out("--out", "phase.txt"),
        ]),
        base(vec![
            word("--distribution", "modified-gamma"),
            word("--refractive-index", "1.33+1e-6i"),
            num("--wavelength-nm", "10000"),
            num("--a", "2.373"),
            num("--alpha", "6"),
            num("--b", "1.5"),
            num("--gamma", "1"),
            num("--r-max-um", "20"),
            out("--matrix-out", "matrix.txt"),
        ]),
        base(vec![
            word("--distribution", "opac"),
            word("--aerosol-type", "continental-clean"),
            num("--wavelength-nm", "1064"),
            out("--out", "phase.txt"),
        ]),
    ]
}

/// Photons per profile and profiles per class above these are valid but large work (threads
/// beyond the cores are capped since finding F9, `findings::f9_…`, so any count is run).
fn dial_too_large(c: &Case) -> bool {
    c.num_or("--photons", 0.0) > 500.0 || c.num_or("--ensemble", 2.0) > 4.0
}

/// A study that ran has at least one profile that did not fail (item 5: a study where every
/// profile failed exits non-zero).
fn some_profile_ran(_: &Case, work: &Path) -> Result<(), String> {
    let p = work.join("d/profiles.csv");
    if !p.is_file() {
        return Ok(()); // a shard
    }
    let text = std::fs::read_to_string(&p).map_err(|e| e.to_string())?;
    let rows = check_csv_text("profiles.csv", &text)?;
    if rows == 0 {
        let failed = std::fs::read_to_string(work.join("d/failed.csv")).unwrap_or_default();
        return Err(format!(
            "every profile failed and the study exited 0 (failed.csv: {})",
            short(&failed)
        ));
    }
    Ok(())
}

const BUDGET: &[&[&str]] = &[&["--ensemble", "--class", "--profiles"]];

fn dial_templates() -> Vec<Template> {
    let f = Fixtures::get();
    let base = |args, inputs| Template {
        command: &["dial"],
        args,
        inputs,
        groups: BUDGET,
        too_large: dial_too_large,
        after: some_profile_ran,
    };
    let study = || text_file("scene.toml", &scene("study_co2_ipda.toml"), Format::Toml);
    let budget = || {
        vec![
            num("--budget-temperature-k", "1"),
            num("--budget-humidity-percent", "10"),
            num("--budget-surface-pressure-hpa", "1"),
            num("--budget-frequency-offset-mhz", "1"),
            num("--budget-linewidth-percent", "10"),
        ]
    };
    vec![
        // A generated ensemble of one class, every budget option.
        base(
            [
                vec![
                    input("", "scene.toml"),
                    num("--ensemble", "2"),
                    word("--class", "tropical"),
                    num("--seed", "4"),
                    num("--threads", "1"),
                    word("--on", "R16e+2.2GHz,R26e+1.2GHz"),
                    flag("--no-plots"),
                    out("--out", "d"),
                ],
                budget(),
            ]
            .concat(),
            vec![study()],
        ),
        // A profile set file, with the figures.
        base(
            vec![
                input("", "scene.toml"),
                input("--profiles", "set.csv"),
                word("--class", "all"),
                num("--threads", "1"),
                out("--out", "d"),
            ],
            vec![
                study(),
                text_file("set.csv", &f.text("set.csv"), Format::Csv),
            ],
        ),
        // A scene with particle layers: the Monte Carlo per profile.
        base(
            [
                vec![
                    input("", "scene.toml"),
                    num("--ensemble", "2"),
                    word("--class", "mid"),
                    num("--photons", "200"),
                    num("--threads", "1"),
                    flag("--no-plots"),
                    flag("--no-netcdf"),
                    out("--out", "d"),
                ],
                budget(),
            ]
            .concat(),
            vec![text_file(
                "scene.toml",
                &scene("airborne_co2_dial.toml"),
                Format::Toml,
            )],
        ),
        // One shard of a study.
        base(
            vec![
                input("", "scene.toml"),
                num("--ensemble", "2"),
                word("--class", "high"),
                num("--threads", "1"),
                word("--shard", "1/2"),
                out("--out", "d"),
            ],
            vec![study()],
        ),
    ]
}

/// Layers of the select-lines grid and on-line positions above these are valid but large
/// work (threads beyond the cores are capped since finding F9, so any count is run).
fn select_too_large(c: &Case) -> bool {
    let layers = c.num_or("--top-km", 30.0) * 1e3 / c.num_or("--layer-m", 1000.0).abs().max(1e-9);
    let positions = match c.text("--on-cm1") {
        Some(list) => list.split(',').count() as f64,
        None => {
            (c.num_or("--max-j", 4.0) + 1.0)
                * c.text("--offsets-ghz").map_or(13, |l| l.split(',').count()) as f64
        }
    };
    layers > 2000.0 || layers * positions > 2e4 || c.num_or("--ensemble", 2.0) > 4.0
}

fn select_templates() -> Vec<Template> {
    let f = Fixtures::get();
    let base = |args, inputs| Template {
        command: &["select-lines"],
        args,
        inputs,
        groups: &[],
        too_large: select_too_large,
        after: nothing,
    };
    let common = || {
        vec![
            num("--off-cm1", "6360.61"),
            num("--co2-ppm", "420"),
            num("--top-km", "30"),
            num("--layer-m", "1000"),
            num("--wing-cm1", "25"),
            num("--threads", "1"),
            out("--out", "s"),
        ]
    };
    vec![
        // AFGL atmospheres, two on-lines, every uncertainty option.
        base(
            [
                vec![
                    word("--atmosphere", "tropical,us_standard"),
                    num("--temperature-uncertainty-k", "1"),
                    num("--frequency-uncertainty-mhz", "1"),
                    num("--surface-pressure-uncertainty-hpa", "1"),
                    num("--h2o-uncertainty-percent", "10"),
                    flag("--no-plots"),
                ],
                vec![num("--on-cm1", "6360.04,6359.98")],
                common(),
            ]
            .concat(),
            vec![],
        ),
        // A scan of the band's lines near the centre, with the figures.
        base(
            [
                vec![
                    word("--atmosphere", "midlatitude_summer"),
                    num("--max-j", "2"),
                    num_joined("--offsets-ghz", "-1,0.5"),
                    word("--figure-lines", "R2e"),
                ],
                common(),
            ]
            .concat(),
            vec![],
        ),
        // A profile set, per profile, with a HITRAN file and a scene for the random error.
        base(
            [
                vec![
                    input("--profiles", "set.csv"),
                    flag("--per-profile"),
                    word("--class", "all"),
                    input("--lines", "lines.par"),
                    input("--scene", "scene.toml"),
                    flag("--no-plots"),
                ],
                vec![num("--on-cm1", "6359.967")],
                common(),
            ]
            .concat(),
            vec![
                text_file("set.csv", &f.text("set.csv"), Format::Csv),
                text_file("lines.par", fuzz::PAR, Format::Par),
                text_file(
                    "scene.toml",
                    &scene("spaceborne_co2_ipda.toml"),
                    Format::Toml,
                ),
            ],
        ),
        // A generated ensemble, one shard.
        base(
            [
                vec![
                    num("--ensemble", "2"),
                    num("--seed", "2"),
                    word("--class", "high"),
                    word("--shard", "0/2"),
                    flag("--no-plots"),
                ],
                vec![num("--on-cm1", "6360.04")],
                common(),
            ]
            .concat(),
            vec![],
        ),
    ]
}

/// A merge that ran: its summary's wall time is finite and non-negative (item 5).
fn merged_wall_time(_: &Case, work: &Path) -> Result<(), String> {
    wall_time_ok(&work.join("m/summary.json"))
}

/// A summary's wall time and threads (a run's, or a study's `timing_s.wall`) are finite and
/// non-negative.
fn wall_time_ok(p: &Path) -> Result<(), String> {
    let Ok(text) = std::fs::read_to_string(p) else {
        return Ok(());
    };
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    for key in ["wall_s", "threads"] {
        if let Some(x) = v.get(key).and_then(serde_json::Value::as_f64)
            && !(x >= 0.0 && x.is_finite())
        {
            return Err(format!("summary.json `{key}` = {x:e}"));
        }
    }
    if let Some(w) = v
        .pointer("/timing_s/wall")
        .and_then(serde_json::Value::as_f64)
        && w < 0.0
    {
        return Err(format!("summary.json `timing_s.wall` = {w}"));
    }
    Ok(())
}

fn merge_templates() -> Vec<Template> {
    let f = Fixtures::get();
    let shards = |dir: &str| -> Vec<Input> {
        let names = file_names(&f.dir.join(dir));
        assert_eq!(names.len(), 2, "{dir}: {names:?}");
        names
            .iter()
            .zip(["shards/shard-0-of-2.lshard", "shards/shard-1-of-2.lshard"])
            .map(|(n, as_name)| Input {
                name: as_name,
                bytes: f.bytes(&format!("{dir}/{n}")),
                kind: Kind::Shard,
            })
            .collect()
    };
    let base = |inputs, no_plots: bool| Template {
        command: &["merge"],
        args: [
            vec![input("", "shards"), out("--out", "m")],
            if no_plots {
                vec![flag("--no-plots")]
            } else {
                vec![]
            },
        ]
        .concat(),
        inputs,
        groups: &[],
        too_large: never,
        after: merged_wall_time,
    };
    vec![
        base(shards("run_shards"), false),
        base(shards("run_shards"), true),
        base(shards("dial_shards"), true),
        base(shards("select_shards"), true),
    ]
}

/// Two layers of the small C.1 scene, one with a phase table and one with a matrix table,
/// both files beside the scene.
fn tables_scene() -> String {
    MINI_SCENE
        .replace(
            "[[layer]]\nname = \"C.1 cloud\"\nbase_m = 1000.0\ntop_m = 1300.0",
            "[[layer]]\nname = \"aerosol, matrix\"\nbase_m = 1000.0\ntop_m = 1150.0\n\
         extinction_per_km = 0.5\nsingle_scattering_albedo = 0.95\n\
         phase = { kind = \"matrix_table\", file = \"matrix.txt\" }\n\n\
         [[layer]]\nname = \"aerosol, table\"\nbase_m = 1150.0\ntop_m = 1300.0",
        )
        .replace(
            "phase = { kind = \"table\", builtin = \"bissonnette_c1_1064nm\" }",
            "phase = { kind = \"table\", file = \"phase.txt\" }",
        )
}

/// Photons above this, and threads beyond 8, are valid but large work.
fn run_too_large(c: &Case) -> bool {
    c.num_or("--photons", 400.0) > 4000.0 || c.num_or("--threads", 1.0) > 8.0
}

/// `run`'s options (its scenes are fuzzed by `tests/fuzz.rs`), a scene's phase and matrix
/// tables, a shard.
fn run_templates() -> Vec<Template> {
    let f = Fixtures::get();
    let base = |args, inputs| Template {
        command: &["run"],
        args,
        inputs,
        groups: &[],
        too_large: run_too_large,
        after: nothing,
    };
    vec![
        base(
            vec![
                input("", "scene.toml"),
                num("--photons", "400"),
                num("--seed", "3"),
                num("--threads", "1"),
                num("--ddis-epsilon", "0.1"),
                flag("--no-plots"),
                out("--out", "o"),
            ],
            vec![
                text_file("scene.toml", &tables_scene(), Format::Toml),
                text_file("phase.txt", &f.text("phase.txt"), Format::Csv),
                text_file("matrix.txt", &f.text("matrix.txt"), Format::Csv),
            ],
        ),
        base(
            vec![
                input("", "scene.toml"),
                word("--shard", "1/2"),
                num("--photons", "400"),
                num("--threads", "1"),
                out("--out", "o"),
            ],
            vec![text_file("scene.toml", MINI_SCENE, Format::Toml)],
        ),
        // The default scene, with its figures.
        base(
            vec![
                num("--photons", "1000"),
                num("--seed", "2"),
                num("--threads", "2"),
                flag("--no-netcdf"),
                out("--out", "o"),
            ],
            vec![],
        ),
    ]
}

fn bench_too_large(c: &Case) -> bool {
    c.num_or("--photons", 1e6) > 4000.0
        || c.num_or("--repeat", 3.0) > 2.0
        || c.num_or("--study", 1.0) > 1.0
        || c.num_or("--seeds", 3.0) > 4.0
}

fn bench_templates() -> Vec<Template> {
    let f = Fixtures::get();
    let base = |args, inputs| Template {
        command: &["bench"],
        args,
        inputs,
        groups: &[],
        too_large: bench_too_large,
        after: nothing,
    };
    let method = || {
        vec![
            num("--batches", "10"),
            num("--ddis-epsilon", "0.1"),
            num("--range-stratification", "0.1"),
            num("--alignment-splitting", "1"),
            num("--roulette-alignment", "1"),
            word("--cone-estimate", "true"),
            word("--crossing-estimate", "false"),
            word("--ddis-crossing", "true"),
        ]
    };
    vec![
        base(
            [
                vec![
                    num("--photons", "2000"),
                    num("--threads", "1"),
                    num("--repeat", "1"),
                    num("--seed", "1"),
                    out("--json", "b.json"),
                ],
                method(),
            ]
            .concat(),
            vec![],
        ),
        base(
            vec![
                num("--study", "1"),
                num("--threads", "1"),
                num("--repeat", "1"),
            ],
            vec![],
        ),
        base(
            vec![
                input("--scenes", "mini.toml"),
                num("--threads", "1"),
                num("--repeat", "1"),
            ],
            vec![text_file("mini.toml", MINI_SCENE, Format::Toml)],
        ),
        base(
            [
                vec![
                    out("--depth", "depth"),
                    input("--plain", "plain.csv"),
                    num("--photons", "2000"),
                    num("--threads", "1"),
                    num("--repeat", "1"),
                ],
                method(),
            ]
            .concat(),
            vec![text_file("plain.csv", &f.text("plain.csv"), Format::Csv)],
        ),
        base(
            vec![
                out("--depth", "depth"),
                num("--seeds", "3"),
                num("--photons", "1000"),
                num("--threads", "1"),
                num("--batches", "10"),
            ],
            vec![],
        ),
        base(
            vec![
                out("--write-plain", "plain.csv"),
                num("--photons", "2000"),
                num("--threads", "1"),
                num("--batches", "10"),
            ],
            vec![],
        ),
    ]
}

// ---------------------------------------------------------------------------------------------
// The tests.

/// Every template, unchanged, runs (exit 0) and passes every check a case that ran owes: the
/// fuzz starts from valid invocations.
#[test]
fn every_template_runs_and_passes_the_checks() {
    let all: Vec<(&str, Vec<Template>)> = vec![
        ("run", run_templates()),
        ("lbl", lbl_templates()),
        ("profiles", profiles_templates()),
        ("mie", mie_templates()),
        ("dial", dial_templates()),
        ("select-lines", select_templates()),
        ("merge", merge_templates()),
        ("bench", bench_templates()),
    ];
    let mut failures = Vec::new();
    for (name, templates) in &all {
        for (i, t) in templates.iter().enumerate() {
            let c = Case {
                template: t.clone(),
                changes: vec![],
                culprits: vec![],
                line_break: false,
            };
            match run_case(&c) {
                Ok((Outcome::Ran, _)) => {}
                Ok((o, _)) => failures.push(format!("{name} template {i}: {o:?}: {}", c.shown())),
                Err(e) => match KNOWN
                    .iter()
                    .find(|k| k.command == *name && (k.matches)(&e, ""))
                {
                    Some(k) => println!("{name} template {i}: known finding {}: {e}", k.id),
                    None => failures.push(format!("{name} template {i}: {e}\n    {}", c.shown())),
                },
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn fuzz_run() {
    fuzz_subcommand("run", 8, 120, &run_templates());
}

#[test]
fn fuzz_lbl() {
    fuzz_subcommand("lbl", 1, 300, &lbl_templates());
}

#[test]
fn fuzz_profiles() {
    fuzz_subcommand("profiles", 2, 300, &profiles_templates());
}

#[test]
fn fuzz_mie() {
    fuzz_subcommand("mie", 3, 250, &mie_templates());
}

#[test]
fn fuzz_dial() {
    fuzz_subcommand("dial", 4, 120, &dial_templates());
}

#[test]
fn fuzz_select_lines() {
    fuzz_subcommand("select-lines", 5, 150, &select_templates());
}

#[test]
fn fuzz_merge() {
    fuzz_subcommand("merge", 6, 300, &merge_templates());
}

#[test]
fn fuzz_bench() {
    fuzz_subcommand("bench", 7, 120, &bench_templates());
}

mod findings {
    //! One test per bug the fuzz found (FUZZ_FINDINGS.md), ignored until its fix is merged:
    //! each fails now with the bug in its message and passes once it is fixed.

    use super::*;
    use crate::util::Bounded;

    /// `lidarsim args` in a fresh directory `dir` (outputs under it), bounded as a fuzz case.
    fn run_in(dir: &Path, args: &[&str]) -> Bounded {
        let args: Vec<OsString> = args.iter().map(OsString::from).collect();
        lidarsim_bounded(&args, dir, dir, TIME_LIMIT).unwrap()
    }

    fn study() -> String {
        project_root()
            .join("scenes/study_co2_ipda.toml")
            .to_string_lossy()
            .into_owned()
    }

    /// Exit 2, and the error names `what`.
    fn refused_naming(ran: &Bounded, what: &str) {
        assert!(
            ran.code == Some(2) && ran.stderr.contains(what),
            "exit {:?}, expected 2 naming {what}: {}",
            ran.code,
            short(&ran.stderr)
        );
    }

    #[test]
    fn f1_a_study_writes_no_nan() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "dial",
                &study(),
                "--ensemble",
                "2",
                "--class",
                "tropical",
                "--no-plots",
                "--threads",
                "1",
                "--out",
                "d",
            ],
        );
        assert_eq!(ran.code, Some(0), "{}", ran.stderr);
        check_written(dir.path()).unwrap();
    }

    #[test]
    fn f2_a_study_where_every_profile_failed_exits_2() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("set.csv"), fuzz::PROFILES_A).unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "dial",
                &study(),
                "--profiles",
                "set.csv",
                "--no-plots",
                "--out",
                "d",
            ],
        );
        refused_naming(&ran, "set.csv");
    }

    #[test]
    fn f4_bench_depth_writes_no_inf() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "bench",
                "--depth",
                "d",
                "--photons",
                "2000",
                "--threads",
                "1",
                "--repeat",
                "1",
                "--batches",
                "10",
            ],
        );
        assert_eq!(ran.code, Some(0), "{}", ran.stderr);
        check_written(dir.path()).unwrap();
    }

    #[test]
    fn f6_mie_names_its_options() {
        let dir = tempfile::tempdir().unwrap();
        let base = [
            "mie",
            "--distribution",
            "lognormal",
            "--refractive-index",
            "1.45+0.001i",
            "--median-radius-um",
            "0.1",
            "--sigma-g",
            "1.5",
        ];
        let ran = run_in(dir.path(), &[&base[..], &["--wavelength-nm", "1"]].concat());
        refused_naming(&ran, "--wavelength-nm");
        let ran = run_in(
            dir.path(),
            &[
                &base[..],
                &[
                    "--wavelength-nm",
                    "532",
                    "--r-min-um",
                    "10",
                    "--r-max-um",
                    "5",
                ],
            ]
            .concat(),
        );
        refused_naming(&ran, "--r-");
    }

    /// The first two RFMIP sites of ../shared, the meta file changed by `edit`.
    fn rfmip(dir: &Path, edit: impl Fn(&str) -> String) -> Option<Bounded> {
        let levels =
            crate::util::shared_file("data/profiles/rfmip_era_interim_100sites_layers.csv")?;
        let meta = crate::util::shared_file("data/profiles/rfmip_era_interim_100sites_meta.csv")?;
        let first = |p: &Path| {
            std::fs::read_to_string(p)
                .unwrap()
                .lines()
                .filter(|l| {
                    l.split(',')
                        .next()
                        .is_none_or(|id| id.parse::<u32>().map_or(true, |id| id < 2))
                })
                .map(|l| format!("{l}\n"))
                .collect::<String>()
        };
        std::fs::write(dir.join("levels.csv"), first(&levels)).unwrap();
        std::fs::write(dir.join("meta.csv"), edit(&first(&meta))).unwrap();
        Some(run_in(
            dir,
            &[
                "profiles",
                "convert",
                "--format",
                "rfmip",
                "--levels",
                "levels.csv",
                "--meta",
                "meta.csv",
                "--out",
                "set.csv",
            ],
        ))
    }

    #[test]
    fn f7_rfmip_meta_errors_name_the_meta_file() {
        let dir = tempfile::tempdir().unwrap();
        let Some(ok) = rfmip(dir.path(), str::to_string) else {
            return;
        };
        assert_eq!(ok.code, Some(0), "{}", ok.stderr);
        let o2 = rfmip(dir.path(), |t| t.replace("O2=0.209", "O2=2.09e29")).unwrap();
        refused_naming(&o2, "meta.csv");
        // Site 1's row given site 0's id.
        let twice = rfmip(dir.path(), |t| t.replace("\n1,", "\n0,")).unwrap();
        refused_naming(&twice, "meta.csv");
    }

    #[test]
    fn f8_class_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "dial",
                &study(),
                "--ensemble",
                "2",
                "--class",
                "a",
                "--out",
                "d",
            ],
        );
        refused_naming(&ran, "--class");
        let ran = run_in(
            dir.path(),
            &[
                "select-lines",
                "--ensemble",
                "2",
                "--class",
                "a",
                "--off-cm1",
                "6360.61",
                "--co2-ppm",
                "420",
                "--out",
                "s",
            ],
        );
        refused_naming(&ran, "--class");
    }

    #[test]
    fn f9_threads_beyond_the_work_cost_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "dial",
                &study(),
                "--ensemble",
                "2",
                "--class",
                "high",
                "--threads",
                "1000",
                "--no-plots",
                "--out",
                "d",
            ],
        );
        // One thread takes 0.2 s.
        assert!(
            ran.took < Duration::from_secs(5),
            "exit {:?} after {:?}",
            ran.code,
            ran.took
        );
    }

    #[test]
    fn f11_a_damaged_scene_in_a_shard_names_the_shard() {
        let f = Fixtures::get();
        let dir = tempfile::tempdir().unwrap();
        let shards = dir.path().join("shards");
        std::fs::create_dir(&shards).unwrap();
        let mut names: Vec<PathBuf> = std::fs::read_dir(f.dir.join("dial_shards"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        // The merge reads the scene from the first shard.
        std::fs::copy(&names[1], shards.join("shard-1-of-2.lshard")).unwrap();
        let good = std::fs::read(&names[0]).unwrap();
        let (mut h, _) = shard_header(&good).unwrap();
        let text = h["scene_text"]
            .as_str()
            .unwrap()
            .replace("seed = 1", "seed = 01");
        h["scene_text"] = text.into();
        std::fs::write(
            shards.join("shard-0-of-2.lshard"),
            with_shard_header(&good, &h),
        )
        .unwrap();
        let ran = run_in(dir.path(), &["merge", "shards", "--out", "m"]);
        refused_naming(&ran, "shard-0-of-2.lshard");
    }

    #[test]
    fn f13_cross_sections_are_never_negative() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "lbl",
                "--pressure-atm",
                "1",
                "--temperature-k",
                "296",
                "--vmr",
                "0.0004",
                "--start-cm1",
                "6359",
                "--end-cm1",
                "6961",
                "--step-cm1",
                "0.01",
                "--out",
                "x.csv",
            ],
        );
        assert_eq!(ran.code, Some(0), "{}", ran.stderr);
        check_written(dir.path()).unwrap();
    }

    #[test]
    fn f14_a_tiny_sphere_gives_finite_amplitudes_or_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "mie",
                "--refractive-index",
                "1.33+0.01i",
                "--size-parameter",
                "5e-324",
                "--angles-deg",
                "0,90,180",
            ],
        );
        match ran.code {
            Some(0) => crate::util::check_json_text("stdout", &ran.stdout).unwrap(),
            _ => refused_naming(&ran, "--size-parameter"),
        }
    }

    #[test]
    fn f15_an_option_without_its_value_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "mie",
                "--distribution",
                "lognormal",
                "--refractive-index",
                "--wavelength-nm",
                "1064",
                "--median-radius-um",
                "0.1",
                "--sigma-g",
                "1.5",
            ],
        );
        refused_naming(&ran, "--refractive-index");
    }

    #[test]
    fn f16_a_size_integration_without_contrast_ends() {
        let dir = tempfile::tempdir().unwrap();
        let ran = run_in(
            dir.path(),
            &[
                "mie",
                "--distribution",
                "lognormal",
                "--refractive-index",
                "1",
                "--wavelength-nm",
                "532",
                "--median-radius-um",
                "10",
                "--sigma-g",
                "1.5",
            ],
        );
        // With 1.45+0.001i it takes 0.3 s.
        assert!(
            ran.took < Duration::from_secs(5) && matches!(ran.code, Some(0 | 2)),
            "exit {:?} after {:?}",
            ran.code,
            ran.took
        );
    }

    /// FUZZ_FINDINGS.md F10 (issue item 5): a run shard whose tally or wall time is not finite or
    /// is negative, with its checksum recomputed, is refused naming the file; a tally of 1e300 J
    /// (beyond any pulse) is refused or gives finite outputs.
    #[test]
    fn merge_refuses_non_finite_and_negative_shard_numbers() {
        let f = Fixtures::get();
        let mut names: Vec<PathBuf> = std::fs::read_dir(f.dir.join("run_shards"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        let good = std::fs::read(&names[1]).unwrap();
        let (h, body) = shard_header(&good).unwrap();
        let (floats, _, wall) = run_shard_words(&h, body, good.len()).unwrap();
        let mut failures = Vec::new();
        let cases = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -1.0,
            -1e300,
            1e300,
        ]
        .into_iter()
        .flat_map(|v| {
            [
                (floats[floats.len() / 3], "a tally", v),
                (wall, "the wall time", v),
            ]
        });
        for (at, what, v) in cases {
            let mut b = good.clone();
            b[at..at + 8].copy_from_slice(&v.to_le_bytes());
            let dir = tempfile::tempdir().unwrap();
            let shards = dir.path().join("shards");
            std::fs::create_dir(&shards).unwrap();
            std::fs::copy(&names[0], shards.join("shard-0-of-2.lshard")).unwrap();
            std::fs::write(shards.join("shard-1-of-2.lshard"), with_checksum(b)).unwrap();
            let out = dir.path().join("m");
            let ran = lidarsim_bounded(
                &[
                    "merge".into(),
                    shards.into(),
                    "--out".into(),
                    out.clone().into(),
                ],
                dir.path(),
                dir.path(),
                TIME_LIMIT,
            )
            .unwrap();
            let outputs = check_written(&out)
                .map(|_| ())
                .and_then(|_| wall_time_ok(&out.join("summary.json")));
            let ok = match ran.code {
                Some(2) => ran.stderr.contains("shard-1-of-2.lshard"),
                // Only a huge finite number may be merged, and then into finite outputs.
                Some(0) => v == 1e300 && outputs.is_ok(),
                _ => false,
            };
            if !ok {
                failures.push(format!(
                    "{what} = {v:e}: exit {:?}: {}",
                    ran.code,
                    outputs.err().unwrap_or_else(|| short(&ran.stderr))
                ));
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n"));
    }

    /// FUZZ_FINDINGS.md F5: a numeric option's negative value in any notation (`-1e-3`, `-inf`,
    /// a list `-1,1`) reaches the option's parser: it is taken or refused naming the option, never
    /// "unexpected argument" (README: "negative numbers are read as values").
    #[test]
    fn negative_values_in_any_notation_reach_the_option() {
        let study = project_root().join("scenes/study_co2_ipda.toml");
        let study = study.to_string_lossy();
        let cases: Vec<(Vec<&str>, &str)> = vec![
            (
                vec![
                    "select-lines",
                    "--atmosphere",
                    "tropical",
                    "--off-cm1",
                    "6360.61",
                    "--co2-ppm",
                    "420",
                    "--top-km",
                    "30",
                    "--layer-m",
                    "1000",
                    "--max-j",
                    "2",
                    "--no-plots",
                    "--threads",
                    "1",
                    "--offsets-ghz",
                    "-1,1",
                ],
                "--offsets-ghz",
            ),
            (
                vec![
                    "dial",
                    &study,
                    "--ensemble",
                    "2",
                    "--class",
                    "high",
                    "--no-plots",
                    "--threads",
                    "1",
                    "--budget-frequency-offset-mhz",
                    "-1e-2",
                ],
                "--budget-frequency-offset-mhz",
            ),
            (
                vec![
                    "lbl",
                    "--atmosphere",
                    "us_standard",
                    "--sensor-altitude-m",
                    "8000",
                    "--zenith-deg",
                    "180",
                    "--start-cm1",
                    "6359",
                    "--end-cm1",
                    "6360",
                    "--step-cm1",
                    "0.1",
                    "--surface-altitude-m",
                    "-1e-3",
                ],
                "--surface-altitude-m",
            ),
            (
                vec![
                    "lbl",
                    "--pressure-atm",
                    "1",
                    "--temperature-k",
                    "296",
                    "--start-cm1",
                    "6359",
                    "--end-cm1",
                    "6360",
                    "--step-cm1",
                    "-inf",
                ],
                "--step-cm1",
            ),
            (
                vec![
                    "mie",
                    "--refractive-index",
                    "1.33",
                    "--size-parameter",
                    "1",
                    "--angles-deg",
                    "-1,90",
                ],
                "--angles-deg",
            ),
            (
                vec![
                    "profiles",
                    "generate",
                    "--class",
                    "mid",
                    "--n",
                    "2",
                    "--seed",
                    "1",
                    "--co2-ppm",
                    "-1e-3",
                ],
                "--co2-ppm",
            ),
            (
                vec!["bench", "--photons", "100", "--ddis-epsilon", "-1e-3"],
                "--ddis-epsilon",
            ),
        ];
        let mut failures = Vec::new();
        for (args, option) in cases {
            let dir = tempfile::tempdir().unwrap();
            let out = dir.path().join("out");
            let mut args: Vec<OsString> = args.into_iter().map(OsString::from).collect();
            // Every command here takes `--out` (bench: `--json`).
            if args[0] == "bench" {
                args.extend(["--json".into(), out.join("b.json").into()]);
            } else {
                args.extend(["--out".into(), out.clone().into()]);
            }
            let ran = lidarsim_bounded(&args, dir.path(), dir.path(), TIME_LIMIT).unwrap();
            let named = ran.stderr.contains(option) && !ran.stderr.contains("unexpected argument");
            if !(ran.code == Some(0) || (ran.code == Some(2) && named)) {
                failures.push(format!(
                    "{option}: exit {:?}: {}",
                    ran.code,
                    short(&ran.stderr)
                ));
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n"));
    }
}
