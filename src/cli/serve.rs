//! `granular serve DIR [--addr 127.0.0.1:8080]`: a read-only live dashboard of a campaign over
//! HTTP (`crate::serve`): the report page kept current, `/api/status` (the JSON of `status
//! --json`), the table files. Loopback unless told otherwise; Ctrl-C/SIGTERM exits at once
//! with 130, saying `granular serve: stopped by SIGTERM` (`signals`: it writes nothing, so
//! there is nothing to finish).
//!
//! For the tests only (README, Live dashboard), the environment can shorten the limits on
//! clients: `GRANULAR_SERVE_HEADER_TIMEOUT_MS`, `GRANULAR_SERVE_SEND_TIMEOUT_MS`,
//! `GRANULAR_SERVE_MAX_CONNECTIONS` (whole numbers from 1).

use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use super::flags::FlagError;
use super::{fail, failed, report_error};
use crate::campaign::Campaign;
use crate::exit_codes;
use crate::serve;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Address to listen on, IP:PORT (`localhost:PORT` too; port 0: any free port). The
    /// default is loopback only: from another machine use `ssh -L 8080:localhost:8080 HOST`.
    #[arg(long, default_value = serve::DEFAULT_ADDR, value_parser = parse_addr)]
    pub(super) addr: SocketAddr,
}

/// `--addr`: a socket address, or `localhost:PORT`.
fn parse_addr(s: &str) -> Result<SocketAddr, FlagError> {
    if let Some(port) = s.strip_prefix("localhost:") {
        let port: u16 = port
            .parse()
            .map_err(|_| FlagError(format!("{port:?} is not a port (0 to 65535)")))?;
        return Ok(SocketAddr::from((Ipv4Addr::LOCALHOST, port)));
    }
    s.parse().map_err(|_| {
        FlagError(format!(
            "{s:?} is not an address: IP:PORT, e.g. 127.0.0.1:8080 or [::1]:8080"
        ))
    })
}

/// The test-only settings of the environment, over the defaults; every bad one named.
fn limits_from_env() -> Result<serve::Limits, FlagError> {
    let mut l = serve::Limits::for_this_process();
    let mut errors = Vec::new();
    let mut number = |var: &str| -> Option<u64> {
        let v = std::env::var_os(var)?;
        match v.to_str().and_then(|s| s.trim().parse::<u64>().ok()) {
            Some(n) if n >= 1 => Some(n),
            _ => {
                errors.push(format!(
                    "{var}: expected a whole number from 1, got {:?}",
                    v.to_string_lossy()
                ));
                None
            }
        }
    };
    if let Some(ms) = number("GRANULAR_SERVE_HEADER_TIMEOUT_MS") {
        l.header_timeout = std::time::Duration::from_millis(ms);
    }
    if let Some(ms) = number("GRANULAR_SERVE_SEND_TIMEOUT_MS") {
        l.send_timeout = std::time::Duration::from_millis(ms);
    }
    if let Some(n) = number("GRANULAR_SERVE_MAX_CONNECTIONS") {
        l.max_connections = usize::try_from(n).unwrap_or(usize::MAX);
    }
    if errors.is_empty() {
        Ok(l)
    } else {
        Err(FlagError(errors.join("\nerror: ")))
    }
}

pub fn run(a: Args) -> i32 {
    super::signals::command("serve");
    let limits = match limits_from_env() {
        Ok(l) => l,
        Err(e) => return failed(&e),
    };
    // campaign.json is read through no link (the campaign directory is a closed world).
    let info = a.dir.join("campaign.json");
    if std::fs::symlink_metadata(&info).is_ok_and(|m| m.file_type().is_symlink()) {
        return fail(
            exit_codes::DIRECTORY_REFUSED,
            format!(
                "{}: a symbolic link; granular serve reads no campaign through one (granular writes campaign.json as a file)",
                info.display()
            ),
        );
    }
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    let links = serve::links_out(&c.root);
    let server = match serve::bind(c, a.addr, limits) {
        Ok(s) => s,
        Err(e) => return failed(&e),
    };
    let addr = match server.local_addr() {
        Ok(x) => x,
        Err(e) => return failed(&e),
    };
    for l in &links {
        eprintln!(
            "warning: {l}: granular follows no such link, so the page and the status are refused (503) while it is there; the table files inside are served"
        );
    }
    if !addr.ip().is_loopback() {
        eprintln!(
            "warning: {addr} is not a loopback address: whoever reaches it can read this campaign (read-only, no authentication)"
        );
    }
    {
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "serving {} at http://{addr}/", a.dir.display());
        let _ = out.flush();
    }
    match server.run() {
        Ok(()) => exit_codes::OK,
        Err(e) => failed(&e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_address_is_loopback() {
        let a: SocketAddr = serve::DEFAULT_ADDR.parse().unwrap();
        assert!(a.ip().is_loopback());
        assert_eq!(a.port(), 8080);
        assert_eq!(
            parse_addr("localhost:0").unwrap(),
            "127.0.0.1:0".parse().unwrap()
        );
        assert_eq!(
            parse_addr("[::1]:9000").unwrap(),
            "[::1]:9000".parse().unwrap()
        );
        for bad in [
            "8080",
            "localhost",
            "localhost:x",
            "1.2.3.4:99999",
            "example.org:80",
        ] {
            assert!(parse_addr(bad).is_err(), "{bad}");
        }
    }
}
