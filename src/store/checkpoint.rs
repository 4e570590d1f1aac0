//! Checkpoints of running simulations: versioned, checksummed, written atomically; the
//! previous good checkpoint is kept as `.prev` until the next one is durable. Final states of
//! finished runs (`run-<id>.final`, what a longer run continues from) share the container.
//!
//! Layout: magic `GRNLCKPT`, format (u32 LE), header length (u32 LE), payload length (u64 LE),
//! CRC-32 of header + payload (u32 LE), header (JSON), payload (the simulator's state).

use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::CHECKPOINT_FORMAT;
use crate::exit_codes::{Classed, ExitClass};
use crate::fsutil;

const MAGIC: &[u8; 8] = b"GRNLCKPT";

/// Why a checkpoint or a final state cannot be used. The worker warns and runs the run from
/// t = 0 (a checkpoint), or continues nothing (a final state): never the process's exit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CheckpointError {
    /// Not a checkpoint of this format, damaged, or another run's: refused.
    #[error("{0}")]
    Corrupt(String),
    /// Cannot be read (its path and why): I/O.
    #[error("{0}")]
    Io(String),
}

impl CheckpointError {
    /// The same error, its message led by `path`.
    fn at(self, path: &Path) -> CheckpointError {
        match self {
            CheckpointError::Corrupt(m) => {
                CheckpointError::Corrupt(format!("{}: {m}", path.display()))
            }
            CheckpointError::Io(m) => CheckpointError::Io(format!("{}: {m}", path.display())),
        }
    }
}

impl Classed for CheckpointError {
    fn class(&self) -> ExitClass {
        match self {
            CheckpointError::Corrupt(_) => ExitClass::Refused,
            CheckpointError::Io(_) => ExitClass::Io,
        }
    }
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CheckpointHeader {
    pub run_id: u64,
    pub seed: u64,
    pub code_version: String,
    /// The simulator's state layout (e.g. `dsmc/1`); a checkpoint of another layout is not
    /// resumed.
    pub state_format: String,
    /// Wall-clock seconds spent on the run so far.
    pub wall_seconds: f64,
    /// Simulated time reached.
    pub t: f64,
    /// The run this one continues from its final state (absent: it ran from t = 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub continued_from: Option<u64>,
}

pub fn path(dir: &Path, run_id: u64) -> PathBuf {
    dir.join(format!("run-{run_id:010}.ckpt"))
}

fn prev_path(dir: &Path, run_id: u64) -> PathBuf {
    dir.join(format!("run-{run_id:010}.ckpt.prev"))
}

pub fn encode(header: &CheckpointHeader, payload: &[u8]) -> Vec<u8> {
    let mut out = encode_head(header, &[payload]);
    out.extend_from_slice(payload);
    out
}

/// What [`encode`] puts before the payload, for a payload that is the concatenation of
/// `parts`.
fn encode_head<P: AsRef<[u8]>>(header: &CheckpointHeader, parts: &[P]) -> Vec<u8> {
    let h = serde_json::to_vec(header).expect("header serialises");
    let mut crc = crc32fast::Hasher::new();
    crc.update(&h);
    let mut len = 0u64;
    for p in parts {
        crc.update(p.as_ref());
        len += p.as_ref().len() as u64;
    }
    let mut out = Vec::with_capacity(28 + h.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&CHECKPOINT_FORMAT.to_le_bytes());
    out.extend_from_slice(&(h.len() as u32).to_le_bytes());
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(&crc.finalize().to_le_bytes());
    out.extend_from_slice(&h);
    out
}

pub fn decode(bytes: &[u8]) -> Result<(CheckpointHeader, &[u8]), CheckpointError> {
    let corrupt = CheckpointError::Corrupt;
    if bytes.len() < 28 || &bytes[..8] != MAGIC {
        return Err(corrupt(
            "not a granular checkpoint (bad magic or too short)".into(),
        ));
    }
    let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().expect("4 bytes"));
    let format = u32_at(8);
    if format != CHECKPOINT_FORMAT {
        return Err(corrupt(format!(
            "checkpoint format {format}, this granular reads {CHECKPOINT_FORMAT}"
        )));
    }
    let hlen = u32_at(12) as usize;
    let plen = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes")) as usize;
    let crc = u32_at(24);
    if bytes.len() != 28 + hlen + plen {
        return Err(corrupt(format!(
            "truncated or padded: {} bytes, expected {}",
            bytes.len(),
            28 + hlen + plen
        )));
    }
    let (h, p) = bytes[28..].split_at(hlen);
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(h);
    hasher.update(p);
    if hasher.finalize() != crc {
        return Err(corrupt("checksum mismatch".into()));
    }
    let header: CheckpointHeader =
        serde_json::from_slice(h).map_err(|e| corrupt(format!("bad header: {e}")))?;
    Ok((header, p))
}

