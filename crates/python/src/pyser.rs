//! A report straight into Python objects: a `serde` serializer that builds what
//! `json.loads(serde_json::to_string(value))` would build (dicts in the value's field order,
//! lists, str, int, float, bool, `None`; a non-finite float `None`; map keys as strings;
//! enums as `serde_json` writes them), without the text in between.

use std::collections::HashMap;
use std::fmt;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::{Mutex, OnceLock};

use pyo3::BoundObject;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use serde::ser::{self, Serialize};

/// What went wrong: a Python error, or a value JSON has no form for.
#[derive(Debug)]
pub(crate) enum Error {
    Py(PyErr),
    Custom(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Py(e) => write!(f, "{e}"),
            Self::Custom(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Error {}

impl ser::Error for Error {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Self::Custom(msg.to_string())
    }
}

impl From<PyErr> for Error {
    fn from(e: PyErr) -> Self {
        Self::Py(e)
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> Self {
        match e {
            Error::Py(e) => e,
            Error::Custom(m) => {
                pyo3::exceptions::PyRuntimeError::new_err(format!("serialising a report: {m}"))
            }
        }
    }
}

type Out<'py> = Result<Bound<'py, PyAny>, Error>;

/// `value` as Python objects.
pub(crate) fn to_py<'py>(py: Python<'py>, value: &impl Serialize) -> PyResult<Bound<'py, PyAny>> {
    Ok(value.serialize(Ser(py, false))?)
}

/// The serializer; `.1`: what it serializes is a map key (a string key is taken from
/// [`key_string`]'s cache).
#[derive(Clone, Copy)]
struct Ser<'py>(Python<'py>, bool);

/// At most this many key strings are kept ([`key_string`]); a report's keys are a few
/// dozen names (fields, columns, joint names), so only a stream of ever new ones passes it.
const MAX_KEYS: usize = 1024;

/// FNV-1a: the cache's keys are short names, which it hashes in a few nanoseconds (the
/// standard hasher takes several times that), and it holds at most [`MAX_KEYS`] of them.
#[derive(Default)]
struct Fnv(u64);

impl Hasher for Fnv {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        let mut h = if self.0 == 0 {
            0xcbf2_9ce4_8422_2325
        } else {
            self.0
        };
        for b in bytes {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        self.0 = h;
    }
}

type KeyCache = HashMap<Box<str>, Py<PyString>, BuildHasherDefault<Fnv>>;

/// The Python string of a dict key `k`, made once: reports use the same keys every call,
/// and a cached string is neither built nor hashed again (Python keeps its hash in it).
/// Past [`MAX_KEYS`] a key is made each time.
fn key_string<'py>(py: Python<'py>, k: &str) -> Bound<'py, PyString> {
    static KEYS: OnceLock<Mutex<KeyCache>> = OnceLock::new();
    let mut keys = KEYS
        .get_or_init(|| Mutex::new(KeyCache::default()))
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(s) = keys.get(k) {
        return s.bind(py).clone();
    }
    let s = PyString::new(py, k);
    if keys.len() < MAX_KEYS {
        keys.insert(k.into(), s.clone().unbind());
    }
    s
}

fn any<'py, T>(py: Python<'py>, v: T) -> Out<'py>
where
    T: IntoPyObject<'py>,
    PyErr: From<T::Error>,
{
    Ok(v.into_pyobject(py)
        .map_err(PyErr::from)?
        .into_any()
        .into_bound())
}

/// `{variant: value}`, `serde_json`'s form of a non-unit enum variant.
fn tagged<'py>(py: Python<'py>, variant: &str, value: Bound<'py, PyAny>) -> Out<'py> {
    let d = PyDict::new(py);
    d.set_item(variant, value)?;
    Ok(d.into_any())
}

