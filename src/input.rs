//! Errors for bad input files, and a small reader for the comma-separated tables lidarsim uses.
//!
//! Every parser in lidarsim (scenes, profiles, HITRAN line files, phase-function tables,
//! partition sums) reports a problem as one [`InputError`] naming the file, the 1-based line and
//! the field (key or column). Nothing panics on user data and nothing is silently defaulted.
//!
//! [`CsvTable`] reads the project's text tables: `#` comment lines anywhere, one header line of
//! column names, then comma-separated rows. Values keep their line numbers so a bad number can be
//! reported where it stands.
//!
//! [`check_finite_range`] is the one check every numeric input passes through (scene keys,
//! command-line options, file fields): finite and inside its physical [`Bounds`], or a message
//! saying which bounds.

use std::fmt;
use std::path::{Path, PathBuf};

/// One problem in one input file: where it is and what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct InputError {
    /// The file (or a pseudo-path such as `<embedded default scene>`).
    pub path: PathBuf,
    /// 1-based line number, where one applies.
    pub line: Option<usize>,
    /// The key, column or record field at fault, where one applies.
    pub field: Option<String>,
    /// What is wrong, in words a user can act on.
    pub message: String,
}

impl InputError {
    /// An error about the file as a whole.
    pub fn file(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        InputError {
            path: path.into(),
            line: None,
            field: None,
            message: message.into(),
        }
    }

    /// An error at one line, about one field.
    pub fn at(
        path: impl Into<PathBuf>,
        line: usize,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        InputError {
            path: path.into(),
            line: Some(line),
            field: Some(field.into()),
            message: message.into(),
        }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if let Some(field) = &self.field {
            write!(f, ": `{field}`")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for InputError {}

/// The interval a numeric input must lie in, each end closed or open.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    /// Whether `lo` itself is allowed.
    pub lo_closed: bool,
    /// Whether `hi` itself is allowed.
    pub hi_closed: bool,
}

impl Bounds {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Bounds {
            lo,
            hi,
            lo_closed: true,
            hi_closed: true,
        }
    }

    /// `(lo, hi)`.
    pub const fn open(lo: f64, hi: f64) -> Self {
        Bounds {
            lo,
            hi,
            lo_closed: false,
            hi_closed: false,
        }
    }

    /// `(0, hi]`: a strictly positive quantity.
    pub const fn positive(hi: f64) -> Self {
        Bounds {
            lo: 0.0,
            hi,
            lo_closed: false,
            hi_closed: true,
        }
    }

    /// `(lo, hi]`.
    pub const fn above(lo: f64, hi: f64) -> Self {
        Bounds {
            lo,
            hi,
            lo_closed: false,
            hi_closed: true,
        }
    }

    /// `[lo, hi)`.
    pub const fn below(lo: f64, hi: f64) -> Self {
        Bounds {
            lo,
            hi,
            lo_closed: true,
            hi_closed: false,
        }
    }

    /// The same interval in another unit: both ends times `factor` (> 0).
    pub fn scaled(self, factor: f64) -> Self {
        Bounds {
            lo: self.lo * factor,
            hi: self.hi * factor,
            ..self
        }
    }

    /// Whether `v` lies inside (false for NaN).
    pub fn contains(&self, v: f64) -> bool {
        let lo_ok = if self.lo_closed {
            v >= self.lo
        } else {
            v > self.lo
        };
        let hi_ok = if self.hi_closed {
            v <= self.hi
        } else {
            v < self.hi
        };
        lo_ok && hi_ok
    }
}

/// A number as people write a bound: `1e8` rather than `100000000`, `1e-9` rather than
/// `0.000000001` (the shortest form that reads back to the same value).
pub fn fmt_bound(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

impl fmt::Display for Bounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}{}, {}{}",
            if self.lo_closed { '[' } else { '(' },
            fmt_bound(self.lo),
            fmt_bound(self.hi),
            if self.hi_closed { ']' } else { ')' }
        )
    }
}

/// `value` if it is finite and inside `bounds`, else a message saying why (the caller adds
/// where: file, line and key, or the option's name).
pub fn check_finite_range(value: f64, bounds: Bounds) -> Result<f64, String> {
    if !value.is_finite() {
        Err(format!("{value} is not a finite number"))
    } else if !bounds.contains(value) {
        Err(format!("{} must lie in {bounds}", fmt_bound(value)))
    } else {
        Ok(value)
    }
}

