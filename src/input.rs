//! Errors for bad input files, and a small reader for the comma-separated tables lidarsim uses.
//!
//! Every parser in lidarsim (scenes, profiles, HITRAN line files, phase-function tables,
//! partition sums) reports a problem as one [`InputError`] naming the file, the 1-based line and
//! the field (key or column). Nothing panics on user data and nothing is silently defaulted.
//!
//! [`CsvTable`] reads the project's text tables: `#` comment lines anywhere, one header line of
//! column names, then comma-separated rows. Values keep their line numbers so a bad number can be
//! reported where it stands.

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

/// Read a file to a string, mapping an I/O failure to an [`InputError`] naming the file.
pub fn read_to_string(path: &Path) -> Result<String, InputError> {
    std::fs::read_to_string(path)
        .map_err(|e| InputError::file(path, format!("cannot read the file: {e}")))
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
}

impl CsvTable {
    /// Parse `text` (the contents of `path`); `path` is only used in error messages.
    pub fn parse(path: impl Into<PathBuf>, text: &str) -> Result<Self, InputError> {
        let path = path.into();
        let mut header: Option<(usize, Vec<String>)> = None;
        let mut rows = Vec::new();
        let mut comments = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line_no = i + 1;
            let line = raw.trim();
            if line.is_empty() {
                continue;
            }
            if let Some(c) = line.strip_prefix('#') {
                comments.push(c.trim().to_string());
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
        })
    }

    /// Read and parse a file.
    pub fn read(path: &Path) -> Result<Self, InputError> {
        Self::parse(path, &read_to_string(path)?)
    }

    /// The file this table came from.
    pub fn path(&self) -> &Path {
        &self.path
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
    fn ragged_row_is_an_error() {
        let e = CsvTable::parse("x.csv", "a,b\n1\n").unwrap_err();
        assert_eq!(e.line, Some(2));
    }
}
