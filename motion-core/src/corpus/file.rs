//! The corpus as one compact file (`fixtures/corpus/corpus.safetensors.gz`): a gzip-compressed
//! safetensors file whose one tensor `joints_mm_delta` (i16, `[66, frames]`: joint-coordinate
//! major, x y z of each of the 22 joints) holds every clip's joint positions in whole
//! millimetres, each clip's first frame as is and the others as the change from the frame
//! before (small numbers, which compress about 2.6× better than positions); the clips, windows
//! (tags and captions) and the drop report are JSON in the header metadata under `corpus`.
//! Positions are rounded to 1 mm (the shared CMU form is float16: 1–4 mm steps).

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::Path;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::clips::{Corpus, CorpusClip, CorpusWindow, DropReport};
use crate::files::{read_bytes, FileError};
use crate::limits::MOCAP_FILE_BYTES;
use crate::skeleton::{Pose, FPS, NUM_JOINTS};

/// Version of the layout, checked on load.
const FORMAT_VERSION: u32 = 1;
/// Name of the joint tensor.
const JOINTS: &str = "joints_mm_delta";
/// Channels per frame: x, y, z of each joint.
const CHANNELS: usize = 3 * NUM_JOINTS;

#[derive(Serialize, Deserialize)]
struct Header {
    format_version: u32,
    fps: f64,
    clips: Vec<CorpusClip>,
    windows: Vec<CorpusWindow>,
    drops: DropReport,
}

/// Writes the corpus to `path` (through a temporary file and a rename).
pub fn save(corpus: &Corpus, path: &Path) -> Result<(), FileError> {
    let format = |message: String| FileError::format(path, message);
    let frames = corpus.joints.len();
    let mut channels = vec![0i16; CHANNELS * frames];
    for clip in &corpus.clips {
        let mut previous = [0i64; CHANNELS];
        for (t, pose) in corpus.clip_joints(clip).iter().enumerate() {
            let row = clip.offset + t;
            for (c, value) in pose.iter().flat_map(|v| v.to_array()).enumerate() {
                let mm = (value * 1000.0).round() as i64;
                let stored = if t == 0 { mm } else { mm - previous[c] };
                channels[c * frames + row] = i16::try_from(stored).map_err(|_| {
                    format(format!("clip {}, frame {t}: {value} m or its change does not fit 16 bits of mm", clip.name))
                })?;
                previous[c] = mm;
            }
        }
    }
    let header = Header {
        format_version: FORMAT_VERSION,
        fps: FPS,
        clips: corpus.clips.clone(),
        windows: corpus.windows.clone(),
        drops: corpus.drops.clone(),
    };
    let json = serde_json::to_string(&header).map_err(|e| format(e.to_string()))?;
    let bytes: Vec<u8> = channels.iter().flat_map(|v| v.to_le_bytes()).collect();
    let view = safetensors::tensor::TensorView::new(safetensors::Dtype::I16, vec![CHANNELS, frames], &bytes)
        .map_err(|e| format(e.to_string()))?;
    let st = safetensors::tensor::serialize(vec![(JOINTS, view)], Some(HashMap::from([("corpus".to_owned(), json)])))
        .map_err(|e| format(e.to_string()))?;
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    gz.write_all(&st).and_then(|_| gz.finish()).map_err(|e| format(e.to_string())).and_then(|packed| {
        crate::files::write_atomically(path, &packed).map_err(|e| FileError::Io { path: e.path, message: e.message })
    })
}

/// Reads a corpus written by [`save`], checking that every clip and window lies inside the
/// joints and every value is finite.
pub fn load(path: &Path) -> Result<Corpus, FileError> {
    Ok(PackedCorpus::open(path)?.into_corpus())
}

/// A corpus file read and checked, its joints still as the file holds them (millimetre deltas):
/// a clip's poses are decoded when asked for, so that a reader of some clips (retrieval's train
/// split) never holds every split's poses as f64 (285 MB for the shipped corpus, whose first
/// touch costs more than the decoding).
pub struct PackedCorpus {
    /// The unpacked safetensors file.
    bytes: Vec<u8>,
    /// Where the joint tensor's data starts in `bytes`.
    data_start: usize,
    /// Frames of every clip together.
    frames: usize,
    /// Every clip, checked to follow the one before it in the joints.
    pub clips: Vec<CorpusClip>,
    /// The captioned windows, checked to lie inside their clips.
    pub windows: Vec<CorpusWindow>,
    /// What the screen dropped.
    pub drops: DropReport,
}