/// A count (photons, members, threads…) if it lies in `lo..=hi`, else a message saying why.
pub fn check_count(value: u64, lo: u64, hi: u64) -> Result<u64, String> {
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(format!(
            "{value} must lie in {lo}..={}",
            fmt_bound(hi as f64)
        ))
    }
}

/// How a count may be written, for messages.
const COUNT_FORMS: &str = "a count is a whole number ≥ 0: 1000000, 1_000_000, 1e6 or 2.5e5";

/// A count as people write one: `1000000`, `1_000_000`, `1e6`, `2.5e5`, `1E+6` (the one parser
/// of every count read from the command line). Exact: the digits and the exponent are read as
/// decimals, so a count beyond 2⁵³ is not rounded through a float. A value that is not a whole
/// number (`1.5`, `1e-3`), negative or beyond `u64` gets a message saying so (the caller names
/// the option or key and checks the range).
pub fn parse_count(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let not_whole = || format!("`{text}` is not a whole number ({COUNT_FORMS})");
    let not_count = || format!("`{text}` is not a count ({COUNT_FORMS})");
    if t.starts_with('-') && t.len() > 1 {
        return Err(format!("`{text}` is negative ({COUNT_FORMS})"));
    }
    // Underscores only between digits, as in Rust, Python and TOML literals.
    let b = t.as_bytes();
    for (i, c) in b.iter().enumerate() {
        if *c == b'_'
            && !(i > 0 && i + 1 < b.len() && b[i - 1].is_ascii_digit() && b[i + 1].is_ascii_digit())
        {
            return Err(not_count());
        }
    }
    let t = t.strip_prefix('+').unwrap_or(t).replace('_', "");
    let (mantissa, exponent) = match t.find(['e', 'E']) {
        Some(i) => {
            let e: i64 = t[i + 1..].parse().map_err(|_| not_count())?;
            (&t[..i], e)
        }
        None => (t.as_str(), 0),
    };
    let (int, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    if (int.is_empty() && frac.is_empty())
        || !int.bytes().chain(frac.bytes()).all(|c| c.is_ascii_digit())
    {
        return Err(not_count());
    }
    // value = digits · 10^(exponent − fraction digits)
    let mut digits = format!("{int}{frac}");
    let mut exp10 = exponent - frac.len() as i64;
    while exp10 < 0 && digits.ends_with('0') {
        digits.pop();
        exp10 += 1;
    }
    let digits = digits.trim_start_matches('0');
    if exp10 < 0 && !digits.is_empty() {
        return Err(not_whole());
    }
    if digits.is_empty() {
        return Ok(0);
    }
    let too_large = || format!("`{text}` is too large for a count");
    let mut v: u64 = digits.parse().map_err(|_| too_large())?;
    for _ in 0..exp10 {
        v = v.checked_mul(10).ok_or_else(too_large)?;
    }
    Ok(v)
}

/// A count given as a float (a TOML `photons = 1e6` is a float): the same rule as
/// [`parse_count`], whole and ≥ 0, and not beyond 2⁵³, above which a float no longer says
/// which whole number was meant.
pub fn count_from_f64(v: f64) -> Result<u64, String> {
    const EXACT: f64 = 9_007_199_254_740_992.0; // 2⁵³
    if !v.is_finite() || v.fract() != 0.0 {
        Err(format!("{v} is not a whole number ({COUNT_FORMS})"))
    } else if v < 0.0 {
        Err(format!("{v} is negative ({COUNT_FORMS})"))
    } else if v > EXACT {
        Err(format!(
            "{} is beyond 2^53 as a float: write the count as an integer",
            fmt_bound(v)
        ))
    } else {
        Ok(v as u64)
    }
}

/// Serde helpers for counts in input files: an integer, or a float that is a whole number
/// (`photons = 1e6`, which TOML reads as a float), by the rule of [`count_from_f64`].
pub mod serde_count {
    use serde::de::{self, Deserializer, Visitor};

    /// For an `Option<T>` field (with `#[serde(default, deserialize_with = …)]`).
    pub fn option<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
    where
        D: Deserializer<'de>,
        T: TryFrom<u64>,
    {
        struct V<T>(std::marker::PhantomData<T>);
        impl<T: TryFrom<u64>> V<T> {
            fn fit<E: de::Error>(v: u64) -> Result<Option<T>, E> {
                T::try_from(v)
                    .map(Some)
                    .map_err(|_| E::custom(format!("{v} is too large for this count")))
            }
        }
        impl<'de, T: TryFrom<u64>> Visitor<'de> for V<T> {
            type Value = Option<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a whole number ≥ 0 (an integer, or a float such as 1e6)")
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                Self::fit(v)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                let v = u64::try_from(v).map_err(|_| {
                    E::custom(format!("{v} is negative (a count is a whole number ≥ 0)"))
                })?;
                Self::fit(v)
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
                Self::fit(super::count_from_f64(v).map_err(E::custom)?)
            }
            fn visit_some<D2: Deserializer<'de>>(self, d: D2) -> Result<Self::Value, D2::Error> {
                d.deserialize_any(self)
            }
            fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
                Ok(None)
            }
        }
        d.deserialize_option(V(std::marker::PhantomData))
    }
}

