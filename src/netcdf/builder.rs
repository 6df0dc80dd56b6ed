//! A data set in memory (dimensions, variables, attributes), built up, then written at once
//! over the `netcdf3` crate ([`Dataset::encode`]) or handed over as it is (the Python package
//! turns the same value into an `xarray.Dataset`, so that a run returned to Python and its
//! `run.nc` hold the same variables).

use std::cell::RefCell;
use std::io::{Cursor, Seek, SeekFrom, Write};
use std::rc::Rc;

use netcdf3::{DataSet, FileWriter, NC_FILL_F64, Version};

use super::{NetcdfError, RUN_FILE};

/// An attribute value.
#[derive(Debug, Clone, PartialEq)]
pub enum Attr {
    /// Text.
    Text(String),
    /// Doubles.
    F64(Vec<f64>),
}

impl Attr {
    /// A text attribute.
    pub fn text(s: impl Into<String>) -> Attr {
        Attr::Text(s.into())
    }
}

/// A variable's values, row-major over its dimensions.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// Doubles; a missing value is `_FillValue` ([`NC_FILL_F64`]) where the variable has one.
    F64(Vec<f64>),
    /// Char array, row-major, each row NUL-padded to the last dimension's length (text over
    /// the other dimensions, CF-1.8 §2.2).
    Char(Vec<u8>),
}

/// One variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Var {
    /// Its name.
    pub name: String,
    /// Its dimensions, slowest first.
    pub dims: Vec<String>,
    /// Its values.
    pub values: Values,
    /// Its attributes, in order.
    pub attrs: Vec<(String, Attr)>,
}

impl Var {
    pub(crate) fn attrs<const N: usize>(&mut self, attrs: [(&str, &str); N]) -> &mut Var {
        for (k, v) in attrs {
            self.attrs.push((k.into(), Attr::text(v)));
        }
        self
    }

    /// Mark non-finite values as missing: they become `_FillValue` (NetCDF's default fill
    /// for doubles, so that a reader that ignores the attribute still sees the same number).
    pub(crate) fn fill(&mut self) -> &mut Var {
        if let Values::F64(v) = &mut self.values {
            for x in v.iter_mut().filter(|x| !x.is_finite()) {
                *x = NC_FILL_F64;
            }
        }
        self.attrs
            .push(("_FillValue".into(), Attr::F64(vec![NC_FILL_F64])));
        self
    }
}

/// A whole data set: what one NetCDF file holds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Dataset {
    /// Dimensions and their lengths, in order.
    pub dims: Vec<(String, usize)>,
    /// Variables, in order.
    pub vars: Vec<Var>,
    /// Global attributes, in order.
    pub globals: Vec<(String, Attr)>,
}

impl Dataset {
    pub(crate) fn dim(&mut self, name: &str, len: usize) {
        self.dims.push((name.into(), len));
    }

    pub(crate) fn global(&mut self, name: &str, value: Attr) {
        self.globals.push((name.into(), value));
    }

    pub(crate) fn f64(&mut self, name: &str, dims: &[&str], values: Vec<f64>) -> &mut Var {
        self.vars.push(Var {
            name: name.into(),
            dims: dims.iter().map(|d| d.to_string()).collect(),
            values: Values::F64(values),
            attrs: Vec::new(),
        });
        let n = self.vars.len() - 1;
        &mut self.vars[n]
    }

    /// A text variable over `dim`: a char array (`dim`, `<name>_strlen`) as CF-1.8 §2.2 has
    /// it, with `_Encoding = "utf-8"` so that netCDF4-python and xarray read strings.
    pub(crate) fn text(&mut self, name: &str, dim: &str, values: &[String]) -> &mut Var {
        let strlen = values.iter().map(String::len).max().unwrap_or(0).max(1);
        let strlen_dim = format!("{name}_strlen");
        self.dim(&strlen_dim, strlen);
        let mut chars = vec![0u8; values.len() * strlen];
        for (row, v) in chars.chunks_mut(strlen).zip(values) {
            row[..v.len()].copy_from_slice(v.as_bytes());
        }
        self.vars.push(Var {
            name: name.into(),
            dims: vec![dim.into(), strlen_dim],
            values: Values::Char(chars),
            attrs: vec![("_Encoding".into(), Attr::text("utf-8"))],
        });
        let n = self.vars.len() - 1;
        &mut self.vars[n]
    }