impl<'py> ser::Serializer for Ser<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    type SerializeSeq = Seq<'py>;
    type SerializeTuple = Seq<'py>;
    type SerializeTupleStruct = Seq<'py>;
    type SerializeTupleVariant = Seq<'py>;
    type SerializeMap = Map<'py>;
    type SerializeStruct = Map<'py>;
    type SerializeStructVariant = Map<'py>;

    fn serialize_bool(self, v: bool) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_i8(self, v: i8) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_i16(self, v: i16) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_i32(self, v: i32) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_i64(self, v: i64) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_i128(self, v: i128) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_u8(self, v: u8) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_u16(self, v: u16) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_u32(self, v: u32) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_u64(self, v: u64) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_u128(self, v: u128) -> Out<'py> {
        any(self.0, v)
    }
    fn serialize_f32(self, v: f32) -> Out<'py> {
        self.serialize_f64(f64::from(v))
    }
    fn serialize_f64(self, v: f64) -> Out<'py> {
        // JSON has no NaN or infinity: serde_json writes null.
        if v.is_finite() {
            any(self.0, v)
        } else {
            Ok(self.0.None().into_bound(self.0))
        }
    }
    fn serialize_char(self, v: char) -> Out<'py> {
        any(self.0, v.to_string())
    }
    fn serialize_str(self, v: &str) -> Out<'py> {
        if self.1 {
            return Ok(key_string(self.0, v).into_any());
        }
        Ok(PyString::new(self.0, v).into_any())
    }
    fn serialize_bytes(self, v: &[u8]) -> Out<'py> {
        // serde_json writes bytes as an array of numbers.
        Ok(PyList::new(self.0, v)?.into_any())
    }
    fn serialize_none(self) -> Out<'py> {
        Ok(self.0.None().into_bound(self.0))
    }
    fn serialize_some<T: ?Sized + Serialize>(self, value: &T) -> Out<'py> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Out<'py> {
        self.serialize_none()
    }
    fn serialize_unit_struct(self, _name: &'static str) -> Out<'py> {
        self.serialize_none()
    }
    fn serialize_unit_variant(self, _n: &'static str, _i: u32, variant: &'static str) -> Out<'py> {
        self.serialize_str(variant)
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(
        self,
        _name: &'static str,
        value: &T,
    ) -> Out<'py> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        value: &T,
    ) -> Out<'py> {
        tagged(self.0, variant, value.serialize(self)?)
    }
    fn serialize_seq(self, _len: Option<usize>) -> Result<Seq<'py>, Error> {
        Ok(Seq {
            py: self.0,
            list: PyList::empty(self.0),
            variant: None,
        })
    }
    fn serialize_tuple(self, len: usize) -> Result<Seq<'py>, Error> {
        self.serialize_seq(Some(len))
    }
    fn serialize_tuple_struct(self, _name: &'static str, len: usize) -> Result<Seq<'py>, Error> {
        self.serialize_seq(Some(len))
    }
    fn serialize_tuple_variant(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        _len: usize,
    ) -> Result<Seq<'py>, Error> {
        Ok(Seq {
            py: self.0,
            list: PyList::empty(self.0),
            variant: Some(variant),
        })
    }
    fn serialize_map(self, _len: Option<usize>) -> Result<Map<'py>, Error> {
        Ok(Map {
            py: self.0,
            dict: PyDict::new(self.0),
            key: None,
            variant: None,
        })
    }
    fn serialize_struct(self, _name: &'static str, len: usize) -> Result<Map<'py>, Error> {
        self.serialize_map(Some(len))
    }
    fn serialize_struct_variant(
        self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        _len: usize,
    ) -> Result<Map<'py>, Error> {
        Ok(Map {
            py: self.0,
            dict: PyDict::new(self.0),
            key: None,
            variant: Some(variant),
        })
    }
}

pub(crate) struct Seq<'py> {
    py: Python<'py>,
    list: Bound<'py, PyList>,
    variant: Option<&'static str>,
}

impl<'py> Seq<'py> {
    fn push<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Error> {
        self.list.append(value.serialize(Ser(self.py, false))?)?;
        Ok(())
    }
    fn done(self) -> Out<'py> {
        match self.variant {
            Some(v) => tagged(self.py, v, self.list.into_any()),
            None => Ok(self.list.into_any()),
        }
    }
}

impl<'py> ser::SerializeSeq for Seq<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Error> {
        self.push(value)
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

impl<'py> ser::SerializeTuple for Seq<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Error> {
        self.push(value)
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

