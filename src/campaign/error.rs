//! [`CampaignError`], the error of every campaign function, with its exit class (a file of
//! its own, so that the campaign's files import it without importing `campaign` itself).

use std::path::Path;

use crate::exit_codes::{Classed, ExitClass};
use crate::fsutil;
use crate::manifest::validate::ManifestErrors;

/// The error of every campaign function; each variant says its exit class
/// ([`CampaignError::class`]), the command line turns the class into the exit code.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// The manifest is invalid (every error with its JSON pointer): invalid input.
    #[error("{0}")]
    Manifest(#[from] ManifestErrors),
    /// Other input that is invalid (a `--time`, a shard `I/N`): invalid input.
    #[error("{0}")]
    Invalid(String),
    /// The directory holds another campaign, is locked by a live process, refuses the
    /// manifest, is corrupt or not a campaign directory, or its tables do not match the
    /// ledger: refused.
    #[error("{0}")]
    Refused(String),
    /// An I/O or internal error (disk full, read-only, permissions; also at a lock): I/O.
    #[error("{0}")]
    Io(String),
    /// A run needs more of the machine than it has (refused before anything is written):
    /// invalid input.
    #[error("{0}")]
    TooLarge(String),
}

impl CampaignError {
    pub fn class(&self) -> ExitClass {
        match self {
            CampaignError::Manifest(_) | CampaignError::Invalid(_) | CampaignError::TooLarge(_) => {
                ExitClass::InvalidInput
            }
            CampaignError::Refused(_) => ExitClass::Refused,
            CampaignError::Io(_) => ExitClass::Io,
        }
    }

    /// The same error with `what` put before its message (`what: message`).
    pub fn context(self, what: impl std::fmt::Display) -> CampaignError {
        match self {
            CampaignError::Manifest(m) => CampaignError::Manifest(m),
            CampaignError::Invalid(m) => CampaignError::Invalid(format!("{what}: {m}")),
            CampaignError::Refused(m) => CampaignError::Refused(format!("{what}: {m}")),
            CampaignError::Io(m) => CampaignError::Io(format!("{what}: {m}")),
            CampaignError::TooLarge(m) => CampaignError::TooLarge(format!("{what}: {m}")),
        }
    }

    /// An I/O error at `path`: a refusal where it is a link or another entry that is not
    /// granular's own (`fsutil::not_own`), else I/O.
    pub fn at(path: &Path, e: std::io::Error) -> CampaignError {
        match fsutil::not_own(&e) {
            Some(n) => CampaignError::Refused(n.to_string()),
            None => CampaignError::Io(format!("{}: {e}", path.display())),
        }
    }
}

impl Classed for CampaignError {
    fn class(&self) -> ExitClass {
        CampaignError::class(self)
    }
}
