//! Issue 11 item 4: fuzzing in the project, with a fixed seed and a bounded number of cases.
//!
//! * Property tests (proptest) over the readers: the scene parser, the profile-set reader, the
//!   phase-table reader, the HITRAN `.par` reader and the CSV line-list reader. On arbitrary
//!   text and on mutated valid files (numbers replaced by NaN, ±inf, ±1e308, 0, −0, huge
//!   integers or scaled by powers of ten; keys and columns deleted, duplicated or renamed;
//!   lines deleted, duplicated, swapped; bytes flipped; truncation) a reader never panics; a
//!   refusal is one line naming the file and a line or key; what it accepts is finite and
//!   inside the ranges its types document.
//! * A mutation fuzz of the shipped scenes through the real binary (`lidarsim run`): no crash,
//!   exit 0 or 2, on 0 every number written finite and every energy non-negative, on 2 a
//!   message and nothing left behind, each case within a time bound.
//!
//! Everything is deterministic: one fixed seed, `LIDARSIM_FUZZ_SEED` to change it,
//! `LIDARSIM_FUZZ_SCALE` to multiply every case count (README, "Fuzzing").

use std::path::{Path, PathBuf};

use crate::util::project_root;

/// The seed of every fuzz test unless `LIDARSIM_FUZZ_SEED` is set.
pub(crate) const SEED: u64 = 0x11_0004;

/// `LIDARSIM_FUZZ_SEED`, or [`SEED`].
pub(crate) fn seed() -> u64 {
    std::env::var("LIDARSIM_FUZZ_SEED")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(SEED)
}

/// `n` times `LIDARSIM_FUZZ_SCALE` (default 1).
pub(crate) fn cases(n: u32) -> u32 {
    let scale: u32 = std::env::var("LIDARSIM_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(1);
    n.saturating_mul(scale.max(1))
}

/// The text formats the mutator knows: where numbers and keys are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Format {
    /// A scene: `key = value` lines, `[section]` headers, `#` comments, quoted strings.
    Toml,
    /// A comma-separated table with a header and `#` comments (`# key = value` metadata).
    Csv,
    /// HITRAN 160-character records: fixed-width fields.
    Par,
}

/// One mutation; `a` and `b` choose where and how (any values are valid).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Mutation {
    /// Which kind (taken modulo [`KINDS`]).
    pub(crate) kind: u8,
    /// Usually where.
    pub(crate) a: u64,
    /// Usually what.
    pub(crate) b: u64,
}

/// Number of mutation kinds.
pub(crate) const KINDS: u8 = 12;

/// Values put in place of a number: non-finite, extreme, signed zeros, integers beyond i64 and
/// u64, and a few things that are not numbers at all.
pub(crate) const SPECIALS: [&str; 36] = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "+inf",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "1e309",
    "-1e400",
    "0",
    "-0",
    "0.0",
    "-0.0",
    "5e-324",
    "1e-308",
    "-1",
    "1",
    "2",
    "0.5",
    "-0.5",
    "99999999999999999999999",
    "18446744073709551615",
    "18446744073709551616",
    "9223372036854775807",
    "-9223372036854775808",
    "4294967296",
    "1e15",
    "1e30",
    "-1e30",
    "1e-30",
    "1_000",
    "",
    "1e",
    "--1",
    "1.0.0",
];

/// Texts inserted at a byte: a byte-order mark, control and structural characters, a
/// multi-byte character, an invalid UTF-8 byte.
const SNIPPETS: [&[u8]; 14] = [
    "\u{feff}".as_bytes(),
    b"\r\n",
    b"\0",
    b"\"",
    b"[",
    b"]]",
    b"=",
    b",",
    b"#",
    b"\n",
    "λ".as_bytes(),
    b"\t",
    b"\xff",
    b"\n[x]\n",
];

/// Unit suffixes swapped by a key rename (`altitude_m` → `altitude_km`).
const SUFFIXES: [&str; 14] = [
    "_m", "_km", "_nm", "_cm1", "_mrad", "_deg", "_j", "_per_m", "_per_km", "_hPa", "_Pa", "_ppmv",
    "_vmr", "_K",
];

/// HITRAN record fields, 0-based half-open column ranges (Rothman et al. 2005, Table 1).
const PAR_FIELDS: [(usize, usize); 17] = [
    (0, 2),
    (2, 3),
    (3, 15),
    (15, 25),
    (25, 35),
    (35, 40),
    (40, 45),
    (45, 55),
    (55, 59),
    (59, 67),
    (67, 82),
    (82, 97),
    (97, 112),
    (112, 127),
    (127, 146),
    (146, 153),
    (153, 160),
];

fn pick<T: Copy>(items: &[T], x: u64) -> Option<T> {
    (!items.is_empty()).then(|| items[(x % items.len() as u64) as usize])
}

/// Byte ranges of the lines of `text` (without their `\n`).
fn line_spans(text: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &c) in text.iter().enumerate() {
        if c == b'\n' {
            out.push((start, i));
            start = i + 1;
        }
    }
    if start < text.len() {
        out.push((start, text.len()));
    }
    out
}

fn is_comment(line: &[u8]) -> bool {
    line.iter().find(|c| !c.is_ascii_whitespace()) == Some(&b'#')
}

/// The parts of each line where values stand: after the first `=` outside quotes and before a
/// comment (TOML, `# key = value` metadata), or the whole of a CSV data line.
fn value_regions(text: &[u8], format: Format) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (s, e) in line_spans(text) {
        let line = &text[s..e];
        match format {
            Format::Csv if !is_comment(line) => out.push((s, e)),
            _ => {
                let mut in_quote = false;
                let mut start = None;
                for (i, &c) in line.iter().enumerate() {
                    match c {
                        b'"' => in_quote = !in_quote,
                        b'=' if !in_quote && start.is_none() => start = Some(i + 1),
                        b'#' if !in_quote && format == Format::Toml => break,
                        _ => {}
                    }
                }
                let end = if format == Format::Toml {
                    // Up to a comment outside quotes.
                    let mut q = false;
                    line.iter()
                        .position(|&c| {
                            if c == b'"' {
                                q = !q;
                            }
                            c == b'#' && !q
                        })
                        .unwrap_or(line.len())
                } else {
                    line.len()
                };
                if let Some(st) = start
                    && st < end
                {
                    out.push((s + st, s + end));
                }
            }
        }
    }
    out
}