    /// Refuse a non-finite number where it cannot be `_FillValue` (a variable without one, an
    /// attribute): it would be `NaN` or `inf` in the file or in the caller's data set.
    pub fn check(&self) -> Result<(), NetcdfError> {
        let non_finite = |what: String| {
            NetcdfError::Layout(format!(
                "{what} holds a value that is not finite and cannot be _FillValue (a bug in lidarsim; please report it)"
            ))
        };
        for (name, a) in &self.globals {
            if matches!(a, Attr::F64(v) if v.iter().any(|x| !x.is_finite())) {
                return Err(non_finite(format!("the global attribute `{name}`")));
            }
        }
        for v in &self.vars {
            for (name, a) in &v.attrs {
                if matches!(a, Attr::F64(x) if x.iter().any(|x| !x.is_finite())) {
                    return Err(non_finite(format!("the attribute `{}:{name}`", v.name)));
                }
            }
            if let Values::F64(x) = &v.values
                && x.iter().any(|x| !x.is_finite())
            {
                return Err(non_finite(format!("the variable `{}`", v.name)));
            }
        }
        Ok(())
    }

    /// The NetCDF-3 file (64-bit offsets): define the data set, write header and values into
    /// memory, and return the bytes; refused as [`Self::check`] refuses.
    pub fn encode(&self) -> Result<Vec<u8>, NetcdfError> {
        self.check()?;
        let err = |e: &dyn std::fmt::Debug| NetcdfError::Format(format!("{e:?}"));
        let mut ds = DataSet::new();
        for (name, len) in &self.dims {
            ds.add_fixed_dim(name, *len).map_err(|e| err(&e))?;
        }
        for (name, a) in &self.globals {
            match a {
                Attr::Text(s) => ds.add_global_attr_string(name, s),
                Attr::F64(v) => ds.add_global_attr_f64(name, v.clone()),
            }
            .map_err(|e| err(&e))?;
        }
        for v in &self.vars {
            let dims: Vec<&str> = v.dims.iter().map(String::as_str).collect();
            match v.values {
                Values::F64(_) => ds.add_var_f64(&v.name, &dims),
                Values::Char(_) => ds.add_var_u8(&v.name, &dims),
            }
            .map_err(|e| err(&e))?;
            for (name, a) in &v.attrs {
                match a {
                    Attr::Text(s) => ds.add_var_attr_string(&v.name, name, s),
                    Attr::F64(x) => ds.add_var_attr_f64(&v.name, name, x.clone()),
                }
                .map_err(|e| err(&e))?;
            }
        }
        let buffer = SharedBuffer::default();
        let mut w =
            FileWriter::open_seek_write(RUN_FILE, Box::new(buffer.clone())).map_err(|e| err(&e))?;
        w.set_def(&ds, Version::Offset64Bit, 0)
            .map_err(|e| err(&e))?;
        for v in &self.vars {
            match &v.values {
                Values::F64(x) => w.write_var_f64(&v.name, x),
                Values::Char(x) => w.write_var_u8(&v.name, x),
            }
            .map_err(|e| err(&e))?;
        }
        w.close().map_err(|e| err(&e))?;
        Ok(buffer.0.take().into_inner())
    }
}

/// An in-memory file the writer (which wants to own a `'static` seekable writer) and this
/// module share, so that the bytes go to the caller's atomic output set.
#[derive(Debug, Clone, Default)]
pub(super) struct SharedBuffer(Rc<RefCell<Cursor<Vec<u8>>>>);

impl Write for SharedBuffer {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for SharedBuffer {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.0.borrow_mut().seek(pos)
    }
}