/// The UTF-8 byte-order mark some editors put at the start of a text file; it is not part of
/// the first line's content.
pub fn strip_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

/// Read a file to a string (without a leading byte-order mark), mapping an I/O failure to an
/// [`InputError`] naming the file.
pub fn read_to_string(path: &Path) -> Result<String, InputError> {
    let mut text = std::fs::read_to_string(path)
        .map_err(|e| InputError::file(path, format!("cannot read the file: {e}")))?;
    if text.starts_with('\u{feff}') {
        text.drain(..'\u{feff}'.len_utf8());
    }
    Ok(text)
}

/// A comma-separated table: a header of column names, then rows, with `#` comment lines.
#[derive(Debug, Clone)]
pub struct CsvTable {
    path: PathBuf,
    header: Vec<String>,
    header_line: usize,
    /// (1-based line number, fields)
    rows: Vec<(usize, Vec<String>)>,
    /// The comment lines (without the leading `#`), in order, for headers carrying metadata.
    pub comments: Vec<String>,
    /// The 1-based line number of each comment line.
    comment_lines: Vec<usize>,
}

impl CsvTable {
    /// Parse `text` (the contents of `path`); `path` is only used in error messages.
    pub fn parse(path: impl Into<PathBuf>, text: &str) -> Result<Self, InputError> {
        let path = path.into();
        let mut header: Option<(usize, Vec<String>)> = None;
        let mut rows = Vec::new();
        let mut comments = Vec::new();
        let mut comment_lines = Vec::new();
        for (i, raw) in strip_bom(text).lines().enumerate() {
            let line_no = i + 1;
            let line = raw.trim();
            if line.is_empty() {
                continue;
            }
            if let Some(c) = line.strip_prefix('#') {
                comments.push(c.trim().to_string());
                comment_lines.push(line_no);
                continue;
            }
            let fields: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
            match &header {
                None => header = Some((line_no, fields)),
                Some((_, h)) => {
                    if fields.len() != h.len() {
                        return Err(InputError::at(
                            &path,
                            line_no,
                            "row",
                            format!("has {} fields, the header has {}", fields.len(), h.len()),
                        ));
                    }
                    rows.push((line_no, fields));
                }
            }
        }
        let (header_line, header) =
            header.ok_or_else(|| InputError::file(&path, "no header line (the file is empty)"))?;
        Ok(CsvTable {
            path,
            header,
            header_line,
            rows,
            comments,
            comment_lines,
        })
    }

    /// The 1-based line number of comment `i` (an index into [`Self::comments`]).
    pub fn comment_line(&self, i: usize) -> usize {
        self.comment_lines[i]
    }

    /// Read and parse a file.
    pub fn read(path: &Path) -> Result<Self, InputError> {
        Self::parse(path, &read_to_string(path)?)
    }

    /// The file this table came from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Line number of the header.
    pub fn header_line(&self) -> usize {
        self.header_line
    }

    /// Column names, in order.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there are no data rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Index of a column, or an error naming the missing column.
    pub fn column(&self, name: &str) -> Result<usize, InputError> {
        self.header.iter().position(|h| h == name).ok_or_else(|| {
            InputError::at(
                &self.path,
                self.header_line,
                name,
                format!(
                    "missing column (the header has: {})",
                    self.header.join(", ")
                ),
            )
        })
    }

