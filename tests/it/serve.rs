//! `granular serve`: the dashboard (figures, progress table, live script), `/api/status` equal
//! to `status --json`, table files downloaded byte for byte, every method but GET/HEAD refused
//! (405) and nothing in the directory changed, traversal (`..`, `%2e%2e`, encoded slashes and
//! backslashes, absolute paths) refused without the target's content; refusals of `status`
//! (not a campaign), a bad `--addr` (2), an address in use (3); and a campaign run by another
//! process followed while it runs.
//!
//! A hostile campaign directory (a closed world: no symbolic link out of it is followed):
//! `tables` itself, a table directory or a part file linked outside are neither served nor
//! listed, the page and status are refused naming the link, nothing outside is read (a FIFO
//! outside has no reader) or changed; `campaign.json` a link is refused. Hostile clients: a
//! slow client is disconnected after the header timeout while others are answered, an idle
//! keep-alive connection is closed, 200 idle sockets against a server with 64 file
//! descriptors do not keep the dashboard from answering, and two `Host` headers (or none in
//! HTTP/1.1, or a foreign authority in the request target) are refused; a bad test-only limit
//! in the environment is refused (2).
//!
//! Requests are raw HTTP/1.1 over `TcpStream` (no client library: the paths go out exactly as
//! written, undecoded).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant, SystemTime};

use serde_json::{json, Value};

use super::util::s;
use super::util::{
    bin, granular, heavy, log_text, run_capture, run_granular, snapshot, write_json,
};

const LIMIT: Duration = Duration::from_secs(300);

/// A running `granular serve`, killed on drop.
struct Server {
    child: Child,
    addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Start `granular serve DIR --addr 127.0.0.1:0` and read the address it prints.
fn serve(dir: &Path, log: &Path) -> Server {
    serve_with(dir, log, &[], None)
}

/// `serve` with the environment variables `env` and, with `nofile`, the soft limit of open
/// files of the server lowered to it (`ulimit -n`).
fn serve_with(dir: &Path, log: &Path, env: &[(&str, &str)], nofile: Option<u64>) -> Server {
    let f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .unwrap();
    let mut cmd = Command::new(bin());
    cmd.args(["serve", s(dir), "--addr", "127.0.0.1:0"])
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(f);
    if let Some(n) = nofile {
        use std::os::unix::process::CommandExt;
        // SAFETY: getrlimit and setrlimit are async-signal-safe system calls.
        unsafe {
            cmd.pre_exec(move || {
                let mut r = libc::rlimit {
                    rlim_cur: 0,
                    rlim_max: 0,
                };
                if libc::getrlimit(libc::RLIMIT_NOFILE, &mut r) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                r.rlim_cur = n.min(r.rlim_max);
                if libc::setrlimit(libc::RLIMIT_NOFILE, &r) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    let mut child = cmd.spawn().expect("spawn granular serve");
    let out = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(out).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = match rx.recv_timeout(Duration::from_secs(60)) {
        Ok(l) => l,
        Err(_) => {
            let _ = child.kill();
            panic!("serve printed no address; log:\n{}", log_text(log));
        }
    };
    let mut server = Server {
        child,
        addr: String::new(),
    };
    let addr = line
        .trim()
        .strip_prefix(&format!("serving {} at http://", s(dir)))
        .and_then(|r| r.strip_suffix('/'))
        .unwrap_or_else(|| panic!("unexpected first line {line:?}; log:\n{}", log_text(log)));
    assert!(addr.starts_with("127.0.0.1:"), "{addr}");
    assert_ne!(addr, "127.0.0.1:0", "the actual port is printed");
    server.addr = addr.to_string();
    server
}

/// One response.
struct Resp {
    code: u16,
    head: String,
    body: Vec<u8>,
}

impl Resp {
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
    fn header(&self, name: &str) -> Option<String> {
        self.head.lines().find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.eq_ignore_ascii_case(name).then(|| v.trim().to_string())
        })
    }
}

/// Send `METHOD target HTTP/1.1` as written (the target is not normalised or encoded).
fn request(addr: &str, method: &str, target: &str) -> Resp {
    let body = if matches!(method, "POST" | "PUT" | "PATCH") {
        "x=1"
    } else {
        ""
    };
    raw_request(
        addr,
        &format!(
            "{method} {target} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
            body.len()
        ),
    )
}

/// Send `text` as it is and read the response to the end of the connection.
fn raw_request(addr: &str, text: &str) -> Resp {
    let mut st = TcpStream::connect(addr).expect("connect");
    st.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    st.write_all(text.as_bytes()).unwrap();
    let mut raw = Vec::new();
    st.read_to_end(&mut raw).expect("read response");
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("no header end: {:?}", String::from_utf8_lossy(&raw)));
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut body = raw[split + 4..].to_vec();
    let code: u16 = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    let r = Resp {
        code,
        head,
        body: Vec::new(),
    };
    if r.header("transfer-encoding")
        .is_some_and(|t| t.contains("chunked"))
    {
        body = dechunk(&body);
    }
    Resp { body, ..r }
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let eol = b.windows(2).position(|w| w == b"\r\n").expect("chunk size");
        let n = usize::from_str_radix(
            std::str::from_utf8(&b[..eol])
                .unwrap()
                .split(';')
                .next()
                .unwrap()
                .trim(),
            16,
        )
        .unwrap();
        if n == 0 {
            return out;
        }
        out.extend_from_slice(&b[eol + 2..eol + 2 + n]);
        b = &b[eol + 2 + n + 2..];
    }
}

fn get(addr: &str, target: &str) -> Resp {
    request(addr, "GET", target)
}

/// 2 points x 2 replicas of a small DSMC campaign (well under a second).
fn manifest() -> Value {
    json!({
        "name": "serve-test",
        "model": "dsmc",
        "seed": 7,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": 10.0,
            "output_times": {"list": [0.5, 1.0, 5.0, 10.0]},
            "observables": ["temperature", "msd"]
        },
        "sweep": {"restitution.constant": [0.7, 0.9]}
    })
}