impl<'py> ser::SerializeTupleStruct for Seq<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Error> {
        self.push(value)
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

impl<'py> ser::SerializeTupleVariant for Seq<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Error> {
        self.push(value)
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

pub(crate) struct Map<'py> {
    py: Python<'py>,
    dict: Bound<'py, PyDict>,
    key: Option<Bound<'py, PyAny>>,
    variant: Option<&'static str>,
}

impl<'py> Map<'py> {
    fn done(self) -> Out<'py> {
        match self.variant {
            Some(v) => tagged(self.py, v, self.dict.into_any()),
            None => Ok(self.dict.into_any()),
        }
    }
}

/// A map key as `serde_json` writes it: a string, or a number or bool as its text.
fn key<'py, T: ?Sized + Serialize>(py: Python<'py>, k: &T) -> Out<'py> {
    let v = k.serialize(Ser(py, true))?;
    if v.is_instance_of::<PyString>() {
        return Ok(v);
    }
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Ok(PyString::new(py, if v.is_truthy()? { "true" } else { "false" }).into_any());
    }
    if v.is_instance_of::<pyo3::types::PyInt>() || v.is_instance_of::<pyo3::types::PyFloat>() {
        return Ok(v.str()?.into_any());
    }
    Err(Error::Custom("a map key must be a string".into()))
}

impl<'py> ser::SerializeMap for Map<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_key<T: ?Sized + Serialize>(&mut self, k: &T) -> Result<(), Error> {
        self.key = Some(key(self.py, k)?);
        Ok(())
    }
    fn serialize_value<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Error> {
        let k = self
            .key
            .take()
            .ok_or_else(|| Error::Custom("a map value without its key".into()))?;
        self.dict
            .set_item(k, value.serialize(Ser(self.py, false))?)?;
        Ok(())
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

impl<'py> ser::SerializeStruct for Map<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        name: &'static str,
        value: &T,
    ) -> Result<(), Error> {
        self.dict.set_item(
            key_string(self.py, name),
            value.serialize(Ser(self.py, false))?,
        )?;
        Ok(())
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

impl<'py> ser::SerializeStructVariant for Map<'py> {
    type Ok = Bound<'py, PyAny>;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        name: &'static str,
        value: &T,
    ) -> Result<(), Error> {
        self.dict.set_item(
            key_string(self.py, name),
            value.serialize(Ser(self.py, false))?,
        )?;
        Ok(())
    }
    fn end(self) -> Out<'py> {
        self.done()
    }
}

// ---------------------------------------------------------------------------------------
// Requests: Python objects to JSON text
// ---------------------------------------------------------------------------------------

/// Writes `s` as a JSON string.
fn json_string(out: &mut String, s: &str) {
    out.push('"');
    // Runs of plain characters are copied whole; only quotes, backslashes and control
    // characters are escaped.
    let mut from = 0;
    for (k, b) in s.bytes().enumerate() {
        let escape = match b {
            b'"' => "\\\"",
            b'\\' => "\\\\",
            0..=0x1f => "",
            _ => continue,
        };
        out.push_str(&s[from..k]);
        if escape.is_empty() {
            use std::fmt::Write as _;
            let _ = write!(out, "\\u{b:04x}");
        } else {
            out.push_str(escape);
        }
        from = k + 1;
    }
    out.push_str(&s[from..]);
    out.push('"');
}

