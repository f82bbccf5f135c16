//! NumPy `.npy` files (format version 1.0), little-endian, C order: what GPU-port engineers
//! `np.load` to compare with their own arrays.

use super::write_atomic;
use crate::error::{Error, Result};
use std::io::Write;
use std::path::Path;

/// Element types we write and read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    U8,
    F32,
    F64,
    U32,
    I32,
    U64,
}

impl Dtype {
    pub fn descr(self) -> &'static str {
        match self {
            Dtype::U8 => "|u1",
            Dtype::F32 => "<f4",
            Dtype::F64 => "<f8",
            Dtype::U32 => "<u4",
            Dtype::I32 => "<i4",
            Dtype::U64 => "<u8",
        }
    }
}

/// Little-endian bytes of a slice of plain numbers.
pub trait NpyElement: Copy {
    const DTYPE: Dtype;
    fn put(self, out: &mut Vec<u8>);
    /// The value of its `size_of::<Self>()` little-endian bytes.
    fn get(bytes: &[u8]) -> Self;
}

macro_rules! element {
    ($t:ty, $d:expr) => {
        impl NpyElement for $t {
            const DTYPE: Dtype = $d;
            fn put(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
            fn get(bytes: &[u8]) -> Self {
                <$t>::from_le_bytes(bytes.try_into().expect("one element's bytes"))
            }
        }
    };
}
element!(u8, Dtype::U8);
element!(f32, Dtype::F32);
element!(f64, Dtype::F64);
element!(u32, Dtype::U32);
element!(i32, Dtype::I32);
element!(u64, Dtype::U64);

/// The complete `.npy` bytes for `data` with `shape` (empty shape = scalar).
pub fn npy_bytes<T: NpyElement>(data: &[T], shape: &[usize]) -> Result<Vec<u8>> {
    let count: usize = shape.iter().product();
    if count != data.len() {
        return Err(Error::invalid(format!(
            "npy: shape {shape:?} needs {count} values, got {}",
            data.len()
        )));
    }
    let dims = match shape.len() {
        0 => String::new(),
        1 => format!("{},", shape[0]),
        _ => shape
            .iter()
            .map(|d| d.to_string())
            .collect::<Vec<_>>()
            .join(", "),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': ({dims}), }}",
        T::DTYPE.descr()
    );
    // Magic (6) + version (2) + length (2) + header + '\n' is a multiple of 64.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat(unpadded.next_multiple_of(64) - unpadded));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len() * 8);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for &v in data {
        v.put(&mut out);
    }
    Ok(out)
}

/// Write an `.npy` file atomically; returns its bytes (for hashing).
pub fn write_npy<T: NpyElement>(path: &Path, data: &[T], shape: &[usize]) -> Result<Vec<u8>> {
    let bytes = npy_bytes(data, shape)?;
    write_atomic(path, |w| w.write_all(&bytes))?;
    Ok(bytes)
}

/// Read an `.npy` of little-endian `f32` (what the tests and tools need): shape and data.
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>)> {
    read_npy(path)
}

/// Read a version 1.0 `.npy` of `T`'s dtype in C order (for `u8`, numpy's `bool` too):
/// shape and data.
pub fn read_npy<T: NpyElement>(path: &Path) -> Result<(Vec<usize>, Vec<T>)> {
    let b = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |m: &str| Error::parse(path, m.to_string());
    if b.len() < 10 || &b[..8] != b"\x93NUMPY\x01\x00" {
        return Err(bad("not a version 1.0 .npy file"));
    }
    let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = std::str::from_utf8(b.get(10..10 + hl).ok_or_else(|| bad("truncated header"))?)
        .map_err(|_| bad("header is not text"))?;
    let descr = T::DTYPE.descr();
    let dtype_ok = header.contains(&format!("'descr': '{descr}'"))
        || (T::DTYPE == Dtype::U8 && header.contains("'descr': '|b1'"));
    if !dtype_ok || header.contains("'fortran_order': True") {
        return Err(bad(&format!("only {descr} in C order is supported here")));
    }
    let inner = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad("no shape in header"))?;
    let shape: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| bad("invalid shape")))
        .collect::<Result<_>>()?;
    let body = &b[10 + hl..];
    let size = std::mem::size_of::<T>();
    let bytes = shape
        .iter()
        .try_fold(size, |n, &d| n.checked_mul(d))
        .ok_or_else(|| bad("the shape's size overflows"))?;
    if body.len() != bytes {
        return Err(bad("data size does not match the shape"));
    }
    Ok((shape, body.chunks_exact(size).map(T::get).collect()))
}