#[test]
fn serve_a_finished_campaign_read_only() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
    );
    write_json(&m, &manifest());
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    // (Links out of the campaign: `serve_never_follows_a_link_out_of_the_campaign`.)
    let (_, status_json) = run_capture(&["status", s(&c), "--json"], &log);
    let want_status: Value = serde_json::from_str(&status_json).expect("status --json");
    let before = snapshot(&c);

    let srv = serve(&c, &log);
    let a = srv.addr.as_str();

    // The dashboard: the report's figures and progress table, and the live script.
    let r = get(a, "/");
    assert_eq!(r.code, 200, "{}", r.head);
    let page = r.text();
    assert!(page.starts_with("<!DOCTYPE html>"));
    assert!(page.contains("serve-test"));
    assert!(page.contains("id=\"progress-table\""));
    assert!(page.contains("data-point=\"0\"") && page.contains("data-point=\"1\""));
    assert!(page.contains("constant=0.7") && page.contains("constant=0.9"));
    assert!(page.contains("4: 4 done, 0 failed, 0 running, 0 pending"));
    let figures = page.matches("<figure").count();
    assert!(figures >= 2, "{figures} figures");
    assert_eq!(page.matches("<svg").count(), figures);
    assert!(page.contains("id=\"live\"") && page.contains("/api/status"));
    assert!(!page.to_ascii_lowercase().contains("src=\"http"));
    assert!(!page.to_ascii_lowercase().contains("<link"));

    // /api/status is status --json.
    let r = get(a, "/api/status");
    assert_eq!(r.code, 200);
    assert!(r
        .header("content-type")
        .unwrap()
        .contains("application/json"));
    let got: Value = serde_json::from_slice(&r.body).expect("JSON");
    assert_eq!(got, want_status);
    let r = request(a, "HEAD", "/api/status");
    assert_eq!(r.code, 200);
    assert!(r.body.is_empty());

    // The report as a download, without the script.
    let r = get(a, "/report.html");
    assert_eq!(r.code, 200);
    assert!(r
        .header("content-disposition")
        .is_some_and(|d| d.contains("attachment")));
    assert!(!r.text().contains("<script"));
    assert_eq!(r.text().matches("<figure").count(), figures);

    // Table files: listed, downloaded byte for byte.
    let r = get(a, "/api/tables");
    assert_eq!(r.code, 200);
    let files: Vec<Value> = serde_json::from_slice(&r.body).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| {
            format!(
                "{}/{}",
                f["table"].as_str().unwrap(),
                f["file"].as_str().unwrap()
            )
        })
        .collect();
    assert!(names.iter().any(|n| n.starts_with("runs/")), "{names:?}");
    assert!(names.iter().any(|n| n.starts_with("points/")), "{names:?}");
    for n in &names {
        assert!(
            !n.contains("passwd") && !n.contains("secret") && !n.starts_with("outside"),
            "{n} listed"
        );
    }
    let listing = get(a, "/tables/").text();
    for n in &names {
        let real = c.join("tables").join(n);
        let r = get(a, &format!("/tables/{n}"));
        assert_eq!(r.code, 200, "{n}: {}", r.head);
        assert_eq!(r.body, std::fs::read(&real).unwrap(), "{n} differs");
        assert_eq!(
            r.header("content-length").unwrap(),
            r.body.len().to_string()
        );
        if n.ends_with(".parquet") {
            assert_eq!(
                r.header("content-type").unwrap(),
                "application/vnd.apache.parquet"
            );
        }
        assert!(
            listing.contains(&format!("/tables/{n}\"")),
            "{n} not linked"
        );
        let h = request(a, "HEAD", &format!("/tables/{n}"));
        assert_eq!(h.code, 200);
        assert!(h.body.is_empty());
    }

    // Traversal: refused, never the target's content.
    let campaign_json = std::fs::read_to_string(c.join("campaign.json")).unwrap();
    for target in [
        "/tables/../campaign.json",
        "/tables/runs/../../campaign.json",
        "/tables/%2e%2e/campaign.json",
        "/tables/%2E%2E/campaign.json",
        "/tables/x/%2e%2e%2f%2e%2e%2fcampaign.json",
        "/tables/runs/%2e%2e%2f%2e%2e%2fcampaign.json",
        "/tables/..%2fcampaign.json",
        "/tables/..%2Fcampaign.json",
        "/tables/runs%2f..%2f..%2fcampaign.json",
        "/tables/runs/..%5c..%5ccampaign.json",
        "/tables/runs\\..\\..\\campaign.json",
        "/tables//etc/passwd",
        "/tables/%2fetc%2fpasswd",
        "/tables/runs/%2fetc%2fpasswd",
        "/tables/runs/passwd.parquet",
        "/tables/runs/secret.parquet",
        "/tables/outside/secret.parquet",
        "/tables/runs/campaign.json%00.parquet",
        "/tables/.gen",
        "/tables/runs/.",
        "/../campaign.json",
        "/campaign.json",
        "/%2e%2e/campaign.json",
    ] {
        let r = get(a, target);
        assert!(
            matches!(r.code, 400 | 403 | 404),
            "{target}: {} {}",
            r.code,
            r.text()
        );
        let body = r.text();
        for leaked in ["root:", "TOP-SECRET", "registry", "format_version"] {
            assert!(!body.contains(leaked), "{target} leaked {leaked}: {body}");
        }
        assert!(!campaign_json.is_empty() && !body.contains(&campaign_json[..20]));
    }

    // Read-only: every other method 405, wherever it points.
    let part = &names[0];
    for method in ["POST", "PUT", "DELETE", "PATCH", "OPTIONS"] {
        for target in [
            "/".to_string(),
            "/api/status".to_string(),
            format!("/tables/{part}"),
            "/tables/runs/new.parquet".to_string(),
            "/nowhere".to_string(),
        ] {
            let r = request(a, method, &target);
            assert_eq!(r.code, 405, "{method} {target}");
            assert_eq!(r.header("allow").as_deref(), Some("GET, HEAD"));
        }
    }
    // A page of another site (DNS rebinding) is refused on loopback.
    let mut st = TcpStream::connect(a).unwrap();
    st.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(
        st,
        "GET /api/status HTTP/1.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut raw = String::new();
    st.read_to_string(&mut raw).unwrap();
    assert!(raw.starts_with("HTTP/1.1 403"), "{raw}");

    // The address is in use: refused (3), naming it.
    let (code, _) = run_capture(&["serve", s(&c), "--addr", a], &log);
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));
    assert!(log_text(&log).contains("is in use"));

    drop(srv);
    assert!(
        before == snapshot(&c),
        "serving changed the campaign directory"
    );
}