    /// Index of an optional column.
    pub fn column_opt(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// Rows as (line number, fields).
    pub fn rows(&self) -> impl Iterator<Item = (usize, &[String])> {
        self.rows.iter().map(|(l, f)| (*l, f.as_slice()))
    }

    /// Parse field `col` of row `row` as a finite f64.
    pub fn f64_at(&self, row: usize, col: usize) -> Result<f64, InputError> {
        let (line, fields) = &self.rows[row];
        parse_f64(&self.path, *line, &self.header[col], &fields[col])
    }

    /// Parse field `col` of row `row` as a finite f64 inside `bounds`.
    pub fn f64_in(&self, row: usize, col: usize, bounds: Bounds) -> Result<f64, InputError> {
        let (line, fields) = &self.rows[row];
        parse_f64_in(&self.path, *line, &self.header[col], &fields[col], bounds)
    }

    /// A whole column parsed as finite f64 values inside `bounds`.
    pub fn f64_column_in(&self, name: &str, bounds: Bounds) -> Result<Vec<f64>, InputError> {
        let col = self.column(name)?;
        (0..self.rows.len())
            .map(|r| self.f64_in(r, col, bounds))
            .collect()
    }

    /// A whole column parsed as finite f64 values.
    pub fn f64_column(&self, name: &str) -> Result<Vec<f64>, InputError> {
        let col = self.column(name)?;
        (0..self.rows.len()).map(|r| self.f64_at(r, col)).collect()
    }

    /// Line number of data row `row`.
    pub fn line_of(&self, row: usize) -> usize {
        self.rows[row].0
    }
}

/// Parse a finite f64, naming file, line and field on failure.
pub fn parse_f64(path: &Path, line: usize, field: &str, text: &str) -> Result<f64, InputError> {
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| InputError::at(path, line, field, format!("`{text}` is not a number")))?;
    if !v.is_finite() {
        return Err(InputError::at(
            path,
            line,
            field,
            format!("`{text}` is not finite"),
        ));
    }
    Ok(v)
}

/// Parse a finite f64 inside `bounds`, naming file, line and field on failure.
pub fn parse_f64_in(
    path: &Path,
    line: usize,
    field: &str,
    text: &str,
    bounds: Bounds,
) -> Result<f64, InputError> {
    let v = parse_f64(path, line, field, text)?;
    check_finite_range(v, bounds).map_err(|m| InputError::at(path, line, field, m))
}

/// The names scene files and the command line use for the built-in choices, kept here, below
/// the modules that implement them, so that a scene is checked against them without those
/// modules (each module's enum lists its variants in the order of its names here).
pub mod names {
    /// AFGL standard atmospheres (`crate::atmosphere::StandardAtmosphere`).
    pub const STANDARD_ATMOSPHERES: [&str; 6] = [
        "tropical",
        "midlatitude_summer",
        "midlatitude_winter",
        "subarctic_summer",
        "subarctic_winter",
        "us_standard",
    ];
    /// OPAC aerosol types (`crate::particles::opac::OpacType`), in kebab case.
    pub const OPAC_TYPES: [&str; 8] = [
        "continental-clean",
        "continental-average",
        "continental-polluted",
        "urban",
        "maritime-clean",
        "maritime-polluted",
        "maritime-tropical",
        "arctic",
    ];
    /// Line shapes of the line-by-line computation (`crate::spectroscopy::LineShapeModel`).
    pub const GAS_LINE_SHAPES: [&str; 3] = ["voigt", "sdvoigt", "ht"];

    /// The index of a standard atmosphere's name, or the message naming the known ones.
    pub fn standard_atmosphere(s: &str) -> Result<usize, String> {
        STANDARD_ATMOSPHERES
            .iter()
            .position(|n| *n == s)
            .ok_or_else(|| {
                format!(
                    "unknown standard atmosphere `{s}` (known: {})",
                    STANDARD_ATMOSPHERES.join(", ")
                )
            })
    }

    /// The index of an OPAC type's name (kebab or snake case, case-insensitive), if known.
    pub fn opac_type(name: &str) -> Option<usize> {
        let n = name.trim().to_ascii_lowercase().replace('_', "-");
        OPAC_TYPES.iter().position(|t| *t == n)
    }

