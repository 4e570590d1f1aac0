//! The history of a campaign's manifests: each accepted manifest is kept, as given, in
//! `manifests/<k>.json`, listed in `campaign.json` with the time it was accepted and the runs
//! it added; and what a campaign keeps for ever (name, model, seed).

use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use super::error::CampaignError;
use crate::fsutil;
use crate::manifest::Manifest;

/// One accepted manifest.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Accepted {
    /// `manifests/<k>.json`, relative to the campaign directory.
    pub file: String,
    /// When it was accepted (UTC, ISO 8601).
    pub accepted: String,
    /// Runs it registered.
    pub runs_added: u64,
}

/// Keep the `k`-th accepted manifest (its text as given), atomically.
pub fn write(
    root: &Path,
    k: usize,
    text: &[u8],
    runs_added: u64,
) -> Result<Accepted, CampaignError> {
    let dir = root.join("manifests");
    let io = |p: &Path, e| CampaignError::Io(format!("{}: {e}", p.display()));
    fsutil::create_dir_durable(&dir).map_err(|e| io(&dir, e))?;
    let file = format!("manifests/{k}.json");
    let path = root.join(&file);
    fsutil::write_atomic(&path, text).map_err(|e| io(&path, e))?;
    Ok(Accepted {
        file,
        accepted: utc_now(),
        runs_added,
    })
}

/// What differs between two manifests in what a campaign keeps for ever.
pub fn identity_differences(old: &Manifest, new: &Manifest) -> Vec<String> {
    let mut d = Vec::new();
    if old.name != new.name {
        d.push(format!(
            "name {:?} (the manifest says {:?})",
            old.name, new.name
        ));
    }
    if old.model != new.model {
        d.push(format!(
            "model {} (the manifest says {})",
            old.model.as_str(),
            new.model.as_str()
        ));
    }
    if old.seed != new.seed {
        d.push(format!(
            "seed {} (the manifest says {})",
            old.seed, new.seed
        ));
    }
    d
}

/// The current time in UTC, `YYYY-MM-DDTHH:MM:SSZ`.
pub fn utc_now() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    utc(secs)
}

/// Seconds since 1970 as `YYYY-MM-DDTHH:MM:SSZ` (proleptic Gregorian calendar).
pub fn utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Howard Hinnant's civil_from_days.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates() {
        assert_eq!(utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc(1_798_761_599), "2026-12-31T23:59:59Z");
    }
}