#[test]
fn serve_refuses_what_status_refuses() {
    let tmp = tempfile::tempdir().unwrap();
    let (log1, log2) = (tmp.path().join("log1"), tmp.path().join("log2"));
    // Not a campaign: the same refusal as status (3, the same message).
    let (code, _) = run_capture(&["status", s(tmp.path())], &log1);
    let (code2, out) = run_capture(&["serve", s(tmp.path()), "--addr", "127.0.0.1:0"], &log2);
    assert_eq!(code, Some(3));
    assert_eq!(code2, code);
    assert!(out.is_empty(), "{out}");
    assert_eq!(log_text(&log1), log_text(&log2));
    // A bad --addr: a usage error (2) naming the flag.
    for bad in ["nowhere", "127.0.0.1", "127.0.0.1:99999"] {
        let (code, _) = run_capture(&["serve", s(tmp.path()), "--addr", bad], &log2);
        assert_eq!(code, Some(2), "{bad}");
        let text = log_text(&log2);
        assert!(text.contains("--addr"), "{text}");
    }
}

/// `campaign.json` a link (to a file outside): refused (3) before anything is read through it.
/// A bad test-only limit in the environment: refused (2), naming the variable.
#[test]
fn serve_refuses_a_linked_campaign_json_and_bad_limits() {
    let tmp = tempfile::tempdir().unwrap();
    let (c, log) = (tmp.path().join("c"), tmp.path().join("log"));
    std::fs::create_dir(&c).unwrap();
    std::fs::write(tmp.path().join("outside.json"), "{}").unwrap();
    std::os::unix::fs::symlink(tmp.path().join("outside.json"), c.join("campaign.json")).unwrap();
    let (code, out) = run_capture(&["serve", s(&c), "--addr", "127.0.0.1:0"], &log);
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));
    assert!(out.is_empty(), "{out}");
    let text = log_text(&log);
    assert!(
        text.contains(&format!(
            "{}: a symbolic link",
            c.join("campaign.json").display()
        )),
        "{text}"
    );
    let log = tmp.path().join("log2");
    let out = Command::new(bin())
        .args(["serve", s(tmp.path()), "--addr", "127.0.0.1:0"])
        .env("GRANULAR_SERVE_HEADER_TIMEOUT_MS", "soon")
        .env("GRANULAR_SERVE_MAX_CONNECTIONS", "0")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    std::fs::write(&log, &out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2), "log:\n{}", log_text(&log));
    let text = log_text(&log);
    for var in [
        "GRANULAR_SERVE_HEADER_TIMEOUT_MS",
        "GRANULAR_SERVE_MAX_CONNECTIONS",
    ] {
        assert!(text.contains(var), "{text}");
    }
}