/// Byte ranges of the numbers in the value regions (outside quoted strings).
fn number_tokens(text: &[u8], format: Format) -> Vec<(usize, usize)> {
    if format == Format::Par {
        let mut out = Vec::new();
        for (s, e) in line_spans(text) {
            if e - s == 160 {
                for (a, z) in PAR_FIELDS {
                    if !(67..146).contains(&a) {
                        out.push((s + a, s + z));
                    }
                }
            }
        }
        return out;
    }
    let mut out = Vec::new();
    let word = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'.';
    for (s, e) in value_regions(text, format) {
        let mut i = s;
        let mut in_quote = false;
        while i < e {
            let c = text[i];
            if c == b'"' {
                in_quote = !in_quote;
                i += 1;
                continue;
            }
            let starts = !in_quote
                && (c.is_ascii_digit()
                    || (matches!(c, b'-' | b'+' | b'.')
                        && i + 1 < e
                        && (text[i + 1].is_ascii_digit() || text[i + 1] == b'.')))
                && (i == 0 || !word(text[i - 1]));
            if starts {
                let mut j = i + 1;
                while j < e
                    && (text[j].is_ascii_digit() || matches!(text[j], b'.' | b'e' | b'E' | b'_'))
                    || (j < e
                        && matches!(text[j], b'+' | b'-')
                        && matches!(text[j - 1], b'e' | b'E'))
                {
                    j += 1;
                }
                out.push((i, j));
                i = j;
            } else {
                i += 1;
            }
        }
    }
    out
}

/// A key as it stands in the text.
#[derive(Debug, Clone, Copy)]
enum Key {
    /// `name = value` (also inside an inline table), or `# name = value` metadata.
    Assign(usize, usize),
    /// `[name]` or `[[name]]`.
    Section(usize, usize),
    /// The `k`-th column name of a CSV header at this byte range.
    Column(usize, usize, usize),
}

impl Key {
    fn span(self) -> (usize, usize) {
        match self {
            Key::Assign(a, z) | Key::Section(a, z) | Key::Column(a, z, _) => (a, z),
        }
    }
}

/// The keys of a scene (keys and section names) or of a CSV (column names, metadata keys).
fn keys(text: &[u8], format: Format) -> Vec<Key> {
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'-';
    let mut out = Vec::new();
    let mut header_done = false;
    for (s, e) in line_spans(text) {
        let line = &text[s..e];
        let first = line.iter().position(|c| !c.is_ascii_whitespace());
        let Some(f) = first else { continue };
        if format == Format::Toml && line[f] == b'[' {
            let a = f + line[f..].iter().take_while(|&&c| c == b'[').count();
            let z = a + line[a..].iter().take_while(|&&c| ident(c)).count();
            if z > a {
                out.push(Key::Section(s + a, s + z));
            }
            continue;
        }
        if format == Format::Csv && !is_comment(line) {
            if !header_done {
                header_done = true;
                let mut a = 0;
                for (k, field) in line.split(|&c| c == b',').enumerate() {
                    out.push(Key::Column(s + a, s + a + field.len(), k));
                    a += field.len() + 1;
                }
            }
            continue;
        }
        // `name =` outside quotes (TOML lines and inline tables, CSV metadata comments).
        let mut in_quote = false;
        let mut i = 0;
        while i < line.len() {
            let c = line[i];
            if c == b'"' {
                in_quote = !in_quote;
            } else if !in_quote && format == Format::Toml && c == b'#' {
                break;
            } else if !in_quote && ident(c) && (i == 0 || !ident(line[i - 1])) {
                let z = i + line[i..].iter().take_while(|&&c| ident(c)).count();
                let rest = line[z..].iter().find(|c| !c.is_ascii_whitespace());
                if rest == Some(&b'=') {
                    out.push(Key::Assign(s + i, s + z));
                }
                i = z;
                continue;
            }
            i += 1;
        }
    }
    out
}

fn replace(text: &[u8], (a, z): (usize, usize), with: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(text.len() + with.len());
    out.extend_from_slice(&text[..a]);
    out.extend_from_slice(with);
    out.extend_from_slice(&text[z..]);
    out
}

/// `text` with the number at `t` replaced by `v`; in a fixed-width HITRAN record, right-aligned
/// and cut to the field's width so that the other fields stay in place.
fn put_number(text: &[u8], t: (usize, usize), v: &str, format: Format) -> Vec<u8> {
    if format == Format::Par {
        let w = t.1 - t.0;
        let mut s = format!("{v:>w$}");
        s.truncate(w);
        replace(text, t, s.as_bytes())
    } else {
        replace(text, t, v.as_bytes())
    }
}

/// The number at `token` scaled, negated or nudged (choice `b`), as the text of the same kind
/// (an integer stays an integer).
fn scaled(token: &[u8], b: u64) -> String {
    let s = String::from_utf8_lossy(token).replace('_', "");
    let integer = !s.contains(['.', 'e', 'E']);
    if integer && let Ok(v) = s.parse::<i128>() {
        const F: [i128; 8] = [
            10,
            100,
            1000,
            1_000_000,
            1_000_000_000,
            1_000_000_000_000,
            1 << 40,
            1 << 63,
        ];
        return match b % 5 {
            0 => v.saturating_mul(pick(&F, b / 5).unwrap_or(10)).to_string(),
            1 => (v / pick(&F, b / 5).unwrap_or(10)).to_string(),
            2 => (-v).to_string(),
            3 => (v + 1).to_string(),
            _ => (v - 1).to_string(),
        };
    }
    let v: f64 = s.parse().unwrap_or(1.0);
    const K: [i32; 16] = [
        1, 2, 3, 6, 12, 30, 100, 300, -1, -2, -3, -6, -12, -30, -100, -300,
    ];
    let x = match b % 4 {
        0 | 1 => v * 10f64.powi(pick(&K, b / 4).unwrap_or(1)),
        2 => -v,
        _ => v * (1.0 + 1e-12) + f64::MIN_POSITIVE,
    };
    // `1e3`, `-2.5e-7`, `inf`: all TOML floats, and numbers to the CSV readers.
    format!("{x:e}")
}