    /// The index of a gas line shape's name, or the message naming the known ones.
    pub fn gas_line_shape(s: &str) -> Result<usize, String> {
        GAS_LINE_SHAPES.iter().position(|n| *n == s).ok_or_else(|| {
            format!(
                "unknown line shape `{s}` (known: {})",
                GAS_LINE_SHAPES.join(", ")
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_header_rows_and_comments() {
        let t = CsvTable::parse("x.csv", "# c1\na,b\n1,2\n\n# c2\n3,4e1\n").unwrap();
        assert_eq!(t.header(), ["a", "b"]);
        assert_eq!(t.f64_column("b").unwrap(), vec![2.0, 40.0]);
        assert_eq!(t.comments, vec!["c1", "c2"]);
        assert_eq!(t.line_of(1), 6);
    }

    #[test]
    fn bad_number_names_file_line_and_column() {
        let t = CsvTable::parse("x.csv", "a,b\n1,zz\n").unwrap();
        let e = t.f64_column("b").unwrap_err();
        assert_eq!(e.to_string(), "x.csv:2: `b`: `zz` is not a number");
    }

    #[test]
    fn a_byte_order_mark_is_not_part_of_the_first_line() {
        let t = CsvTable::parse("x.csv", "\u{feff}# c\na,b\n1,2\n").unwrap();
        assert_eq!(t.header(), ["a", "b"]);
        let t = CsvTable::parse("x.csv", "\u{feff}a,b\n1,2\n").unwrap();
        assert_eq!(t.header(), ["a", "b"]);
    }

    #[test]
    fn bounds_refuse_nan_infinity_and_both_sides() {
        let b = Bounds::positive(10.0);
        assert!(check_finite_range(f64::NAN, b).is_err());
        assert!(check_finite_range(f64::INFINITY, Bounds::closed(0.0, f64::MAX)).is_err());
        assert!(check_finite_range(0.0, b).is_err());
        assert!(check_finite_range(10.0, b).is_ok());
        assert!(check_finite_range(10.000001, b).is_err());
        assert!(check_finite_range(-0.0, Bounds::closed(0.0, 1.0)).is_ok());
        assert!(check_finite_range(1.0, Bounds::below(0.0, 1.0)).is_err());
        assert_eq!(b.to_string(), "(0, 10]");
        assert_eq!(Bounds::closed(-1e4, 1e8).to_string(), "[-10000, 1e8]");
        assert!(check_count(0, 1, 5).is_err());
        assert!(check_count(5, 1, 5).is_ok());
    }

    #[test]
    fn counts_read_in_every_notation_people_use() {
        for (t, v) in [
            ("1000000", 1_000_000),
            ("1_000_000", 1_000_000),
            ("1e6", 1_000_000),
            ("1E6", 1_000_000),
            ("1e+6", 1_000_000),
            ("2.5e5", 250_000),
            ("+7", 7),
            (" 12 ", 12),
            ("0", 0),
            ("0e0", 0),
            ("0.0", 0),
            ("1.0", 1),
            ("1.50e1", 15),
            ("10e-1", 1),
            ("18446744073709551615", u64::MAX),
            ("1234567890123456789", 1_234_567_890_123_456_789),
            ("1.234567890123456789e18", 1_234_567_890_123_456_789),
        ] {
            assert_eq!(parse_count(t), Ok(v), "{t}");
        }
        for t in ["1.5", "1e-3", "2.55e1"] {
            let e = parse_count(t).unwrap_err();
            assert!(e.contains("is not a whole number"), "{t}: {e}");
        }
        for t in [
            "", "e6", "1e", "abc", "_1", "1_", "1__0", "1._5", "0x10", "inf", "nan", "1.2.3",
        ] {
            assert!(
                parse_count(t).unwrap_err().contains("is not a count"),
                "{t}"
            );
        }
        assert!(parse_count("-5").unwrap_err().contains("negative"));
        assert!(parse_count("1e20").unwrap_err().contains("too large"));
        assert!(
            parse_count("18446744073709551616")
                .unwrap_err()
                .contains("too large")
        );
    }

    #[test]
    fn a_count_given_as_a_float_must_be_whole() {
        assert_eq!(count_from_f64(1e6), Ok(1_000_000));
        assert_eq!(count_from_f64(0.0), Ok(0));
        assert!(
            count_from_f64(1.5)
                .unwrap_err()
                .contains("not a whole number")
        );
        assert!(
            count_from_f64(1e-3)
                .unwrap_err()
                .contains("not a whole number")
        );
        assert!(count_from_f64(-1.0).unwrap_err().contains("negative"));
        assert!(count_from_f64(1e17).unwrap_err().contains("2^53"));
        assert!(count_from_f64(f64::NAN).is_err());
    }

    #[test]
    fn ragged_row_is_an_error() {
        let e = CsvTable::parse("x.csv", "a,b\n1\n").unwrap_err();
        assert_eq!(e.line, Some(2));
    }
}