impl PackedCorpus {
    /// Reads and checks the corpus file at `path` (its header, the joint tensor's type and shape,
    /// every clip's place and every window's), leaving the joints packed.
    pub fn open(path: &Path) -> Result<Self, FileError> {
        let format = |message: String| FileError::format(path, message);
        let packed = read_bytes(path, &MOCAP_FILE_BYTES)?;
        // gzip's trailer holds the unpacked size (mod 2^32): the buffer is made once, at that
        // size, instead of growing by doubling (each growth a copy and fresh pages to zero).
        let unpacked = match packed.len().checked_sub(4).map(|at| &packed[at..]) {
            Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]) as usize,
            _ => 0,
        };
        let mut bytes = Vec::with_capacity(unpacked.min(usize::try_from(MOCAP_FILE_BYTES.max).unwrap_or(usize::MAX)));
        flate2::read::GzDecoder::new(packed.as_slice())
            .take(MOCAP_FILE_BYTES.max)
            .read_to_end(&mut bytes)
            .map_err(|e| format(format!("not a gzip file: {e}")))?;
        drop(packed);
        let st = safetensors::SafeTensors::deserialize(&bytes)
            .map_err(|e| format(format!("not a safetensors file: {e}")))?;
        let meta = crate::tensor_file::read_metadata(&bytes).map_err(format)?;
        let json = meta.get("corpus").ok_or_else(|| format("no `corpus` in the header metadata".into()))?;
        let header: Header = serde_json::from_str(json).map_err(|e| format(format!("bad corpus header: {e}")))?;
        if header.format_version != FORMAT_VERSION {
            return Err(format(format!("format version {} (expected {FORMAT_VERSION})", header.format_version)));
        }
        if header.fps != FPS {
            return Err(format(format!("{} fps (expected {FPS})", header.fps)));
        }
        let frames: usize = header.clips.iter().map(|c| c.frames).sum();
        let tensor = st.tensor(JOINTS).map_err(|e| format(format!("tensor `{JOINTS}`: {e}")))?;
        if tensor.dtype() != safetensors::Dtype::I16 || tensor.shape() != [CHANNELS, frames] {
            return Err(format(format!(
                "tensor `{JOINTS}` is {:?} {:?}, expected I16 [{CHANNELS}, {frames}]",
                tensor.dtype(),
                tensor.shape()
            )));
        }
        // The tensor's data is a slice of `bytes`: its offset there, without holding the borrow.
        let data_start = tensor.data().as_ptr() as usize - bytes.as_ptr() as usize;
        let mut offset = 0;
        for (i, clip) in header.clips.iter().enumerate() {
            if clip.offset != offset || clip.frames == 0 {
                return Err(format(format!(
                    "clip {i} ({}) starts at frame {} (expected {offset})",
                    clip.name, clip.offset
                )));
            }
            offset += clip.frames;
        }
        for (i, w) in header.windows.iter().enumerate() {
            let inside = header.clips.get(w.clip).is_some_and(|c| w.frames > 0 && w.start + w.frames <= c.frames);
            if !inside {
                return Err(format(format!("window {i} lies outside its clip")));
            }
        }
        Ok(PackedCorpus {
            bytes,
            data_start,
            frames,
            clips: header.clips,
            windows: header.windows,
            drops: header.drops,
        })
    }

    /// Appends the poses of `clip` (one of [`PackedCorpus::clips`]) to `poses`, in metres:
    /// pose by pose, each channel's running sum carried along, so that the poses are written
    /// once, in order, while the channels are read as 66 forward streams.
    pub fn decode_clip(&self, clip: &CorpusClip, poses: &mut Vec<Pose>) {
        let data = &self.bytes[self.data_start..self.data_start + 2 * CHANNELS * self.frames];
        let value = |i: usize| i16::from_le_bytes([data[2 * i], data[2 * i + 1]]);
        poses.reserve(clip.frames);
        let mut mm = [0i64; CHANNELS];
        for row in clip.offset..clip.offset + clip.frames {
            let first = row == clip.offset;
            let mut pose = [DVec3::ZERO; NUM_JOINTS];
            for (c, sum) in mm.iter_mut().enumerate() {
                let stored = i64::from(value(c * self.frames + row));
                *sum = if first { stored } else { *sum + stored };
                pose[c / 3][c % 3] = *sum as f64 / 1000.0;
            }
            poses.push(pose);
        }
    }

    /// The whole corpus, every clip decoded.
    pub fn into_corpus(self) -> Corpus {
        let mut joints = Vec::with_capacity(self.frames);
        for clip in &self.clips {
            self.decode_clip(clip, &mut joints);
        }
        Corpus { clips: self.clips, joints, windows: self.windows, drops: self.drops }
    }
}

/// Joints of a pose as the file stores them (rounded to whole millimetres).
pub fn rounded(pose: &Pose) -> Pose {
    pose.map(|v| (v * 1000.0).round() / 1000.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corpus::screen::ScreenConfig;
    use crate::corpus::{RawTake, Source};
    use crate::motion::test_support::walking_poses;

    #[test]
    fn a_corpus_survives_the_file_to_the_millimetre_and_damage_is_named() {
        let take = |id: &str, turn| RawTake {
            source: Source::Cmu,
            take: id.into(),
            subject: id[..2].into(),
            description: "walk".into(),
            poses: walking_poses(130, turn),
            screen: true,
            hold_frames: 0,
        };
        let corpus = Corpus::build(vec![take("01_01", 0.0), take("02_01", 0.5)], &ScreenConfig::default());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("corpus.safetensors.gz");
        save(&corpus, &path).unwrap();
        let back = load(&path).unwrap();
        assert_eq!(back.clips, corpus.clips);
        assert_eq!(back.windows, corpus.windows);
        assert_eq!(back.joints.len(), corpus.joints.len());
        for (a, b) in back.joints.iter().zip(&corpus.joints) {
            assert_eq!(*a, rounded(b));
        }
        // One clip decoded on its own, after another's poses, is that clip's stretch of the joints.
        let packed = PackedCorpus::open(&path).unwrap();
        let mut poses = vec![[DVec3::splat(7.0); NUM_JOINTS]];
        packed.decode_clip(&packed.clips[1], &mut poses);
        assert_eq!(&poses[1..], back.clip_joints(&back.clips[1]));
        std::fs::write(&path, b"not gzip").unwrap();
        let e = load(&path).err().unwrap().to_string();
        assert!(e.contains("corpus.safetensors.gz") && e.contains("gzip"), "{e}");
    }
}
