//! The binary glTF container (GLB 2.0): a 12-byte header (`glTF`, version 2, total length), a
//! JSON chunk and an optional BIN chunk, every length a multiple of 4 bytes, little-endian.
//! [`glb_container`] packs one for the writers ([`super::gltf`], a user's character in
//! [`super::retarget`]); [`glb_chunks`] unpacks one read from a file.

use super::error::ExportError;

/// GLB chunk types: `JSON` and `BIN\0` read as little-endian `u32`.
pub const CHUNK_JSON: u32 = 0x4E4F_534A;
/// See [`CHUNK_JSON`].
pub const CHUNK_BIN: u32 = 0x004E_4942;

/// The GLB container: 12-byte header, the JSON chunk padded with spaces, the BIN chunk padded
/// with zeros, each chunk a multiple of 4 bytes. Fails on a file over 4 GiB.
pub fn glb_container(json: &[u8], bin: &[u8]) -> Result<Vec<u8>, ExportError> {
    let padded = |len: usize| len.next_multiple_of(4);
    let total = 12 + 8 + padded(json.len()) + 8 + padded(bin.len());
    let total_u32 = u32::try_from(total)
        .map_err(|_| ExportError::Shape(format!("a GLB holds at most 4 GiB; this one needs {total} bytes")))?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend(total_u32.to_le_bytes());
    for (chunk, kind, fill) in [(json, CHUNK_JSON, b' '), (bin, CHUNK_BIN, 0)] {
        let len = padded(chunk.len());
        // Fits in a u32: the whole file's length does.
        out.extend((len as u32).to_le_bytes());
        out.extend(kind.to_le_bytes());
        out.extend_from_slice(chunk);
        out.resize(out.len() + len - chunk.len(), fill);
    }
    Ok(out)
}

/// The JSON chunk and the BIN chunk (when there is one) of GLB `bytes`. The error says what is
/// wrong: not a GLB, another version, a length that disagrees with the file's, a first chunk that
/// is not JSON. Chunks of unknown types after the first two are skipped, as the format asks.
pub fn glb_chunks(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    let word = |at: usize| bytes.get(at..at + 4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]));
    if bytes.get(..4) != Some(b"glTF") {
        return Err("not a GLB file (it does not start with `glTF`)".into());
    }
    match word(4) {
        Some(2) => {}
        Some(v) => return Err(format!("GLB version {v}; only glTF 2.0 is read")),
        None => return Err("the GLB header is cut short".into()),
    }
    let declared = word(8).ok_or("the GLB header is cut short")? as usize;
    if declared != bytes.len() {
        return Err(format!("the GLB header says {declared} bytes but the file has {}", bytes.len()));
    }
    let mut chunks = Vec::new();
    let mut at = 12;
    while at < bytes.len() {
        let (len, kind) =
            word(at).zip(word(at + 4)).ok_or_else(|| format!("a chunk header at byte {at} is cut short"))?;
        let body = bytes
            .get(at + 8..at + 8 + len as usize)
            .ok_or_else(|| format!("the chunk at byte {at} claims {len} bytes, past the end of the file"))?;
        chunks.push((kind, body));
        at += 8 + len as usize;
    }
    match chunks.as_slice() {
        [(CHUNK_JSON, json), rest @ ..] => {
            Ok((json, rest.first().and_then(|(kind, body)| (*kind == CHUNK_BIN).then_some(*body))))
        }
        _ => Err("the first GLB chunk is not JSON".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_container_reads_back_and_damage_is_named() {
        let glb = glb_container(br#"{"asset":{"version":"2.0"}}"#, &[1, 2, 3]).unwrap();
        assert_eq!(glb.len() % 4, 0);
        let (json, bin) = glb_chunks(&glb).unwrap();
        assert_eq!(json.trim_ascii_end(), br#"{"asset":{"version":"2.0"}}"#);
        assert_eq!(bin.unwrap(), [1, 2, 3, 0]);
        assert!(glb_chunks(b"PK\x03\x04").unwrap_err().contains("not a GLB"));
        assert!(glb_chunks(&glb[..glb.len() - 4]).unwrap_err().contains("says"));
        let mut v1 = glb.clone();
        v1[4] = 1;
        assert!(glb_chunks(&v1).unwrap_err().contains("version 1"));
        let mut long = glb.clone();
        long[12] = 200;
        assert!(glb_chunks(&long).unwrap_err().contains("past the end"));
    }
}