/// Apply one mutation; a mutation that finds nothing to act on returns the text unchanged.
fn mutate_once(text: &[u8], format: Format, m: Mutation) -> Vec<u8> {
    let lines = line_spans(text);
    let numbers = number_tokens(text, format);
    let line_of = |pos: usize| lines.iter().position(|&(s, e)| s <= pos && pos <= e);
    match m.kind % KINDS {
        // A number replaced by a special value (same width in a fixed-width record).
        0 => {
            let Some(t) = pick(&numbers, m.a) else {
                return text.to_vec();
            };
            let v = SPECIALS[(m.b % SPECIALS.len() as u64) as usize];
            put_number(text, t, v, format)
        }
        // A number scaled by a power of ten, negated or nudged.
        1 => {
            let Some(t) = pick(&numbers, m.a) else {
                return text.to_vec();
            };
            let v = scaled(&text[t.0..t.1], m.b);
            put_number(text, t, &v, format)
        }
        // One digit of a number changed.
        2 => {
            let Some(t) = pick(&numbers, m.a) else {
                return text.to_vec();
            };
            let digits: Vec<usize> = (t.0..t.1).filter(|&i| text[i].is_ascii_digit()).collect();
            let Some(i) = pick(&digits, m.b) else {
                return text.to_vec();
            };
            let mut out = text.to_vec();
            out[i] = b'0' + ((m.b / 7) % 10) as u8;
            out
        }
        // A key (or column) deleted.
        3 => {
            if format == Format::Par {
                // A field blanked.
                let Some(t) = pick(&numbers, m.a) else {
                    return text.to_vec();
                };
                return replace(text, t, &vec![b' '; t.1 - t.0]);
            }
            let ks = keys(text, format);
            let Some(k) = pick(&ks, m.a) else {
                return text.to_vec();
            };
            match k {
                Key::Column(_, _, col) => map_csv_rows(text, |fields| {
                    if col < fields.len() {
                        fields.remove(col);
                    }
                }),
                Key::Section(a, _) | Key::Assign(a, _) => {
                    let Some(l) = line_of(a) else {
                        return text.to_vec();
                    };
                    let (s, e) = lines[l];
                    let first = text[s..e].iter().position(|c| !c.is_ascii_whitespace());
                    let at_start = first.is_some_and(|f| s + f == a || text[s + f] == b'#');
                    if at_start {
                        delete_line(text, &lines, l)
                    } else {
                        // Inside an inline table: up to and with the next comma, or to `}`.
                        let rest = &text[a..e];
                        let z = match rest.iter().position(|&c| c == b',' || c == b'}') {
                            Some(p) if rest[p] == b',' => a + p + 1,
                            Some(p) => a + p,
                            None => e,
                        };
                        replace(text, (a, z), b"")
                    }
                }
            }
        }
        // A key (or column) duplicated: the line again, right after it or elsewhere.
        4 => {
            if format == Format::Par {
                // A field copied from another record.
                let Some(t) = pick(&numbers, m.a) else {
                    return text.to_vec();
                };
                let Some(src) = pick(&numbers, m.b) else {
                    return text.to_vec();
                };
                if src.1 - src.0 != t.1 - t.0 {
                    return text.to_vec();
                }
                let v = text[src.0..src.1].to_vec();
                return replace(text, t, &v);
            }
            let ks = keys(text, format);
            let Some(k) = pick(&ks, m.a) else {
                return text.to_vec();
            };
            match k {
                Key::Column(_, _, col) => map_csv_rows(text, |fields| {
                    if col < fields.len() {
                        let f = fields[col].clone();
                        fields.insert(col + 1, f);
                    }
                }),
                Key::Section(a, _) | Key::Assign(a, _) => {
                    let Some(l) = line_of(a) else {
                        return text.to_vec();
                    };
                    let to = if m.b.is_multiple_of(2) {
                        l + 1
                    } else {
                        (m.b / 2 % (lines.len() as u64 + 1)) as usize
                    };
                    copy_line(text, &lines, l, to)
                }
            }
        }
        // A key renamed: to another key of the file, to another unit, or misspelt.
        5 => {
            let ks = keys(text, format);
            let Some(k) = pick(&ks, m.a) else {
                return text.to_vec();
            };
            let (a, z) = k.span();
            let name = String::from_utf8_lossy(&text[a..z]).into_owned();
            let new = match m.b % 3 {
                0 => {
                    let other = pick(&ks, m.b / 3).map_or((a, z), Key::span);
                    String::from_utf8_lossy(&text[other.0..other.1]).into_owned()
                }
                1 => {
                    let stem = SUFFIXES
                        .iter()
                        .find_map(|s| name.strip_suffix(s))
                        .unwrap_or(&name);
                    format!(
                        "{stem}{}",
                        SUFFIXES[(m.b / 3 % SUFFIXES.len() as u64) as usize]
                    )
                }
                _ => format!("{name}x"),
            };
            replace(text, (a, z), new.as_bytes())
        }
        // A line deleted.
        6 => match pick(&(0..lines.len()).collect::<Vec<_>>(), m.a) {
            Some(l) => delete_line(text, &lines, l),
            None => text.to_vec(),
        },
        // A line duplicated somewhere.
        7 => match pick(&(0..lines.len()).collect::<Vec<_>>(), m.a) {
            Some(l) => copy_line(text, &lines, l, (m.b % (lines.len() as u64 + 1)) as usize),
            None => text.to_vec(),
        },
        // Two lines swapped.
        8 => {
            if lines.len() < 2 {
                return text.to_vec();
            }
            let i = (m.a % lines.len() as u64) as usize;
            let j = (m.b % lines.len() as u64) as usize;
            let mut ls: Vec<&[u8]> = lines.iter().map(|&(s, e)| &text[s..e]).collect();
            ls.swap(i, j);
            let mut out = ls.join(&b'\n');
            if text.ends_with(b"\n") {
                out.push(b'\n');
            }
            out
        }
        // Truncated.
        9 => text[..(m.a % (text.len() as u64 + 1)) as usize].to_vec(),
        // One byte changed: a bit flipped, or set to a structural character.
        10 => {
            if text.is_empty() {
                return text.to_vec();
            }
            let i = (m.a % text.len() as u64) as usize;
            let mut out = text.to_vec();
            out[i] = if m.b.is_multiple_of(2) {
                out[i] ^ (1 << (m.b / 2 % 8))
            } else {
                const BYTES: &[u8] = b"\"=[],.#-+e0\n\r ";
                BYTES[(m.b / 2 % BYTES.len() as u64) as usize]
            };
            out
        }
        // A snippet inserted (a byte-order mark at the start, a NUL, a quote…).
        _ => {
            let snippet = SNIPPETS[(m.b % SNIPPETS.len() as u64) as usize];
            let at = if m.b.is_multiple_of(SNIPPETS.len() as u64) {
                0
            } else {
                (m.a % (text.len() as u64 + 1)) as usize
            };
            replace(text, (at, at), snippet)
        }
    }
}

fn delete_line(text: &[u8], lines: &[(usize, usize)], l: usize) -> Vec<u8> {
    let (s, e) = lines[l];
    let e = (e + 1).min(text.len());
    replace(text, (s, e), b"")
}

fn copy_line(text: &[u8], lines: &[(usize, usize)], l: usize, to: usize) -> Vec<u8> {
    let (s, e) = lines[l];
    let mut copy = text[s..e].to_vec();
    copy.push(b'\n');
    let at = if to < lines.len() {
        lines[to].0
    } else {
        text.len()
    };
    let mut out = text.to_vec();
    if at == text.len() && !text.is_empty() && !text.ends_with(b"\n") {
        out.push(b'\n');
    }
    let at = at.min(out.len());
    out.splice(at..at, copy);
    out
}

/// Edit the comma-separated fields of every non-comment line of a CSV.
fn map_csv_rows(text: &[u8], f: impl Fn(&mut Vec<Vec<u8>>)) -> Vec<u8> {
    let mut out = Vec::with_capacity(text.len());
    for (n, (s, e)) in line_spans(text).into_iter().enumerate() {
        if n > 0 {
            out.push(b'\n');
        }
        let line = &text[s..e];
        if is_comment(line) || line.iter().all(u8::is_ascii_whitespace) {
            out.extend_from_slice(line);
            continue;
        }
        let mut fields: Vec<Vec<u8>> = line.split(|&c| c == b',').map(<[u8]>::to_vec).collect();
        f(&mut fields);
        out.extend_from_slice(&fields.join(&b','));
    }
    if text.ends_with(b"\n") {
        out.push(b'\n');
    }
    out
}

