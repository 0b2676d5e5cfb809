//! NumPy `.npy` float arrays: a reader that checks the header against the file's size before
//! reading, so a truncated or corrupt file is an error naming the file, never a panic or a huge
//! allocation, and a writer that builds the file in memory for one write.

use std::path::Path;

use candle_core::{DType, Tensor};

use crate::files::{read_bytes, FileError};
use crate::limits::MOCAP_FILE_BYTES;

/// A float array read from a `.npy` file, converted to f32, C order.
pub(crate) struct NpyArray {
    /// Dimensions.
    pub(crate) shape: Vec<usize>,
    /// Values, C order.
    pub(crate) data: Vec<f32>,
}

fn invalid(path: &Path, location: &str, message: String) -> FileError {
    FileError::format(path, format!("{location}: {message}"))
}

const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// Reads a little-endian `<f4` or `<f8` `.npy` file (format versions 1–3) of at most
/// [`MOCAP_FILE_BYTES`]. `check_shape` sees the header's shape before the data is sized
/// against it or converted, so a shape over a limit is refused from the header alone (with the
/// caller's error `E`, which every [`FileError`] converts into).
pub(crate) fn read_float_npy<E: From<FileError>>(
    path: &Path,
    check_shape: impl FnOnce(&[usize]) -> Result<(), E>,
) -> Result<NpyArray, E> {
    let bytes = read_bytes(path, &MOCAP_FILE_BYTES)?;
    let bad = |message: String| E::from(invalid(path, "npy header", message));
    if bytes.len() < 10 || !bytes.starts_with(NPY_MAGIC) {
        return Err(bad("not a .npy file (no \\x93NUMPY magic)".into()));
    }
    let (header_start, header_len) = match bytes[6] {
        1 => (10, usize::from(u16::from_le_bytes([bytes[8], bytes[9]]))),
        2 | 3 => match bytes.get(8..12) {
            Some(&[a, b, c, d]) => (12, u32::from_le_bytes([a, b, c, d]) as usize),
            _ => return Err(bad("truncated header".into())),
        },
        v => return Err(bad(format!("unsupported .npy version {v}"))),
    };
    let data_start = header_start + header_len;
    let header = bytes.get(header_start..data_start).ok_or_else(|| bad("truncated header".into()))?;
    let header = std::str::from_utf8(header).map_err(|_| bad("header is not text".into()))?;
    let descr = dict_value(header, "descr")
        .and_then(|v| v.strip_prefix('\'')?.split_once('\''))
        .ok_or_else(|| bad(format!("no readable 'descr' in {header:?}")))?
        .0;
    let item_size: usize = match descr {
        "<f4" => 4,
        "<f8" => 8,
        other => return Err(bad(format!("dtype '{other}'; expected float32 ('<f4') or float64 ('<f8')"))),
    };
    if dict_value(header, "fortran_order").is_some_and(|v| v.starts_with("True")) {
        return Err(bad("Fortran-ordered arrays are not supported".into()));
    }
    let shape = dict_value(header, "shape")
        .and_then(parse_shape)
        .ok_or_else(|| bad(format!("no readable 'shape' in {header:?}")))?;
    check_shape(&shape)?;
    let expected = shape
        .iter()
        .try_fold(item_size, |acc, d| acc.checked_mul(*d))
        .ok_or_else(|| bad(format!("shape {shape:?} is too large")))?;
    let data = &bytes[data_start.min(bytes.len())..];
    if data.len() != expected {
        return Err(E::from(invalid(
            path,
            "data",
            format!(
                "shape {shape:?} of {descr} needs {expected} bytes; the file has {} (truncated or corrupt)",
                data.len()
            ),
        )));
    }
    let data = if item_size == 4 {
        data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    } else {
        data.chunks_exact(8)
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f32)
            .collect()
    };
    Ok(NpyArray { shape, data })
}

/// The text after `'key':` in a numpy header dict (the value and everything after it).
fn dict_value<'h>(header: &'h str, key: &str) -> Option<&'h str> {
    let at = header.find(&format!("'{key}'"))? + key.len() + 2;
    header[at..].trim_start().strip_prefix(':').map(str::trim_start)
}

/// Parses `(3, 263)` (the start of a header value) into dimensions.
fn parse_shape(value: &str) -> Option<Vec<usize>> {
    let inner = value.strip_prefix('(')?.split_once(')')?.0;
    inner.split(',').map(str::trim).filter(|s| !s.is_empty()).map(|s| s.parse().ok()).collect()
}

/// `tensor` as the bytes of a `.npy` (version 1.0) file of little-endian f32, C order.
pub fn npy_bytes(tensor: &Tensor) -> Result<Vec<u8>, String> {
    let values = tensor
        .to_dtype(DType::F32)
        .and_then(|t| t.flatten_all())
        .and_then(|t| t.to_vec1::<f32>())
        .map_err(|e| e.to_string())?;
    let shape: Vec<String> = tensor.dims().iter().map(ToString::to_string).collect();
    let shape = match shape.len() {
        1 => format!("({},)", shape[0]),
        _ => format!("({})", shape.join(", ")),
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    // Magic (6) + version (2) + header length (2) + header + newline, padded to 64 bytes.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let length = u16::try_from(header.len()).map_err(|_| format!("shape {shape} is too long for an npy header"))?;
    let mut bytes = Vec::with_capacity(10 + header.len() + 4 * values.len());
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&length.to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for value in values {
        bytes.extend_from_slice(&value.to_le_bytes());
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn npy_bytes_round_trip_through_candle() {
        let dir = tempfile::tempdir().unwrap();
        for shape in [vec![5], vec![2, 3, 4]] {
            let n: usize = shape.iter().product();
            let values: Vec<f32> = (0..n).map(|i| i as f32 * 0.5 - 1.0).collect();
            let tensor = Tensor::from_vec(values.clone(), shape.as_slice(), &Device::Cpu).unwrap();
            let bytes = npy_bytes(&tensor).unwrap();
            assert_eq!((bytes.len() - 4 * n) % 64, 0, "header padded to 64 bytes");
            let path = dir.path().join("a.npy");
            std::fs::write(&path, bytes).unwrap();
            let back = Tensor::read_npy(&path).unwrap();
            assert_eq!(back.dims(), shape.as_slice());
            assert_eq!(back.flatten_all().unwrap().to_vec1::<f32>().unwrap(), values);
        }
    }
}