/// Write a checkpoint atomically; the previous one becomes `.prev`.
pub fn write(dir: &Path, header: &CheckpointHeader, payload: &[u8]) -> std::io::Result<()> {
    let bytes = encode(header, payload);
    let cur = path(dir, header.run_id);
    let tmp = fsutil::temp_path(&cur);
    let result = (|| {
        {
            use std::io::Write;
            let mut f = fs::File::create(&tmp)?;
            f.write_all(&bytes)?;
            f.sync_all()?;
        }
        if cur.exists() {
            fs::rename(&cur, prev_path(dir, header.run_id))?;
        }
        fs::rename(&tmp, &cur)?;
        fsutil::sync_dir(dir)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// What loading a run's checkpoint found.
pub struct Loaded {
    pub header: CheckpointHeader,
    pub payload: Vec<u8>,
    /// Problems with newer checkpoint files that were skipped (for warnings).
    pub skipped: Vec<String>,
}

/// The newest good checkpoint of a run (current, else previous); `Ok(None)` if there is none.
/// Bad files are reported in `skipped` (or in the error when no good one is left).
pub fn load(dir: &Path, run_id: u64, seed: u64) -> Result<Option<Loaded>, Vec<String>> {
    let mut skipped = Vec::new();
    for p in [path(dir, run_id), prev_path(dir, run_id)] {
        let bytes = match fs::read(&p) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => {
                skipped.push(format!("{}: {e}", p.display()));
                continue;
            }
        };
        match decode(&bytes) {
            Ok((header, payload)) if header.run_id == run_id && header.seed == seed => {
                return Ok(Some(Loaded {
                    header,
                    payload: payload.to_vec(),
                    skipped,
                }))
            }
            Ok((header, _)) => skipped.push(format!(
                "{}: belongs to run {} seed {}, expected run {run_id} seed {seed}",
                p.display(),
                header.run_id,
                header.seed
            )),
            Err(e) => skipped.push(format!("{}: {e}", p.display())),
        }
    }
    if skipped.is_empty() {
        Ok(None)
    } else {
        Err(skipped)
    }
}

/// The final state of run `run_id` in `dir`.
pub fn final_path(dir: &Path, run_id: u64) -> PathBuf {
    dir.join(format!("run-{run_id:010}.final"))
}

/// Write a finished run's final state, the concatenation of `parts`, atomically (the
/// directory is created if needed): the bytes of [`encode`], written part by part.
pub fn write_final<P: AsRef<[u8]>>(
    dir: &Path,
    header: &CheckpointHeader,
    parts: &[P],
) -> std::io::Result<()> {
    if !dir.is_dir() {
        fsutil::create_dir_durable(dir)?;
    }
    let head = encode_head(header, parts);
    let mut all: Vec<&[u8]> = vec![&head];
    all.extend(parts.iter().map(|p| p.as_ref()));
    fsutil::write_atomic_parts(&final_path(dir, header.run_id), &all)
}

/// A finished run's final state; `Ok(None)` if there is none, Err if it is unusable (why).
pub fn load_final(
    dir: &Path,
    run_id: u64,
    seed: u64,
) -> Result<Option<(CheckpointHeader, Vec<u8>)>, CheckpointError> {
    let p = final_path(dir, run_id);
    let bytes = match fs::read(&p) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(CheckpointError::Io(format!("{}: {e}", p.display()))),
    };
    let (header, payload) = decode(&bytes).map_err(|e| e.at(&p))?;
    if header.run_id != run_id || header.seed != seed {
        return Err(CheckpointError::Corrupt(format!(
            "{}: belongs to run {} seed {}, expected run {run_id} seed {seed}",
            p.display(),
            header.run_id,
            header.seed
        )));
    }
    Ok(Some((header, payload.to_vec())))
}

/// Remove a run's final state (once a longer run continuing it is committed).
pub fn remove_final(dir: &Path, run_id: u64) {
    let _ = fs::remove_file(final_path(dir, run_id));
}

/// Remove a run's checkpoints (after its rows are committed).
pub fn remove(dir: &Path, run_id: u64) {
    let _ = fs::remove_file(path(dir, run_id));
    let _ = fs::remove_file(prev_path(dir, run_id));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header() -> CheckpointHeader {
        CheckpointHeader {
            run_id: 3,
            seed: 9,
            code_version: "x".into(),
            state_format: "dsmc/1".into(),
            wall_seconds: 1.5,
            t: 2.0,
            continued_from: None,
        }
    }

    /// A final state written in parts is the file of its concatenation, and loads back.
    #[test]
    fn final_state_in_parts_is_one_payload() {
        let dir = tempfile::tempdir().unwrap();
        let parts = [
            b"head".to_vec(),
            vec![],
            (0..=255u8).cycle().take(70_000).collect(),
        ];
        write_final(dir.path(), &header(), &parts).unwrap();
        let whole = parts.concat();
        let bytes = fs::read(final_path(dir.path(), 3)).unwrap();
        assert_eq!(bytes, encode(&header(), &whole));
        let (h, payload) = load_final(dir.path(), 3, 9).unwrap().unwrap();
        assert_eq!((h.run_id, payload), (3, whole));
    }

    #[test]
    fn round_trip_and_corruption_detected() {
        let bytes = encode(&header(), b"payload bytes");
        let (h, p) = decode(&bytes).unwrap();
        assert_eq!(h, header());
        assert_eq!(p, b"payload bytes");
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x40;
            assert!(decode(&bad).is_err(), "flipped byte {i} not detected");
        }
        assert!(decode(&bytes[..bytes.len() - 1]).is_err());
    }

    #[test]
    fn final_states_round_trip_and_check_their_run() {
        let dir = tempfile::tempdir().unwrap();
        let finals = dir.path().join("finals");
        assert_eq!(load_final(&finals, 3, 9), Ok(None));
        write_final(&finals, &header(), &[b"end"]).unwrap();
        let (h, p) = load_final(&finals, 3, 9).unwrap().unwrap();
        assert_eq!((h, p.as_slice()), (header(), &b"end"[..]));
        assert!(load_final(&finals, 3, 10)
            .unwrap_err()
            .to_string()
            .contains("seed 9"));
        let f = final_path(&finals, 3);
        let mut b = fs::read(&f).unwrap();
        b[30] ^= 1;
        fs::write(&f, b).unwrap();
        assert!(load_final(&finals, 3, 9)
            .unwrap_err()
            .to_string()
            .contains("checksum"));
        remove_final(&finals, 3);
        assert_eq!(load_final(&finals, 3, 9), Ok(None));
    }

    #[test]
    fn falls_back_to_previous() {
        let dir = tempfile::tempdir().unwrap();
        let mut h = header();
        write(dir.path(), &h, b"first").unwrap();
        h.t = 3.0;
        write(dir.path(), &h, b"second").unwrap();
        // Corrupt the newest: the previous is used, with a warning.
        let cur = path(dir.path(), 3);
        let mut b = fs::read(&cur).unwrap();
        let n = b.len();
        b[n - 2] ^= 1;
        fs::write(&cur, b).unwrap();
        let got = load(dir.path(), 3, 9).unwrap().unwrap();
        assert_eq!(got.payload, b"first");
        assert_eq!(got.skipped.len(), 1);
        // Wrong seed: nothing usable.
        assert!(load(dir.path(), 3, 10).is_err());
    }
}