/// Apply mutations in order.
pub(crate) fn mutate(text: &[u8], format: Format, ms: &[Mutation]) -> Vec<u8> {
    ms.iter()
        .fold(text.to_vec(), |t, &m| mutate_once(&t, format, m))
}

// ---------------------------------------------------------------------------------------------
// Valid inputs the readers' mutations start from.

/// A profile set: two profiles, levels bottom-up and top-down, every optional column.
pub(crate) const PROFILES_A: &str = "# lidarsim profile set\n\
profile,latitude_deg,longitude_deg,time_utc,weight,level,altitude_m,pressure_hPa,temperature_K,H2O_ppmv,CO2_ppmv\n\
a,15,0,2007-02-20T12:00Z,0.5,1,0,1013,299.7,25900,420.1\n\
a,15,0,2007-02-20T12:00Z,0.5,2,1000,898,293.2,18000,420.0\n\
a,15,0,2007-02-20T12:00Z,0.5,3,5000,540,270.1,3000,419.5\n\
a,15,0,2007-02-20T12:00Z,0.5,4,15000,120,205.0,4,418.0\n\
b,-60,170,2007-02-21,1.5,1,20000,55,215.0,4,418.0\n\
b,-60,170,2007-02-21,1.5,2,8000,350,230.0,100,419.0\n\
b,-60,170,2007-02-21,1.5,3,500,950,260.0,2000,421.0\n";

/// A profile set with hydrostatic altitudes, Pa, specific humidity and per-dry-air CO2.
pub(crate) const PROFILES_B: &str = "profile,latitude_deg,longitude_deg,surface_altitude_m,pressure_Pa,temperature_K,q_kgkg,CO2_ppmv_dry,CH4_ppbv\n\
s1,45,7,120,100000,290,0.01,400,1900\n\
s1,45,7,120,85000,282,0.006,400,1890\n\
s1,45,7,120,50000,250,0.001,400,1850\n\
s2,46,8,0,101000,288,0.008,401,1910\n\
s2,46,8,0,20000,220,0.00001,401,1700\n";

/// HITRAN2016 records of CO2 626 and H2O 161.
pub(crate) const PAR: &str = " 21 6359.967244 1.779E-23 7.543e-03.07470.102  106.12970.67-.005510       3 0 0 12       0 0 0 01                    R 16e     4788762029 6 5 6 8    35.0   33.0
 21 6027.480381 1.338E-29 3.505e-06.06730.074 1664.19460.73-.007616       2 3 3 13       0 1 1 01                    P 50f     3677642029 5 4 5 7    99.0  101.0
 21 6027.563121 5.844E-29 1.372e-03.06880.087 2514.73730.76-.007350       4 1 1 14       1 1 1 01                    R 33e     3677642029 5 4 5 7    69.0   67.0
 11 6074.315120 3.367E-26 3.035E-04.06900.311  709.60820.61-.006881          0 1 1          0 0 0  8  6  3        7  2  6      574423303330572210    17.0   15.0
";

/// A CSV line list as HITRANonline writes it (Voigt parameters only).
pub(crate) const LINES_VOIGT: &str = "molec_id,local_iso_id,nu,sw,elower,gamma_air,gamma_self,n_air,delta_air\n\
2,1,6359.967244,1.779e-23,106.1297,0.0747,0.102,0.67,-0.00551\n\
2,1,6360.0,1.0e-25,500.0,0.07,0.09,0.7,-0.006\n\
1,1,6074.315120,3.367e-26,709.6082,0.069,0.311,0.61,-0.006881\n";

/// A CSV line list with beyond-Voigt columns (as the NIST 30012 list of usnistgov/MATS), with
/// its repeated `elower` column.
pub(crate) const LINES_HT: &str = "trans_id,molec_id,local_iso_id,nu,sw,a,elower,gp,gpp,elower,global_upper_quanta,global_lower_quanta,local_upper_quanta,local_lower_quanta,gamma0_air,n_gamma0_air,delta0_air,n_delta0_air,SD_gamma_air,n_gamma2_air,SD_delta_air,n_delta2_air,nuVC_air,n_nuVC_air,eta_air,y_air,n_y_air,gamma0_self,n_gamma0_self,delta0_self,n_delta0_self,SD_gamma_self,n_gamma2_self,SD_delta_self,n_delta2_self,nuVC_self,n_nuVC_self,eta_self,y_self,n_y_self\n\
6795046,2,1,6317.158845,5.8000E-24,0.007312,464.1717,67,69,464.1717,       3 0 0 12,       0 0 0 01,               ,     P 34e     ,0.068857763,0.75,-0.006996265,0,0.078309491,0.75,0,0,0.002670806,1,0,0,0,0.086,0.75,0,0,0,0.75,0,0,0,1,0,0,0\n\
6795159,2,1,6319.19565,7.0800E-24,0.007364,411.9225,63,65,411.9225,       3 0 0 12,       0 0 0 01,               ,     P 32e     ,0.069407106,0.72,-0.006590684,0,0.088385581,0.72,0,0,0.000684057,1,0,0,0,0.088,0.72,0,0,0,0.72,0,0,0,1,0,0,0\n";

/// A small phase table (isotropic, three nodes).
pub(crate) const PHASE_SMALL: &str = "# lidarsim phase function table\n\
# wavelength_nm = 532\n\
# refractive_index = none\n\
# distribution = none\n\
theta_deg,phase_4pi\n\
0,1\n\
90,1\n\
180,1\n";

/// The shipped phase tables (1400 rows each): one is enough for the mutations.
fn phase_shipped() -> String {
    std::fs::read_to_string(project_root().join("phase_functions/continental_average_532nm.txt"))
        .expect("a shipped phase table")
}

/// The shipped scenes: (path, text).
pub(crate) fn shipped_scenes() -> Vec<(PathBuf, String)> {
    let mut out: Vec<(PathBuf, String)> = std::fs::read_dir(project_root().join("scenes"))
        .expect("scenes/")
        .map(|e| e.expect("scenes/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| {
            let t = std::fs::read_to_string(&p).expect("a scene");
            (p, t)
        })
        .collect();
    out.sort();
    assert!(out.len() >= 6, "the shipped scenes");
    out
}

// ---------------------------------------------------------------------------------------------
// What every reader owes: a refusal names the file and a line or a key on one line; what is
// accepted holds finite values.

use lidarsim::input::InputError;