/// Writes a Python request (dicts with string keys, lists, tuples, strings, numbers, bools,
/// `None`, and anything with numpy's `tolist`) as JSON text, within
/// [`MAX_REQUEST_BYTES`](robobus::frontend::parse::MAX_REQUEST_BYTES) and `MAX_DEPTH`
/// levels: the library then parses it as it parses any request's text (`serde_json`
/// reads text faster than it reads its own value tree). Each value's type is asked once,
/// in the order requests use them (no failed conversion per value).
pub(crate) fn json_text(
    py: Python<'_>,
    v: &Bound<'_, PyAny>,
    depth: usize,
    out: &mut String,
) -> PyResult<()> {
    use pyo3::types::{PyBool, PyFloat, PyInt, PyTuple};
    use std::fmt::Write as _;
    let bad = |what: String| crate::raise(py, robobus::ErrorKind::BadInput, &what, None);
    if depth > crate::MAX_DEPTH {
        return Err(bad(format!(
            "request: nested deeper than {} levels; nothing was sent",
            crate::MAX_DEPTH
        )));
    }
    if out.len() > robobus::frontend::parse::MAX_REQUEST_BYTES {
        return Err(crate::too_long(py));
    }
    if let Ok(d) = v.cast_exact::<PyDict>() {
        return json_object(py, d, depth, out);
    }
    if let Ok(s) = v.cast_exact::<PyString>() {
        json_string(out, s.to_str()?);
    } else if v.is_none() {
        out.push_str("null");
    } else if v.is_exact_instance_of::<PyBool>() {
        out.push_str(if v.is_truthy()? { "true" } else { "false" });
    } else if v.is_instance_of::<PyInt>() {
        // (`bool` has no subclasses: every bool was written above.)
        if let Ok(i) = v.extract::<i64>() {
            out.push_str(itoa(i, &mut [0u8; 20]));
        } else if let Ok(u) = v.extract::<u64>() {
            let _ = write!(out, "{u}");
        } else {
            return Err(bad(format!(
                "request: the number {v} is out of range (allowed: 64-bit integers); nothing \
                 was sent"
            )));
        }
    } else if let Ok(f) = v.cast::<PyFloat>() {
        let x = f.value();
        if !x.is_finite() {
            return Err(bad(format!(
                "request: the number {x} is not finite (allowed: finite numbers); nothing was sent"
            )));
        }
        // `{:?}` keeps a float a float (`1.0`, not `1`), as Python's json writes it.
        let _ = write!(out, "{x:?}");
    } else if let Ok(l) = v.cast::<PyList>() {
        out.push('[');
        for (n, item) in l.iter().enumerate() {
            if n > 0 {
                out.push(',');
            }
            json_text(py, &item, depth + 1, out)?;
        }
        out.push(']');
    } else if let Ok(t) = v.cast::<PyTuple>() {
        out.push('[');
        for (n, item) in t.iter().enumerate() {
            if n > 0 {
                out.push(',');
            }
            json_text(py, &item, depth + 1, out)?;
        }
        out.push(']');
    } else if let Ok(s) = v.cast::<PyString>() {
        json_string(out, s.to_str()?);
    } else if let Ok(d) = v.cast::<PyDict>() {
        return json_object(py, d, depth, out);
    } else if let Ok(plain) = v.call_method0("tolist")
        && !plain.is(v)
    {
        // numpy arrays and scalars.
        json_text(py, &plain, depth + 1, out)?;
    } else {
        return Err(bad(format!(
            "request: a {} is not a JSON value (allowed: dict, list, str, int, float, bool, \
             None); nothing was sent",
            v.get_type().name()?
        )));
    }
    Ok(())
}

/// A dict's items as a JSON object (its keys strings).
fn json_object(
    py: Python<'_>,
    d: &Bound<'_, PyDict>,
    depth: usize,
    out: &mut String,
) -> PyResult<()> {
    out.push('{');
    for (n, (k, item)) in d.iter().enumerate() {
        let key = k.cast::<PyString>().map_err(|_| {
            crate::raise(
                py,
                robobus::ErrorKind::BadInput,
                &format!("request: the key {k} is not a string; nothing was sent"),
                None,
            )
        })?;
        if n > 0 {
            out.push(',');
        }
        json_string(out, key.to_str()?);
        out.push(':');
        json_text(py, &item, depth + 1, out)?;
    }
    out.push('}');
    Ok(())
}

/// `i` in decimal, written into `buf`.
fn itoa(i: i64, buf: &mut [u8; 20]) -> &str {
    let mut k = buf.len();
    let mut n = i.unsigned_abs();
    loop {
        k -= 1;
        // A digit: 0..=9.
        buf[k] = b'0' + u8::try_from(n % 10).unwrap_or(0);
        n /= 10;
        if n == 0 {
            break;
        }
    }
    if i < 0 {
        k -= 1;
        buf[k] = b'-';
    }
    std::str::from_utf8(&buf[k..]).unwrap_or("0")
}