/// A campaign run by another process: `/api/status` shows a run running, then more runs done,
/// while `granular run` goes on.
#[test]
fn serve_follows_a_running_campaign() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log, run_log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
        tmp.path().join("run.log"),
    );
    // 3 runs of a few seconds each, one at a time, each committed when it finishes.
    write_json(
        &m,
        &json!({
            "name": "serve-live",
            "model": "dsmc",
            "seed": 3,
            "replicas": 3,
            "params": {
                "method": "low_rank",
                "species": {"power_law": {"n1": 0.1, "N1": 800000, "theta": 3}},
                "restitution": {"constant": 0.8},
                "t_end": 100.0,
                "output_times": {"list": [1.0, 100.0]},
                "observables": ["temperature"]
            }
        }),
    );
    struct Killed(Child);
    impl Drop for Killed {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let mut run = Killed(
        granular(
            &[
                "run",
                s(&m),
                "--out",
                s(&c),
                "--threads",
                "1",
                "--flush-every",
                "0",
                "--quiet",
            ],
            &run_log,
        )
        .spawn()
        .expect("spawn run"),
    );
    let t0 = Instant::now();
    while !c.join("campaign.json").exists() {
        assert!(
            t0.elapsed() < LIMIT,
            "no campaign.json; log:\n{}",
            log_text(&run_log)
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let srv = serve(&c, &log);
    let (mut saw_running, mut first_done, mut last_done) = (false, None, 0);
    let mut finished = false;
    while t0.elapsed() < LIMIT {
        let r = get(&srv.addr, "/api/status");
        if r.code == 200 {
            let st: Value = serde_json::from_slice(&r.body).expect("JSON");
            let (done, running) = (
                st["done"].as_u64().unwrap(),
                st["running"].as_u64().unwrap(),
            );
            if running > 0 {
                saw_running = true;
                assert!(
                    !st["live_shards"].as_array().unwrap().is_empty(),
                    "running without a live shard: {st}"
                );
            }
            first_done.get_or_insert(done);
            last_done = done;
            if done == 3 {
                break;
            }
        }
        if !finished {
            if let Some(status) = run.0.try_wait().unwrap() {
                assert!(status.success(), "run failed; log:\n{}", log_text(&run_log));
                finished = true;
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        saw_running,
        "no running run seen; log:\n{}",
        log_text(&run_log)
    );
    assert_eq!(last_done, 3, "log:\n{}", log_text(&run_log));
    assert!(
        first_done.unwrap() < 3,
        "the campaign had finished before the first answer"
    );
    // The dashboard of the finished campaign.
    let page = get(&srv.addr, "/").text();
    assert!(page.contains("3: 3 done, 0 failed, 0 running, 0 pending"));
}

/// A finished campaign of [`manifest`] in `tmp/c`.
fn finished_campaign(tmp: &Path) -> PathBuf {
    let _g = heavy();
    let (m, c, log) = (tmp.join("m.json"), tmp.join("c"), tmp.join("run.log"));
    write_json(&m, &manifest());
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    c
}

/// What is under `dir`, links not followed and FIFOs not opened: every entry with its kind,
/// its content (a file's bytes, a link's target) and its modification time.
type Entries = BTreeMap<PathBuf, (&'static str, Vec<u8>, SystemTime)>;

fn entries(dir: &Path) -> Entries {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("read_dir") {
            let p = e.expect("entry").path();
            let md = std::fs::symlink_metadata(&p).expect("lstat");
            let t = md.file_type();
            let (kind, content) = if t.is_dir() {
                stack.push(p.clone());
                ("dir", Vec::new())
            } else if t.is_symlink() {
                let target = std::fs::read_link(&p).expect("read_link");
                ("link", target.into_os_string().into_encoded_bytes())
            } else if t.is_file() {
                ("file", std::fs::read(&p).expect("read"))
            } else {
                ("other", Vec::new())
            };
            out.insert(p, (kind, content, md.modified().expect("mtime")));
        }
    }
    out
}

/// The table files `/api/tables` lists, as `table/file`.
fn listed(addr: &str) -> Vec<String> {
    let r = get(addr, "/api/tables");
    assert_eq!(r.code, 200, "{}", r.text());
    let files: Vec<Value> = serde_json::from_slice(&r.body).expect("JSON");
    files
        .iter()
        .map(|f| {
            format!(
                "{}/{}",
                f["table"].as_str().unwrap(),
                f["file"].as_str().unwrap()
            )
        })
        .collect()
}

fn mkfifo(p: &Path) {
    let c = std::ffi::CString::new(s(p)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
}

/// Whether some process holds the FIFO `p` open for reading (or waits to): an open for
/// writing that must not block fails with ENXIO when none does.
fn fifo_has_reader(p: &Path) -> bool {
    use std::os::unix::fs::OpenOptionsExt;
    match std::fs::OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(p)
    {
        Ok(_) => true,
        Err(e) if e.raw_os_error() == Some(libc::ENXIO) => false,
        Err(e) => panic!("{}: {e}", p.display()),
    }
}

/// The page, the status and the report download are refused (503), naming every link in
/// `links` and showing nothing of `secret`.
fn page_refused(addr: &str, links: &[PathBuf], secret: &str) {
    for target in ["/", "/api/status", "/report.html"] {
        let r = get(addr, target);
        let text = r.text();
        assert_eq!(r.code, 503, "{target}: {text}");
        assert!(!text.contains(secret), "{target} leaked: {text}");
        for l in links {
            assert!(
                text.contains(&format!("{}: a symbolic link", l.display())),
                "{target} does not name {}: {text}",
                l.display()
            );
        }
    }
}

/// `DIR/tables` itself a link to a directory outside (a campaign unpacked from someone else's
/// tarball): nothing under it is served or listed, and nothing outside is changed.
#[test]
fn serve_refuses_tables_linked_outside() {
    let tmp = tempfile::tempdir().unwrap();
    let c = finished_campaign(tmp.path());
    let log = tmp.path().join("log");
    let outside = tmp.path().join("outside");
    std::fs::create_dir_all(outside.join("runs")).unwrap();
    std::fs::create_dir_all(outside.join("etc")).unwrap();
    std::fs::write(outside.join("runs/secret.parquet"), "TOP-SECRET-CONTENT").unwrap();
    std::fs::write(outside.join("etc/passwd"), "root:x:0:0:TOP-SECRET").unwrap();
    std::fs::rename(c.join("tables"), tmp.path().join("tables-set-aside")).unwrap();
    std::os::unix::fs::symlink(&outside, c.join("tables")).unwrap();
    let (before, before_outside) = (snapshot(&c), entries(&outside));

    let srv = serve(&c, &log);
    let a = srv.addr.as_str();
    for target in [
        "/tables/runs/secret.parquet",
        "/tables/etc/passwd",
        "/tables/runs/missing.parquet",
    ] {
        let r = get(a, target);
        assert_eq!(r.code, 404, "{target}: {}", r.text());
        assert!(!r.text().contains("TOP-SECRET"), "{target} leaked");
    }
    assert_eq!(listed(a), Vec::<String>::new());
    let page = get(a, "/tables/");
    assert_eq!(page.code, 200);
    assert!(page.text().contains("No table files"), "{}", page.text());
    assert!(!page.text().contains("secret") && !page.text().contains("passwd"));
    page_refused(a, &[c.join("tables")], "TOP-SECRET");

    drop(srv);
    assert!(
        before == snapshot(&c),
        "serving changed the campaign directory"
    );
    assert!(
        before_outside == entries(&outside),
        "serving changed the outside"
    );
}

/// A table directory that is a link to a directory outside (whose files may even link back
/// into the campaign), or to a generation of another table: not served, not listed; the real
/// tables still are.
#[test]
fn serve_refuses_a_table_dir_linked_outside() {
    let tmp = tempfile::tempdir().unwrap();
    let c = finished_campaign(tmp.path());
    let log = tmp.path().join("log");
    let part = std::fs::read_dir(c.join("tables/runs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .find(|n| n.ends_with(".parquet"))
        .expect("a runs part");
    let real_part = c.join("tables/runs").join(&part).canonicalize().unwrap();
    let outside = tmp.path().join("outside");
    std::fs::create_dir(&outside).unwrap();
    std::fs::write(outside.join("secret.parquet"), "TOP-SECRET-CONTENT").unwrap();
    std::os::unix::fs::symlink(&real_part, outside.join("back.parquet")).unwrap();
    std::os::unix::fs::symlink(&outside, c.join("tables/evil")).unwrap();
    let gen = std::fs::read_link(c.join("tables/runs")).unwrap();
    std::os::unix::fs::symlink(&gen, c.join("tables/other")).unwrap();
    let (before, before_outside) = (snapshot(&c), entries(&outside));

    let srv = serve(&c, &log);
    let a = srv.addr.as_str();
    for target in [
        "/tables/evil/secret.parquet".to_string(),
        "/tables/evil/back.parquet".to_string(),
        format!("/tables/other/{part}"),
    ] {
        let r = get(a, &target);
        assert_eq!(r.code, 404, "{target}: {}", r.text());
        assert!(!r.text().contains("TOP-SECRET"), "{target} leaked");
    }
    let names = listed(a);
    assert!(names.contains(&format!("runs/{part}")), "{names:?}");
    assert!(names.iter().any(|n| n.starts_with("points/")), "{names:?}");
    for n in &names {
        assert!(
            !n.starts_with("evil/") && !n.starts_with("other/"),
            "{n} listed"
        );
    }
    let listing = get(a, "/tables/").text();
    assert!(!listing.contains("evil") && !listing.contains("/tables/other/"));
    let r = get(a, &format!("/tables/runs/{part}"));
    assert_eq!(r.code, 200);
    assert_eq!(r.body, std::fs::read(&real_part).unwrap());
    page_refused(
        a,
        &[c.join("tables/evil"), c.join("tables/other")],
        "TOP-SECRET",
    );

    drop(srv);
    assert!(
        before == snapshot(&c),
        "serving changed the campaign directory"
    );
    assert!(
        before_outside == entries(&outside),
        "serving changed the outside"
    );
}

/// Part files that are links (to a file outside, to a FIFO outside, to a part beside them):
/// not served, not listed, and nothing outside opened (the FIFO never has a reader).
#[test]
fn serve_refuses_part_files_that_are_links() {
    let tmp = tempfile::tempdir().unwrap();
    let c = finished_campaign(tmp.path());
    let log = tmp.path().join("log");
    let runs = c.join("tables/runs");
    let part = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .find(|n| n.ends_with(".parquet"))
        .expect("a runs part");
    let outside = tmp.path().join("outside");
    std::fs::create_dir(&outside).unwrap();
    std::fs::write(outside.join("secret.parquet"), "TOP-SECRET-CONTENT").unwrap();
    mkfifo(&outside.join("fifo"));
    let links = [
        runs.join("secret.parquet"),
        runs.join("part-s1of1-999999.parquet"),
        runs.join("copy.parquet"),
    ];
    std::os::unix::fs::symlink(outside.join("secret.parquet"), &links[0]).unwrap();
    std::os::unix::fs::symlink(outside.join("fifo"), &links[1]).unwrap();
    std::os::unix::fs::symlink(&part, &links[2]).unwrap();
    let (before, before_outside) = (snapshot(&c), entries(&outside));

    let srv = serve(&c, &log);
    let a = srv.addr.as_str();
    for l in &links {
        let target = format!("/tables/runs/{}", l.file_name().unwrap().to_str().unwrap());
        let r = get(a, &target);
        assert_eq!(r.code, 404, "{target}: {}", r.text());
        assert!(!r.text().contains("TOP-SECRET"), "{target} leaked");
    }
    let names = listed(a);
    assert!(names.contains(&format!("runs/{part}")), "{names:?}");
    for l in &links {
        let n = format!("runs/{}", l.file_name().unwrap().to_str().unwrap());
        assert!(!names.contains(&n), "{n} listed");
    }
    // The page and status are refused: they would be read through the links.
    page_refused(a, &links, "TOP-SECRET");
    assert!(
        !fifo_has_reader(&outside.join("fifo")),
        "the server opened the FIFO outside"
    );

    drop(srv);
    assert!(
        before == snapshot(&c),
        "serving changed the campaign directory"
    );
    assert!(
        before_outside == entries(&outside),
        "serving changed the outside"
    );
}

/// A slow client (half a request head, then nothing) is disconnected after the header timeout
/// while others are answered; an idle keep-alive connection is closed too.
#[test]
fn serve_disconnects_slow_and_idle_clients() {
    let tmp = tempfile::tempdir().unwrap();
    let c = finished_campaign(tmp.path());
    let log = tmp.path().join("log");
    let srv = serve_with(
        &c,
        &log,
        &[("GRANULAR_SERVE_HEADER_TIMEOUT_MS", "300")],
        None,
    );
    let a = srv.addr.as_str();
    let mut slow = TcpStream::connect(a).unwrap();
    slow.set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    slow.write_all(format!("GET /api/status HTTP/1.1\r\nHost: {a}\r\n").as_bytes())
        .unwrap();
    // Another client is answered meanwhile.
    let r = get(a, "/api/status");
    assert_eq!(r.code, 200, "{}", r.text());
    // The slow one gets no answer, only the end of the connection.
    let mut got = Vec::new();
    let end = slow.read_to_end(&mut got);
    assert!(end.is_ok(), "the slow client was not disconnected: {end:?}");
    assert!(
        !got.starts_with(b"HTTP/1.1 200"),
        "{:?}",
        String::from_utf8_lossy(&got)
    );

    // A keep-alive connection: one answer, then closed when idle.
    let mut ka = TcpStream::connect(a).unwrap();
    ka.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    ka.write_all(format!("GET /api/status HTTP/1.1\r\nHost: {a}\r\n\r\n").as_bytes())
        .unwrap();
    let mut raw = Vec::new();
    let end = ka.read_to_end(&mut raw);
    assert!(end.is_ok(), "the idle connection was not closed: {end:?}");
    let text = String::from_utf8_lossy(&raw);
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    assert_eq!(text.matches("HTTP/1.1 ").count(), 1, "{text}");
}

/// 200 idle sockets (half of them with half a request head) against a server allowed 64 open
/// files: the dashboard still answers.
#[test]
fn serve_answers_while_idle_sockets_are_held() {
    let tmp = tempfile::tempdir().unwrap();
    let c = finished_campaign(tmp.path());
    let log = tmp.path().join("log");
    let srv = serve_with(&c, &log, &[], Some(64));
    let a = srv.addr.as_str();
    let addr: std::net::SocketAddr = a.parse().unwrap();
    // The server's sockets, sampled while the idle ones arrive: the listener, at most the cap
    // of 16 connections ((64 - 32) / 2, evicted ones still closing included), and one accepted
    // only to be closed. (Before the cap counted sockets rather than live connections, a burst
    // of accepts held dozens and the status below found no descriptor.)
    let fds = PathBuf::from(format!("/proc/{}/fd", srv.child.id()));
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = {
        let sampling = sampling.clone();
        std::thread::spawn(move || {
            let mut most = 0;
            while sampling.load(Ordering::Relaxed) {
                let sockets = std::fs::read_dir(&fds)
                    .into_iter()
                    .flatten()
                    .flatten()
                    .filter(|e| {
                        std::fs::read_link(e.path())
                            .is_ok_and(|t| t.to_string_lossy().starts_with("socket:"))
                    })
                    .count();
                most = most.max(sockets);
            }
            most
        })
    };
    let mut idle = Vec::new();
    for i in 0..200 {
        let mut st = TcpStream::connect_timeout(&addr, Duration::from_secs(20))
            .unwrap_or_else(|e| panic!("idle socket {i}: {e}; log:\n{}", log_text(&log)));
        if i % 2 == 0 {
            // The server may have closed it already.
            let _ = st.write_all(b"GET / HTTP/1.1\r\n");
        }
        idle.push(st);
    }
    std::thread::sleep(Duration::from_millis(200));
    sampling.store(false, Ordering::Relaxed);
    let most = sampler.join().unwrap();
    assert!(most <= 18, "the server held {most} sockets at once");
    for target in ["/api/status", "/", "/api/tables"] {
        let r = get(a, target);
        assert_eq!(r.code, 200, "{target}: {}", r.text());
    }
    assert!(get(a, "/").text().contains("4: 4 done"));
    drop(idle);
}

/// `Host` decides whether a request may read the campaign (DNS rebinding): two of them, none
/// in HTTP/1.1, or a foreign authority in the request target are refused.
#[test]
fn serve_refuses_ambiguous_hosts() {
    let tmp = tempfile::tempdir().unwrap();
    let c = finished_campaign(tmp.path());
    let log = tmp.path().join("log");
    let srv = serve(&c, &log);
    let a = srv.addr.as_str();
    for (head, code) in [
        (
            format!("GET /api/status HTTP/1.1\r\nHost: {a}\r\nHost: evil.example\r\n"),
            400,
        ),
        (
            format!("GET /api/status HTTP/1.1\r\nHost: evil.example\r\nHost: {a}\r\n"),
            400,
        ),
        (
            format!("GET /api/status HTTP/1.1\r\nHost: {a}\r\nHost: {a}\r\n"),
            400,
        ),
        ("GET /api/status HTTP/1.1\r\n".to_string(), 400),
        (
            format!("GET http://evil.example/api/status HTTP/1.1\r\nHost: {a}\r\n"),
            403,
        ),
        (
            format!("GET http://{a}/api/status HTTP/1.1\r\nHost: {a}\r\n"),
            200,
        ),
        ("GET /api/status HTTP/1.0\r\n".to_string(), 200),
        (format!("GET /api/status HTTP/1.1\r\nHost: {a}\r\n"), 200),
    ] {
        let r = raw_request(a, &format!("{head}Connection: close\r\n\r\n"));
        assert_eq!(r.code, code, "{head:?}: {}", r.text());
        if code != 200 {
            assert!(!r.text().contains("\"runs\""), "{head:?}: {}", r.text());
        }
    }
}