/// Refusals that concern the file as a whole and so name neither a line nor a key.
const WHOLE_FILE: [&str; 3] = [
    "no header line (the file is empty)",
    "no profiles (no data rows)",
    "needs at least two angles (0 and 180)",
];

/// Checks an error; `Err(description)` when it breaks the contract.
fn check_refusal(e: &InputError, path: &Path, text: &str) -> Result<(), String> {
    let shown = e.to_string();
    if e.path != path || !shown.starts_with(&path.display().to_string()) {
        return Err(format!(
            "does not name the file {}: {shown}",
            path.display()
        ));
    }
    if e.message.trim().is_empty() {
        return Err(format!("empty message: {shown}"));
    }
    if shown.contains('\n') {
        return Err(format!("more than one line: {shown:?}"));
    }
    if e.line.is_none() && e.field.is_none() && !WHOLE_FILE.iter().any(|w| e.message.contains(w)) {
        return Err(format!("names neither a line nor a key: {shown}"));
    }
    let lines = text.lines().count().max(1);
    if let Some(l) = e.line
        && (l == 0 || l > lines + 1)
    {
        return Err(format!(
            "line {l} outside the file's {lines} lines: {shown}"
        ));
    }
    Ok(())
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The invariants `Profile` documents: altitudes strictly increasing, pressures strictly
/// decreasing and positive, temperatures positive, mixing ratios in [0, 1], all finite.
fn check_profiles(set: &lidarsim::atmosphere::ProfileSet) -> Result<(), String> {
    for m in &set.members {
        let p = &m.profile;
        let n = p.altitude_m.len();
        let ok = n >= 1
            && p.pressure_pa.len() == n
            && p.temperature_k.len() == n
            && all_finite(&p.altitude_m)
            && all_finite(&p.pressure_pa)
            && all_finite(&p.temperature_k)
            && p.altitude_m.windows(2).all(|w| w[0] < w[1])
            && p.pressure_pa.windows(2).all(|w| w[0] > w[1])
            && p.pressure_pa.iter().all(|&x| x > 0.0)
            && p.temperature_k.iter().all(|&x| x > 0.0)
            && p.gases
                .iter()
                .all(|g| g.vmr.len() == n && g.vmr.iter().all(|&x| (0.0..=1.0).contains(&x)));
        if !ok {
            return Err(format!("accepted a profile breaking its invariants: {p:?}"));
        }
    }
    Ok(())
}

fn check_lines(list: &lidarsim::spectroscopy::LineList) -> Result<(), String> {
    for l in &list.lines {
        let mut v = vec![
            l.nu_cm1,
            l.sw_cm_per_molecule,
            l.einstein_a_per_s,
            l.gamma_air_cm1_per_atm,
            l.gamma_self_cm1_per_atm,
            l.elower_cm1,
            l.n_air,
            l.delta_air_cm1_per_atm,
        ];
        if let Some(s) = &l.shape {
            for b in [&s.air, &s.self_broadening] {
                v.extend([
                    b.gamma0, b.n_gamma0, b.delta0, b.n_delta0, b.sd_gamma, b.n_gamma2, b.sd_delta,
                    b.nu_vc, b.n_nu_vc, b.eta, b.y, b.n_y,
                ]);
            }
        }
        let ok = all_finite(&v)
            && l.nu_cm1 > 0.0
            && l.sw_cm_per_molecule >= 0.0
            && l.gamma_air_cm1_per_atm >= 0.0
            && l.gamma_self_cm1_per_atm >= 0.0;
        if !ok {
            return Err(format!("accepted a line with a value out of range: {l:?}"));
        }
    }
    if !list.lines.windows(2).all(|w| w[0].nu_cm1 <= w[1].nu_cm1) {
        return Err("accepted lines not sorted by wavenumber".into());
    }
    Ok(())
}

fn check_phase(t: &lidarsim::particles::table::PhaseTable) -> Result<(), String> {
    let ok = t.theta_deg.len() >= 2
        && t.theta_deg.len() == t.phase_4pi.len()
        && t.theta_deg.first() == Some(&0.0)
        && t.theta_deg.last() == Some(&180.0)
        && t.theta_deg.windows(2).all(|w| w[0] < w[1])
        && t.phase_4pi.iter().all(|&p| p.is_finite() && p >= 0.0)
        && (t.normalisation() - 1.0).abs() <= 0.02;
    if ok {
        Ok(())
    } else {
        Err(format!(
            "accepted a table breaking the format: {:?}",
            t.theta_deg.len()
        ))
    }
}

/// The readers, each as: parse `text` as if read from `path`, and check the outcome.
#[derive(Debug, Clone, Copy)]
enum Reader {
    Scene,
    ProfileSet,
    PhaseTable,
    Par,
    CsvLines,
}

impl Reader {
    fn read(self, path: &Path, text: &str) -> Result<(), String> {
        use lidarsim::spectroscopy::{LineFilter, LineList};
        // Errors are checked; a value accepted is checked by the reader's own postcondition.
        let outcome: Result<Result<(), String>, InputError> =
            match self {
                Reader::Scene => lidarsim::scene::Scene::from_toml(path, text).map(|_| Ok(())),
                Reader::ProfileSet => lidarsim::atmosphere::set::parse_profile_set(path, text)
                    .map(|s| check_profiles(&s)),
                Reader::PhaseTable => lidarsim::particles::table::PhaseTable::parse(path, text)
                    .map(|t| check_phase(&t)),
                Reader::Par => {
                    LineList::parse_par(path, text, &LineFilter::default()).map(|l| check_lines(&l))
                }
                Reader::CsvLines => {
                    LineList::parse_csv(path, text, &LineFilter::default()).map(|l| check_lines(&l))
                }
            };
        match outcome {
            Ok(accepted) => accepted,
            Err(e) => check_refusal(&e, path, text),
        }
    }

    fn format(self) -> Format {
        match self {
            Reader::Scene => Format::Toml,
            Reader::Par => Format::Par,
            _ => Format::Csv,
        }
    }

    /// The file name errors must show.
    fn path(self) -> PathBuf {
        match self {
            // In the scenes' folder, so that relative phase-table paths resolve.
            Reader::Scene => project_root().join("scenes/fuzzed.toml"),
            Reader::ProfileSet => PathBuf::from("fuzz/profiles.csv"),
            Reader::PhaseTable => PathBuf::from("fuzz/phase.txt"),
            Reader::Par => PathBuf::from("fuzz/lines.par"),
            Reader::CsvLines => PathBuf::from("fuzz/lines.csv"),
        }
    }

    /// The valid texts mutations start from.
    fn seeds(self) -> Vec<String> {
        match self {
            Reader::Scene => shipped_scenes().into_iter().map(|(_, t)| t).collect(),
            Reader::ProfileSet => vec![PROFILES_A.into(), PROFILES_B.into()],
            Reader::PhaseTable => vec![PHASE_SMALL.into(), phase_shipped()],
            Reader::Par => vec![PAR.into()],
            Reader::CsvLines => vec![LINES_VOIGT.into(), LINES_HT.into()],
        }
    }

    /// A mutated text, replacing invalid UTF-8 (the readers take text; reading a file that
    /// is not UTF-8 is refused before them).
    fn mutated(self, seed: &str, ms: &[Mutation]) -> String {
        String::from_utf8_lossy(&mutate(seed.as_bytes(), self.format(), ms)).into_owned()
    }
}

const READERS: [Reader; 5] = [
    Reader::Scene,
    Reader::ProfileSet,
    Reader::PhaseTable,
    Reader::Par,
    Reader::CsvLines,
];

#[test]
fn the_seed_inputs_are_valid() {
    for r in READERS {
        for (i, s) in r.seeds().iter().enumerate() {
            let path = r.path();
            let ok = match r {
                Reader::Scene => lidarsim::scene::Scene::from_toml(&path, s).map(|_| ()),
                Reader::ProfileSet => {
                    lidarsim::atmosphere::set::parse_profile_set(&path, s).map(|_| ())
                }
                Reader::PhaseTable => {
                    lidarsim::particles::table::PhaseTable::parse(&path, s).map(|_| ())
                }
                Reader::Par => {
                    lidarsim::spectroscopy::LineList::parse_par(&path, s, &Default::default())
                        .map(|l| assert_eq!(l.len(), 4))
                }
                Reader::CsvLines => {
                    lidarsim::spectroscopy::LineList::parse_csv(&path, s, &Default::default())
                        .map(|l| assert!(l.len() >= 2))
                }
            };
            assert!(ok.is_ok(), "{r:?} seed {i}: {ok:?}");
        }
    }
}

/// The mutator finds what it should: numbers in values (not in keys or comments), keys,
/// columns and HITRAN fields; and it is deterministic.
#[test]
fn the_mutator_finds_numbers_and_keys() {
    let toml = b"# 1 comment 2\n[lidar]\naltitude_m = -1.5e3 # 7\nname = \"a 3\"\nphase = { kind = \"hg\", g = 0.7 }\nfov = [0.2, 1_000]\n";
    let nums: Vec<String> = number_tokens(toml, Format::Toml)
        .into_iter()
        .map(|(a, z)| String::from_utf8_lossy(&toml[a..z]).into_owned())
        .collect();
    assert_eq!(nums, ["-1.5e3", "0.7", "0.2", "1_000"]);
    let ks: Vec<String> = keys(toml, Format::Toml)
        .into_iter()
        .map(|k| {
            let (a, z) = k.span();
            String::from_utf8_lossy(&toml[a..z]).into_owned()
        })
        .collect();
    assert_eq!(
        ks,
        ["lidar", "altitude_m", "name", "phase", "kind", "g", "fov"]
    );
    let csv = b"# wavelength_nm = 532\nH2O_ppmv,b\n1e4,-2\n";
    let nums: Vec<String> = number_tokens(csv, Format::Csv)
        .into_iter()
        .map(|(a, z)| String::from_utf8_lossy(&csv[a..z]).into_owned())
        .collect();
    assert_eq!(nums, ["532", "1e4", "-2"]);
    assert_eq!(keys(csv, Format::Csv).len(), 3);
    // Deleting the column `b` removes it from every row.
    let m = Mutation {
        kind: 3,
        a: 2,
        b: 0,
    };
    assert_eq!(
        mutate_once(csv, Format::Csv, m),
        b"# wavelength_nm = 532\nH2O_ppmv\n1e4\n"
    );
    // Deleting `g` inside the inline table keeps the rest of the line.
    let m = Mutation {
        kind: 3,
        a: 5,
        b: 0,
    };
    let out = String::from_utf8(mutate_once(toml, Format::Toml, m)).unwrap();
    assert!(out.contains("phase = { kind = \"hg\", }"), "{out}");
    // A HITRAN field replaced keeps the record's 160 characters.
    let rec = PAR.lines().next().unwrap().as_bytes();
    let m = Mutation {
        kind: 0,
        a: 3,
        b: 0,
    };
    let out = mutate_once(rec, Format::Par, m);
    assert_eq!(out.len(), 160);
    assert_eq!(&out[15..25], b"       nan");
    let ms = [
        Mutation {
            kind: 1,
            a: 9,
            b: 4,
        },
        Mutation {
            kind: 10,
            a: 3,
            b: 5,
        },
    ];
    assert_eq!(
        mutate(toml, Format::Toml, &ms),
        mutate(toml, Format::Toml, &ms)
    );
}

mod readers {
    //! Property tests: every reader on arbitrary and on mutated text.

    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{RngAlgorithm, RngSeed};

    /// Bounded, deterministic, nothing written to disk.
    fn config(n: u32) -> ProptestConfig {
        ProptestConfig {
            cases: cases(n),
            failure_persistence: None,
            rng_algorithm: RngAlgorithm::ChaCha,
            rng_seed: RngSeed::Fixed(seed()),
            ..ProptestConfig::default()
        }
    }

    fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
        prop::collection::vec(
            (0..KINDS, any::<u64>(), any::<u64>()).prop_map(|(kind, a, b)| Mutation { kind, a, b }),
            1..=4,
        )
    }

    /// Arbitrary text: raw bytes (as text), printable ASCII with line breaks, or lines made
    /// of the characters the format is written in.
    fn arbitrary_text(r: Reader) -> BoxedStrategy<String> {
        let alphabet = match r {
            Reader::Scene => {
                "([a-z_]{1,14} ?= ?[-+0-9.eE_a-z\"\\[\\]{},=]{0,14}|\\[{1,2}[a-z_]{1,10}\\]{1,2}|#.{0,8})"
            }
            Reader::Par => "[ 0-9.eE+-]{160}",
            _ => {
                "([a-zA-Z_0-9]{1,12}(,[-+0-9.eE:TZa-z_]{0,10}){0,8}|# ?[a-z_]{1,14} ?= ?[-0-9.e]{0,8})"
            }
        };
        let lines = prop::collection::vec(proptest::string::string_regex(alphabet).unwrap(), 0..20)
            .prop_map(|ls| ls.join("\n"));
        prop_oneof![
            prop::collection::vec(any::<u8>(), 0..600)
                .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
            "[ -~\n]{0,600}",
            lines,
        ]
        .boxed()
    }

    fn run(r: Reader, text: &str) -> Result<(), TestCaseError> {
        r.read(&r.path(), text)
            .map_err(|e| TestCaseError::fail(format!("{r:?}: {e}\n--- input:\n{text}")))
    }

    macro_rules! reader_properties {
        ($($name:ident: $reader:expr, $mutated:expr, $arbitrary:expr;)*) => {$(
            mod $name {
                use super::*;

                proptest! {
                    #![proptest_config(config($mutated))]
                    #[test]
                    fn mutated_valid_input(seed_index in any::<usize>(), ms in mutations()) {
                        let seeds = $reader.seeds();
                        let text = $reader.mutated(&seeds[seed_index % seeds.len()], &ms);
                        run($reader, &text)?;
                    }
                }

                proptest! {
                    #![proptest_config(config($arbitrary))]
                    #[test]
                    fn arbitrary_input(text in arbitrary_text($reader)) {
                        run($reader, &text)?;
                    }
                }
            }
        )*};
    }

    reader_properties! {
        scene: Reader::Scene, 1000, 300;
        profile_set: Reader::ProfileSet, 1000, 300;
        phase_table: Reader::PhaseTable, 500, 300;
        hitran_par: Reader::Par, 1000, 300;
        csv_lines: Reader::CsvLines, 1000, 300;
    }
}

