//! Writing named f32 (or f16) tensors and string metadata as one safetensors file, and reading
//! the metadata back.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Tensor};

/// Writes `tensors` (f16 ones as f16, every other one converted to f32, on the CPU) with header
/// `metadata` to `path` atomically, creating the parent folder. Errors are messages; callers
/// add the path and their context.
pub fn write_safetensors(
    path: &Path,
    tensors: &[(String, Tensor)],
    metadata: HashMap<String, String>,
) -> Result<(), String> {
    let mut data: Vec<(String, safetensors::Dtype, Vec<usize>, Vec<u8>)> = Vec::with_capacity(tensors.len());
    for (name, t) in tensors {
        let flat = t.flatten_all();
        let stored = if t.dtype() == DType::F16 {
            flat.and_then(|t| t.to_vec1::<half::f16>())
                .map(|v| (safetensors::Dtype::F16, v.iter().flat_map(|x| x.to_le_bytes()).collect()))
        } else {
            flat.and_then(|t| t.to_dtype(DType::F32))
                .and_then(|t| t.to_vec1::<f32>())
                .map(|v| (safetensors::Dtype::F32, v.iter().flat_map(|x| x.to_le_bytes()).collect()))
        };
        let (dtype, bytes) = stored.map_err(|e| format!("tensor `{name}`: {e}"))?;
        data.push((name.clone(), dtype, t.dims().to_vec(), bytes));
    }
    let views = data
        .iter()
        .map(|(name, dtype, shape, bytes)| {
            safetensors::tensor::TensorView::new(*dtype, shape.clone(), bytes)
                .map(|v| (name.clone(), v))
                .map_err(|e| format!("tensor `{name}`: {e}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let bytes = safetensors::tensor::serialize(views, Some(metadata)).map_err(|e| e.to_string())?;
    // Through a temporary file and a rename: a kill while saving a prior, a database or a
    // training checkpoint leaves the previous file whole.
    crate::files::write_atomically(path, &bytes).map_err(|e| e.to_string())
}

/// The string metadata of a safetensors file's header (empty when it has none). Errors are
/// messages; callers add the path.
pub fn read_metadata(bytes: &[u8]) -> Result<HashMap<String, String>, String> {
    let (_, meta) =
        safetensors::SafeTensors::read_metadata(bytes).map_err(|e| format!("not a safetensors file: {e}"))?;
    Ok(meta.metadata().clone().unwrap_or_default())
}

/// Largest safetensors header read (the format's own bound, 100 MB).
const MAX_HEADER_BYTES: u64 = 100_000_000;

/// The string metadata of the safetensors file at `path` (empty when it has none), reading its
/// JSON header only, not the tensors behind it (which are not checked). Errors are messages;
/// callers add the path.
pub fn read_file_metadata(path: &Path) -> Result<HashMap<String, String>, String> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut length = [0u8; 8];
    file.read_exact(&mut length)
        .map_err(|_| "not a safetensors file: shorter than its 8-byte header length".to_owned())?;
    let n = u64::from_le_bytes(length);
    if n > MAX_HEADER_BYTES {
        return Err(format!("not a safetensors file: a {n}-byte header"));
    }
    let mut header = Vec::new();
    file.take(n).read_to_end(&mut header).map_err(|e| e.to_string())?;
    if header.len() as u64 != n {
        return Err(format!("not a safetensors file: it ends inside its {n}-byte header"));
    }
    let header: serde_json::Value =
        serde_json::from_slice(&header).map_err(|e| format!("not a safetensors file: its header is not JSON: {e}"))?;
    match header.get("__metadata__") {
        None => Ok(HashMap::new()),
        Some(meta) => serde_json::from_value(meta.clone()).map_err(|e| format!("metadata that is not strings: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn f16_tensors_stay_f16_and_the_rest_become_f32() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.safetensors");
        let values = [0.25f32, -1.5, 3.0e-4];
        let half = Tensor::new(&values, &Device::Cpu).unwrap().to_dtype(DType::F16).unwrap();
        let double = Tensor::new(&[1.0f64, 2.0], &Device::Cpu).unwrap();
        let meta = HashMap::from([("k".to_owned(), "v".to_owned())]);
        write_safetensors(&path, &[("h".into(), half), ("d".into(), double)], meta.clone()).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(read_metadata(&bytes).unwrap(), meta);
        assert_eq!(read_file_metadata(&path).unwrap(), meta);
        let short = dir.path().join("short");
        std::fs::write(&short, [1u8, 2]).unwrap();
        assert!(read_file_metadata(&short).unwrap_err().contains("8-byte"));
        std::fs::write(&short, u64::MAX.to_le_bytes()).unwrap();
        assert!(read_file_metadata(&short).unwrap_err().contains("header"));
        std::fs::write(&short, [&40u64.to_le_bytes()[..], b"{}"].concat()).unwrap();
        assert!(read_file_metadata(&short).unwrap_err().contains("ends inside"));
        let read = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu).unwrap();
        assert_eq!(read["h"].dtype(), DType::F16);
        assert_eq!(read["d"].dtype(), DType::F32);
        let back = read["h"].to_dtype(DType::F32).unwrap().to_vec1::<f32>().unwrap();
        assert!(back.iter().zip(values).all(|(b, v)| (b - v).abs() <= 1e-3 * v.abs()), "{back:?}");
        assert_eq!(read["d"].to_vec1::<f32>().unwrap(), [1.0, 2.0]);
    }
}
