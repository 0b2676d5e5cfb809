//! Writing named f32 tensors and string metadata as one safetensors file.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Tensor};

/// Writes `tensors` (converted to f32 on the CPU) with header `metadata` to `path` atomically,
/// creating the parent folder. Errors are messages; callers add the path and their context.
pub fn write_safetensors(
    path: &Path,
    tensors: &[(String, Tensor)],
    metadata: HashMap<String, String>,
) -> Result<(), String> {
    let mut data: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::with_capacity(tensors.len());
    for (name, t) in tensors {
        let values = t
            .to_dtype(DType::F32)
            .and_then(|t| t.flatten_all())
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(|e| format!("tensor `{name}`: {e}"))?;
        data.push((name.clone(), t.dims().to_vec(), values.iter().flat_map(|x| x.to_le_bytes()).collect()));
    }
    let views = data
        .iter()
        .map(|(name, shape, bytes)| {
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes)
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