mod scenes {
    //! The shipped scenes, mutated, through the real binary: `lidarsim run SCENE --out DIR
    //! --photons 2000 --no-plots`, a few hundred cases on two threads.

    use super::*;
    use crate::util::{
        NON_NEGATIVE_COLUMNS, TEXT_COLUMNS, absolute_paths, check_json_text, lidarsim_bounded,
    };
    use rand::{RngExt, SeedableRng};
    use std::ffi::OsString;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::{Duration, Instant};

    /// Cases in CI (times `LIDARSIM_FUZZ_SCALE`).
    const CASES: u32 = 600;
    /// Photon packets per run: enough to reach every tally, small enough for ~0.1 s a run.
    const PHOTONS: &str = "2000";
    /// A case that takes longer has hung (the unmutated scenes take at most 0.3 s).
    const TIME_LIMIT: Duration = Duration::from_secs(20);

    /// One fuzz case: a shipped scene and the mutations applied to it.
    struct Case {
        scene: String,
        original: String,
        mutations: Vec<Mutation>,
        text: Vec<u8>,
    }

    /// Case `index` of the run with seed `seed`: independent of the others, so one case can
    /// be run alone (`LIDARSIM_FUZZ_CASE`).
    fn case(index: usize, seed: u64, scenes: &[(PathBuf, String)]) -> Case {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(
            seed ^ (index as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        let (path, text) = &scenes[index % scenes.len()];
        // Relative paths (phase tables) resolve from the scenes' folder: make them absolute.
        let original = absolute_paths(text);
        // Most cases change numbers as a user might (a power of ten, a sign, a digit) and
        // often reach the physics; a quarter put in one hostile value; the rest damage keys,
        // lines and bytes.
        let roll = rng.random_range(0..100);
        let kinds: Vec<u8> = match roll {
            0..60 => (0..rng.random_range(1..=3))
                .map(|_| if rng.random_range(0..4) == 0 { 2 } else { 1 })
                .collect(),
            60..85 => vec![0],
            _ => (0..rng.random_range(1..=2))
                .map(|_| rng.random_range(3..KINDS))
                .collect(),
        };
        let mutations: Vec<Mutation> = kinds
            .into_iter()
            .map(|kind| Mutation {
                kind,
                a: rng.random(),
                b: rng.random(),
            })
            .collect();
        let text = mutate(original.as_bytes(), Format::Toml, &mutations);
        Case {
            scene: path.file_name().unwrap().to_string_lossy().into_owned(),
            original,
            mutations,
            text,
        }
    }

    /// The lines a case changed, for the failure message (at most a few).
    fn changed_lines(c: &Case) -> String {
        let new = String::from_utf8_lossy(&c.text);
        let old: Vec<&str> = c.original.lines().collect();
        let new: Vec<&str> = new.lines().collect();
        let mut out = Vec::new();
        for i in 0..old.len().max(new.len()) {
            let (a, b) = (old.get(i), new.get(i));
            if a != b {
                out.push(format!(
                    "    line {}: {:?} -> {:?}",
                    i + 1,
                    a.unwrap_or(&""),
                    b.unwrap_or(&"")
                ));
            }
            if out.len() == 4 {
                out.push("    …".into());
                break;
            }
        }
        out.join("\n")
    }

    /// How a case ended.
    enum Outcome {
        Ran,
        Refused,
    }

    /// How a case ended and how long it took, or the promise it broke.
    type CaseResult = Result<(Outcome, Duration), String>;

    /// Run one case.
    fn run_case(c: &Case) -> CaseResult {
        let root = tempfile::tempdir().map_err(|e| e.to_string())?;
        let scene = root.path().join(&c.scene);
        std::fs::write(&scene, &c.text).map_err(|e| e.to_string())?;
        // The output's parent holds nothing else, so that anything left behind shows.
        let work = root.path().join("work");
        std::fs::create_dir(&work).map_err(|e| e.to_string())?;
        let out_dir = work.join("out");
        let args: Vec<OsString> = vec![
            "run".into(),
            scene.into(),
            "--out".into(),
            out_dir.clone().into(),
            "--photons".into(),
            PHOTONS.into(),
            "--no-plots".into(),
        ];
        let ran = lidarsim_bounded(&args, root.path(), root.path(), TIME_LIMIT)?;
        let (took, stderr) = (ran.took, ran.stderr);
        let short = |s: &str| s.chars().take(600).collect::<String>();
        if stderr.contains("panicked") {
            return Err(format!("panicked: {}", short(&stderr)));
        }
        let leftovers = |dir: &Path| -> Vec<String> {
            std::fs::read_dir(dir)
                .map(|rd| {
                    rd.filter_map(Result::ok)
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .collect()
                })
                .unwrap_or_default()
        };
        match ran.code {
            Some(0) => {
                let mut left = leftovers(&work);
                left.retain(|n| n != "out");
                let inside = leftovers(&out_dir);
                if let Some(n) = left
                    .iter()
                    .chain(&inside)
                    .find(|n| n.starts_with('.') || n.ends_with(".tmp"))
                {
                    return Err(format!("exit 0 left a temporary entry `{n}`"));
                }
                if !left.is_empty() {
                    return Err(format!(
                        "exit 0 wrote beside the output directory: {left:?}"
                    ));
                }
                check_outputs(&out_dir)?;
                Ok((Outcome::Ran, took))
            }
            Some(2) => {
                let message = stderr.strip_prefix("lidarsim: error: ").unwrap_or("");
                if message.trim().is_empty() || stderr.trim_end().lines().count() != 1 {
                    return Err(format!("exit 2 without one line of error: {stderr:?}"));
                }
                let left = leftovers(&work);
                if !left.is_empty() {
                    return Err(format!(
                        "exit 2 left {left:?} behind ({})",
                        short(stderr.trim())
                    ));
                }
                eprintln!(
                    "REFUSED {}",
                    stderr
                        .trim()
                        .rsplit(": `")
                        .next()
                        .unwrap_or("")
                        .chars()
                        .take(70)
                        .collect::<String>()
                );
                Ok((Outcome::Refused, took))
            }
            code => Err(format!(
                "exit status {} (code {code:?}), expected 0 or 2: {}",
                ran.status,
                short(&stderr)
            )),
        }
    }

    /// Every CSV written parses, holds finite numbers and no negative energy or error; the
    /// summary holds no `null` (serde_json writes a NaN as null).
    fn check_outputs(dir: &Path) -> Result<(), String> {
        let returns = dir.join("returns.csv");
        if !returns.is_file() {
            return Err("exit 0 without returns.csv".into());
        }
        for entry in std::fs::read_dir(dir).map_err(|e| e.to_string())? {
            let p = entry.map_err(|e| e.to_string())?.path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if name == "retrieval.csv" {
                continue;
            }
            if name.ends_with(".csv") {
                let mut r = csv::Reader::from_path(&p).map_err(|e| format!("{name}: {e}"))?;
                let header: Vec<String> = r
                    .headers()
                    .map_err(|e| format!("{name}: {e}"))?
                    .iter()
                    .map(str::to_string)
                    .collect();
                let mut rows = 0;
                for (n, rec) in r.records().enumerate() {
                    let rec = rec.map_err(|e| format!("{name} row {}: {e}", n + 2))?;
                    rows += 1;
                    for (col, field) in header.iter().zip(rec.iter()) {
                        if TEXT_COLUMNS.contains(&col.as_str()) {
                            continue;
                        }
                        if field.is_empty() && may_be_empty(&name, &header, &rec, col) {
                            continue;
                        }
                        let v: f64 = field.parse().map_err(|_| {
                            format!("{name} row {}: `{col}` = `{field}` is not a number", n + 2)
                        })?;
                        if !v.is_finite() {
                            return Err(format!("{name} row {}: `{col}` = {field}", n + 2));
                        }
                        if v < 0.0 && NON_NEGATIVE_COLUMNS.contains(&col.as_str()) {
                            return Err(format!(
                                "{name} row {}: `{col}` = {field} is negative",
                                n + 2
                            ));
                        }
                    }
                }
                if rows == 0 && name == "returns.csv" {
                    return Err("returns.csv has no rows".into());
                }
            } else if name.ends_with(".json") {
                let text = std::fs::read_to_string(&p).map_err(|e| format!("{name}: {e}"))?;
                check_json_text(&name, &text)?;
            }
        }
        Ok(())
    }

    /// retrieval.csv leaves empty what cannot be computed (README): the simulated figures, and
    /// the estimates of a row from Monte Carlo returns (a window where no photon scored).
    fn may_be_empty(file: &str, header: &[String], rec: &csv::StringRecord, col: &str) -> bool {
        let source = header
            .iter()
            .position(|h| h == "source")
            .and_then(|i| rec.get(i));
        // Each row fills the value columns of its quantity's unit only (`truth_ppm`, …).
        let quantity = header
            .iter()
            .position(|h| h == "quantity")
            .and_then(|i| rec.get(i));
        let unit = match quantity {
            Some("mixing_ratio") => "_ppm",
            Some("slant_column") => "_molecules_per_m2",
            _ => "_molecules_per_m3",
        };
        file == "retrieval.csv"
            && (!col.ends_with(unit)
                || col.starts_with("simulated_")
                || (source == Some("mc")
                    && [
                        "retrieved",
                        "bias",
                        "mc_stderr",
                        "random_error_per_shot_pair",
                        "random_error_averaged",
                    ]
                    .iter()
                    .any(|c| col.strip_suffix(unit) == Some(c))))
    }

    /// Cases that fail for a reason that belongs to the photon loop
    /// (`src/transport/photon/`), each with why: reported, not fixed here. Applies to the
    /// default seed only.
    const KNOWN_FAILURES: &[(usize, &str)] = &[];

    #[test]
    fn mutated_shipped_scenes_run_or_are_refused_cleanly() {
        let scenes = shipped_scenes();
        let seed = seed();
        let only: Option<usize> = std::env::var("LIDARSIM_FUZZ_CASE")
            .ok()
            .and_then(|s| s.trim().parse().ok());
        let indices: Vec<usize> = match only {
            Some(i) => vec![i],
            None => (0..cases(CASES) as usize).collect(),
        };
        let next = AtomicUsize::new(0);
        let started = Instant::now();
        let results: Vec<(usize, CaseResult)> = std::thread::scope(|s| {
            let workers: Vec<_> = (0..2)
                .map(|_| {
                    s.spawn(|| {
                        let mut done = Vec::new();
                        loop {
                            let k = next.fetch_add(1, Ordering::Relaxed);
                            let Some(&i) = indices.get(k) else { break };
                            done.push((i, run_case(&case(i, seed, &scenes))));
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
        let ran = results
            .iter()
            .filter(|(_, r)| matches!(r, Ok((Outcome::Ran, _))))
            .count();
        let (slowest, slowest_case) = results
            .iter()
            .filter_map(|(i, r)| r.as_ref().ok().map(|(_, t)| (*t, *i)))
            .max()
            .unwrap_or_default();
        println!(
            "{} mutated scenes (seed {seed}): {ran} ran, {} refused, {} failed; {:.1} s, slowest case {:.2} s (case {slowest_case})",
            results.len(),
            results
                .iter()
                .filter(|(_, r)| matches!(r, Ok((Outcome::Refused, _))))
                .count(),
            results.iter().filter(|(_, r)| r.is_err()).count(),
            started.elapsed().as_secs_f64(),
            slowest.as_secs_f64()
        );
        let keep = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz");
        let mut failures = Vec::new();
        let mut sorted = results;
        sorted.sort_by_key(|(i, _)| *i);
        for (i, r) in sorted {
            if only.is_some() {
                // One case asked for: show it, whatever its outcome.
                let c = case(i, seed, &scenes);
                let _ = std::fs::create_dir_all(&keep);
                let saved = keep.join(format!("case-{i}-{}", c.scene));
                let _ = std::fs::write(&saved, &c.text);
                println!(
                    "case {i} ({}; {:?}):\n{}\n    scene: {}",
                    c.scene,
                    c.mutations,
                    changed_lines(&c),
                    saved.display()
                );
            }
            let Err(why) = r else { continue };
            let known = KNOWN_FAILURES.iter().find(|(k, _)| *k == i && seed == SEED);
            let c = case(i, seed, &scenes);
            let _ = std::fs::create_dir_all(&keep);
            let saved = keep.join(format!("case-{i}-{}", c.scene));
            let _ = std::fs::write(&saved, &c.text);
            let report = format!(
                "case {i} ({}; {:?}): {why}\n{}\n    scene: {}",
                c.scene,
                c.mutations,
                changed_lines(&c),
                saved.display()
            );
            match known {
                Some((_, reason)) => println!("known failure ({reason}): {report}"),
                None => failures.push(report),
            }
        }
        assert!(
            failures.is_empty(),
            "{} of the mutated scenes broke a promise (rerun one with LIDARSIM_FUZZ_CASE=N):\n{}",
            failures.len(),
            failures.join("\n")
        );
    }
}
