//! `granular serve`: a read-only live dashboard of a campaign over HTTP/1.1 (hyper, the
//! response types of axum, on a current-thread tokio runtime).
//!
//! - `/`: the report page (`report::build`) with a small inline script that polls
//!   `/api/status` every 2 s, updates the progress counts and bars in place, and swaps in the
//!   page's sections anew (figures, failures, campaign) when runs finish, the shards change or
//!   the campaign grows; a "live" line shows the time of the last answer, or that the server
//!   is unreachable.
//! - `/api/status`: the JSON of `granular status --json` (`campaign::status::to_json`).
//! - `/report.html`: the report as a download (no script).
//! - `/tables/`, `/api/tables`: the table files (HTML, JSON); `/tables/<table>/<file>`: one
//!   file, streamed.
//!
//! Read-only: only GET and HEAD are answered (anything else 405), no lock is taken, nothing
//! is healed or written; the campaign is read from disk again whenever the status
//! fingerprint (`campaign::status::fingerprint`: the ledger, locks and heartbeats, checkpoints,
//! tables, live lock holders) changes, or after `MAX_AGE`, so a campaign run by other
//! processes (shards, SLURM tasks) is followed. Computations run on blocking threads; one at
//! a time per cached item.
//!
//! The campaign directory is a closed world: the only symbolic links granular writes are the
//! generation links `tables/<table>` -> `.gen/<table>.<n>` (`store::layout`), and serve
//! follows no other. A table file is opened component by component from the campaign
//! directory (`openat` with `O_NOFOLLOW`: `tables` must be a directory, `<table>` a directory
//! or a generation link whose target is read and opened as `.gen/<table>.<n>` under `tables`,
//! the file a regular file), so a link swapped in between a check and the open cannot lead
//! out; the request path, percent-decoded segment by segment, must be `<table>/<file>`, no
//! segment empty, hidden (`.`, `..`, `.gen`, pending parts), or holding `/`, `\`, NUL or a
//! control character. The page and the status are read by the report and the campaign
//! through paths; before each computation [`links_out`] looks (without following) at what
//! they read, and while it finds a link (or a FIFO, socket or device) they are refused (503)
//! naming it.
//!
//! Hostile clients: a request's head must arrive within `header_timeout` of the connection
//! being ready for it (accepted, or the previous answer sent: also the keep-alive idle
//! timeout); an answer that makes no progress for `send_timeout` closes its connection; at
//! most `max_connections` connections are open (derived from the limit of open files): one
//! more closes the connection that has waited longest without progress and is not computing
//! an answer, and is accepted once that one's socket is closed, or, if every one is
//! computing, is accepted and closed itself. A request must have one `Host` (none only
//! in HTTP/1.0); on loopback it and an absolute request target must name this machine.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::ffi::{CStr, CString};
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::os::fd::{AsRawFd, FromRawFd, IntoRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::body::{Body, Bytes};
use axum::http::{header, request, HeaderValue, Method, StatusCode, Version};
use axum::response::Response;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use crate::campaign::{status, Campaign, CampaignError};
use crate::exit_codes::{Classed, ExitClass};
use crate::report;
use crate::store::layout::GEN_DIR;

/// The default address: loopback only.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8080";

/// How long a cached status or page is used while the fingerprint stays the same (the
/// fingerprint does not see a table file changed in place, nor a SLURM job's queue state).
const MAX_AGE: Duration = Duration::from_secs(30);
/// The same while SLURM submissions are recorded (their queue states come from `squeue`).
const MAX_AGE_SLURM: Duration = Duration::from_secs(10);
/// While `/api/status` was asked for within `WATCHED`, a refresher thread checks the
/// fingerprint every `REFRESH` and computes the status anew when it changed; meanwhile
/// requests are answered from the previous status (so at once, however large the campaign)
/// unless it is older than `STALE_LIMIT`.
const REFRESH: Duration = Duration::from_millis(250);
const WATCHED: Duration = Duration::from_secs(10);
const STALE_LIMIT: Duration = Duration::from_secs(10);

/// How long a request's head may take, from the moment its connection is ready for it
/// (accepted, or the previous answer sent): a slow client (half a head, then nothing) and an
/// idle keep-alive connection are closed after it. A browser's dashboard asks every 2 s.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// How long an answer may make no progress (a client that stopped reading) before its
/// connection is closed. Computing the answer (a large campaign's page) is not counted.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(30);
/// The most connections open at once, fewer where the limit of open files is low
/// ([`connection_cap`]).
pub const MAX_CONNECTIONS: usize = 256;
/// The fewest, however low the limit of open files.
pub const MIN_CONNECTIONS: usize = 4;
/// File descriptors left for the rest of the process (standard streams, the listener, the
/// runtime, the files the report and the status read), out of the limit of open files.
const RESERVED_FDS: u64 = 32;
/// After a failed accept (out of file descriptors: one idle connection is closed first).
const ACCEPT_BACKOFF: Duration = Duration::from_millis(10);

/// What one client may take of the server.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub header_timeout: Duration,
    pub send_timeout: Duration,
    pub max_connections: usize,
}

impl Limits {
    /// The defaults, with the connection cap derived from this process's limit of open files.
    pub fn for_this_process() -> Limits {
        Limits {
            header_timeout: HEADER_TIMEOUT,
            send_timeout: SEND_TIMEOUT,
            max_connections: connection_cap(open_files_limit()),
        }
    }
}

/// The soft limit of open files (`ulimit -n`); `None` if unlimited or unknown.
pub fn open_files_limit() -> Option<u64> {
    let mut r = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `r` is a valid rlimit for getrlimit to fill.
    if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut r) } != 0
        || r.rlim_cur == libc::RLIM_INFINITY
    {
        return None;
    }
    Some(r.rlim_cur as u64)
}

/// The connections served at once under a limit of `nofile` open files: each holds its socket
/// and, while it streams a table file, that file; `RESERVED_FDS` are left for the rest.
/// Between [`MIN_CONNECTIONS`] and [`MAX_CONNECTIONS`] (below the minimum's need, a failed
/// accept closes an idle connection and tries again).
pub fn connection_cap(nofile: Option<u64>) -> usize {
    match nofile {
        None => MAX_CONNECTIONS,
        Some(n) => usize::try_from(n.saturating_sub(RESERVED_FDS) / 2)
            .unwrap_or(MAX_CONNECTIONS)
            .clamp(MIN_CONNECTIONS, MAX_CONNECTIONS),
    }
}

/// A bound server: `local_addr` is known before `run` serves.
pub struct Server {
    rt: tokio::runtime::Runtime,
    listener: std::net::TcpListener,
    state: Arc<Served>,
    limits: Limits,
}

/// What one computed item is cached with.
struct Cached<T> {
    fingerprint: u64,
    at: Instant,
    max_age: Duration,
    value: T,
}

/// A computed text, or the error that computing it gave.
type Text = Result<Arc<String>, Unavailable>;

/// The errors of `bind` and `Server::run`; each says its exit class.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The address is taken (another server?): refused.
    #[error(
        "{0} is in use (another server?); choose another with --addr, e.g. --addr 127.0.0.1:0 for any free port"
    )]
    AddrInUse(SocketAddr),
    /// The address cannot be bound for another reason: I/O.
    #[error("--addr {addr}: {source}")]
    Bind { addr: SocketAddr, source: io::Error },
    /// Serving failed: I/O.
    #[error("{0}")]
    Io(#[from] io::Error),
}

impl Classed for ServeError {
    fn class(&self) -> ExitClass {
        match self {
            ServeError::AddrInUse(_) => ExitClass::Refused,
            ServeError::Bind { .. } | ServeError::Io(_) => ExitClass::Io,
        }
    }
}

/// Why the page or the status cannot be shown now (answered 503 with this text): the
/// campaign cannot be read, or its directory has a link out; never the process's exit.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{0}")]
pub struct Unavailable(String);

impl From<CampaignError> for Unavailable {
    fn from(e: CampaignError) -> Self {
        Unavailable(e.to_string())
    }
}

/// A cached text, and the lock of its computation.
#[derive(Default)]
struct Slot {
    value: Mutex<Option<Cached<Text>>>,
    compute: Mutex<()>,
}

struct Served {
    root: PathBuf,
    /// Whether the server listens on loopback only (then requests must name a local host:
    /// a DNS-rebinding page cannot read the campaign).
    loopback: bool,
    /// The campaign, opened again when `campaign.json` changes (a grown manifest).
    campaign: Mutex<(Option<std::time::SystemTime>, u64, Arc<Campaign>)>,
    status: Slot,
    page: Slot,
    /// When `/api/status` was last asked for.
    watched: Mutex<Option<Instant>>,
}

/// Bind `addr` for the campaign `c` (already opened by the caller, so that its refusals are
/// the other commands').
pub fn bind(c: Campaign, addr: SocketAddr, limits: Limits) -> Result<Server, ServeError> {
    let bound = (|| {
        let listener = std::net::TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        Ok::<_, io::Error>((listener, rt))
    })();
    let (listener, rt) = match bound {
        Ok(x) => x,
        Err(e) if e.kind() == io::ErrorKind::AddrInUse => return Err(ServeError::AddrInUse(addr)),
        Err(source) => return Err(ServeError::Bind { addr, source }),
    };
    let root = c.root.clone();
    let stamp = campaign_stamp(&root);
    Ok(Server {
        rt,
        listener,
        limits,
        state: Arc::new(Served {
            root,
            loopback: addr.ip().is_loopback(),
            campaign: Mutex::new((stamp.0, stamp.1, Arc::new(c))),
            status: Slot::default(),
            page: Slot::default(),
            // Watched from the start: the refresher computes the first status at once.
            watched: Mutex::new(Some(Instant::now())),
        }),
    })
}

impl Server {
    /// The address bound (the actual port when 0 was asked for).
    pub fn local_addr(&self) -> Result<SocketAddr, ServeError> {
        Ok(self.listener.local_addr()?)
    }

    /// Serve until the process ends (Ctrl-C/SIGTERM: the command line's handler exits).
    pub fn run(self) -> Result<(), ServeError> {
        let Server {
            rt,
            listener,
            state,
            limits,
        } = self;
        let s = state.clone();
        std::thread::Builder::new()
            .name("status-refresher".into())
            .spawn(move || loop {
                let watched = s
                    .watched
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .is_some_and(|t| t.elapsed() < WATCHED);
                if watched {
                    let _ = s.status_json(false);
                }
                std::thread::sleep(REFRESH);
            })?;
        rt.block_on(async move {
            let listener = tokio::net::TcpListener::from_std(listener)?;
            accept_loop(listener, state, limits).await
        })?;
        Ok(())
    }
}

/// Accept connections for ever, each served on a task of its own within `limits`.
async fn accept_loop(
    listener: tokio::net::TcpListener,
    state: Arc<Served>,
    limits: Limits,
) -> io::Result<()> {
    let conns = Arc::new(Conns::new(limits.max_connections));
    loop {
        // A slot before the accept, so that at most the cap of sockets is ever open. None:
        // every connection is computing an answer; the next one is accepted and closed.
        let slot = conns.slot().await;
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(e) => {
                // Out of file descriptors: make room. Otherwise a connection that ended
                // before it was accepted; either way, go on after a moment.
                if matches!(
                    e.raw_os_error(),
                    Some(libc::EMFILE | libc::ENFILE | libc::ENOBUFS | libc::ENOMEM)
                ) {
                    conns.evict_one();
                }
                drop(slot);
                tokio::time::sleep(ACCEPT_BACKOFF).await;
                continue;
            }
        };
        let Some(slot) = slot else {
            continue;
        };
        let conn = conns.admit(slot);
        let _ = stream.set_nodelay(true);
        tokio::spawn(serve_connection(
            stream,
            conn,
            conns.clone(),
            state.clone(),
            limits,
        ));
    }
}

/// One open connection, as the cap sees it.
struct Conn {
    id: u64,
    epoch: Instant,
    /// Milliseconds from `epoch` to the last byte received or sent.
    last: AtomicU64,
    /// Requests whose answer is being computed (such a connection is not closed for room).
    busy: AtomicUsize,
    /// Closes the connection (to make room for a new one).
    evict: tokio::sync::Notify,
    /// Its place under the cap, given back when the last reference goes: after the socket
    /// (which the connection's task owns) is closed, not when the connection is evicted.
    _slot: tokio::sync::OwnedSemaphorePermit,
}

impl Conn {
    fn touch(&self) {
        let ms = u64::try_from(self.epoch.elapsed().as_millis()).unwrap_or(u64::MAX);
        self.last.store(ms, Ordering::Relaxed);
    }
}

/// The open connections, at most `cap`: a connection holds one of `slots` from before its
/// socket is accepted until after it is closed, so evicted connections still closing count.
struct Conns {
    epoch: Instant,
    slots: Arc<tokio::sync::Semaphore>,
    next: AtomicU64,
    live: Mutex<BTreeMap<u64, Arc<Conn>>>,
}

impl Conns {
    fn new(cap: usize) -> Conns {
        Conns {
            epoch: Instant::now(),
            slots: Arc::new(tokio::sync::Semaphore::new(cap.max(1))),
            next: AtomicU64::new(0),
            live: Mutex::new(BTreeMap::new()),
        }
    }

    /// A slot for one more connection; at the cap, room is made (the connection idle longest
    /// is closed, and its socket waited for). `None` if there is none to make.
    async fn slot(&self) -> Option<tokio::sync::OwnedSemaphorePermit> {
        if let Ok(p) = self.slots.clone().try_acquire_owned() {
            return Some(p);
        }
        if !self.evict_one() {
            return None;
        }
        // Err only if the semaphore were closed, which it never is.
        self.slots.clone().acquire_owned().await.ok()
    }

    /// A new connection in `slot`.
    fn admit(&self, slot: tokio::sync::OwnedSemaphorePermit) -> Arc<Conn> {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let c = Arc::new(Conn {
            id,
            epoch: self.epoch,
            last: AtomicU64::new(0),
            busy: AtomicUsize::new(0),
            evict: tokio::sync::Notify::new(),
            _slot: slot,
        });
        c.touch();
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id, c.clone());
        c
    }

    fn evict_one(&self) -> bool {
        Self::evict_from(&mut self.live.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Close the connection that has waited longest without progress (idle, a slow client,
    /// a stalled answer) among those not computing an answer.
    fn evict_from(live: &mut BTreeMap<u64, Arc<Conn>>) -> bool {
        let victim = live
            .values()
            .filter(|c| c.busy.load(Ordering::Relaxed) == 0)
            .min_by_key(|c| (c.last.load(Ordering::Relaxed), c.id))
            .map(|c| c.id);
        match victim.and_then(|id| live.remove(&id)) {
            Some(c) => {
                c.evict.notify_one();
                true
            }
            None => false,
        }
    }

    fn leave(&self, id: u64) {
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(&id);
    }
}

/// Marks a connection as computing an answer while alive.
struct Busy<'a>(&'a Conn);

impl<'a> Busy<'a> {
    fn enter(c: &'a Conn) -> Busy<'a> {
        c.busy.fetch_add(1, Ordering::Relaxed);
        c.touch();
        Busy(c)
    }
}

impl Drop for Busy<'_> {
    fn drop(&mut self) {
        self.0.touch();
        self.0.busy.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Serve one connection (HTTP/1.1, keep-alive) until it ends, times out or is evicted.
async fn serve_connection(
    stream: tokio::net::TcpStream,
    conn: Arc<Conn>,
    conns: Arc<Conns>,
    s: Arc<Served>,
    limits: Limits,
) {
    let io = hyper_util::rt::TokioIo::new(Tracked {
        inner: stream,
        conn: conn.clone(),
        send_timeout: limits.send_timeout,
        stall: None,
    });
    let c = conn.clone();
    let svc = hyper::service::service_fn(move |req: hyper::Request<hyper::body::Incoming>| {
        let (s, c) = (s.clone(), c.clone());
        async move {
            // The request's body is never read (GET and HEAD have none).
            let (parts, _) = req.into_parts();
            let _busy = Busy::enter(&c);
            Ok::<_, Infallible>(dispatch(&s, &parts).await)
        }
    });
    let mut b = hyper::server::conn::http1::Builder::new();
    b.timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .keep_alive(true);
    let served = b.serve_connection(io, svc);
    let evicted = conn.evict.notified();
    futures_util::future::select(std::pin::pin!(served), std::pin::pin!(evicted)).await;
    conns.leave(conn.id);
}

/// A connection's socket that notes its progress for the cap and fails a write that makes no
/// progress for `send_timeout`.
struct Tracked {
    inner: tokio::net::TcpStream,
    conn: Arc<Conn>,
    send_timeout: Duration,
    stall: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl Tracked {
    fn sent<T>(&mut self, cx: &mut Context<'_>, r: Poll<io::Result<T>>) -> Poll<io::Result<T>> {
        match r {
            Poll::Pending => {
                let d = self.send_timeout;
                let stall = self
                    .stall
                    .get_or_insert_with(|| Box::pin(tokio::time::sleep(d)));
                if stall.as_mut().poll(cx).is_ready() {
                    return Poll::Ready(Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        "the client took none of the answer for the send timeout",
                    )));
                }
                Poll::Pending
            }
            Poll::Ready(r) => {
                self.stall = None;
                if r.is_ok() {
                    self.conn.touch();
                }
                Poll::Ready(r)
            }
        }
    }
}

impl AsyncRead for Tracked {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        let r = Pin::new(&mut this.inner).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            this.conn.touch();
        }
        r
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, b: &[u8]) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write(cx, b);
        this.sent(cx, r)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write_vectored(cx, bufs);
        this.sent(cx, r)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_flush(cx);
        this.sent(cx, r)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

fn campaign_stamp(root: &Path) -> (Option<std::time::SystemTime>, u64) {
    match std::fs::metadata(root.join("campaign.json")) {
        Ok(m) => (m.modified().ok(), m.len()),
        Err(_) => (None, 0),
    }
}

impl Served {
    /// The campaign as `campaign.json` now describes it.
    fn campaign(&self) -> Result<Arc<Campaign>, Unavailable> {
        let stamp = campaign_stamp(&self.root);
        let mut g = self.campaign.lock().unwrap_or_else(|e| e.into_inner());
        if (g.0, g.1) != stamp {
            let c = Campaign::open(&self.root)?;
            *g = (stamp.0, stamp.1, Arc::new(c));
        }
        Ok(g.2.clone())
    }

    /// A cached item, computed again when the fingerprint changed or it is too old; with
    /// `stale_ok`, the previous value while it is younger than `STALE_LIMIT`. Refused while
    /// the campaign directory has a link out of it ([`links_out`]).
    fn cached(
        &self,
        slot: &Slot,
        stale_ok: bool,
        make: impl FnOnce(&Campaign) -> Result<(String, bool), Unavailable>,
    ) -> Text {
        let lock = |m: &Mutex<Option<Cached<Text>>>| {
            let g = m.lock().unwrap_or_else(|e| e.into_inner());
            g.as_ref()
                .map(|c| (c.fingerprint, c.at.elapsed(), c.max_age, c.value.clone()))
        };
        let fp = status::fingerprint(&self.root);
        if let Some((f, age, max_age, v)) = lock(&slot.value) {
            if (f == fp && age < max_age) || (stale_ok && age < STALE_LIMIT) {
                return v;
            }
        }
        let _computing = slot.compute.lock().unwrap_or_else(|e| e.into_inner());
        // Computed while this thread waited?
        if let Some((f, age, max_age, v)) = lock(&slot.value) {
            if f == fp && age < max_age {
                return v;
            }
        }
        let links = links_out(&self.root);
        let computed = if links.is_empty() {
            self.campaign().and_then(|c| make(&c))
        } else {
            Err(Unavailable(links_refusal(&links)))
        };
        let (value, slurm) = match computed {
            Ok((v, slurm)) => (Ok(Arc::new(v)), slurm),
            Err(e) => (Err(e), false),
        };
        *slot.value.lock().unwrap_or_else(|e| e.into_inner()) = Some(Cached {
            fingerprint: fp,
            at: Instant::now(),
            max_age: if slurm { MAX_AGE_SLURM } else { MAX_AGE },
            value: value.clone(),
        });
        value
    }

    /// The status JSON; `stale_ok` for requests (the refresher keeps it current).
    fn status_json(&self, stale_ok: bool) -> Text {
        self.cached(&self.status, stale_ok, |c| {
            let s = status::status(c)?;
            Ok((status::to_json(&s), !s.slurm.is_empty()))
        })
    }

    /// The report page (without the live script), always current.
    fn page(&self) -> Text {
        self.cached(&self.page, false, |c| {
            let r = report::build(c)?;
            let slurm = r.html.contains("slurm submission");
            Ok((r.html, slurm))
        })
    }
}

/// Run `f` on a blocking thread (the runtime keeps answering).
async fn blocking<T: Send + 'static>(
    s: &Arc<Served>,
    f: impl FnOnce(&Served) -> T + Send + 'static,
) -> Result<T, Unavailable> {
    let s = s.clone();
    tokio::task::spawn_blocking(move || f(&s))
        .await
        .map_err(|e| Unavailable(format!("internal error: {e}")))
}

/// Every request: its `Host`, the method, then the path, decided here; every answer with
/// `nosniff` and, unless it says otherwise, `no-store`.
async fn dispatch(s: &Arc<Served>, req: &request::Parts) -> Response {
    let mut r = route(s, req).await;
    let h = r.headers_mut();
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.entry(header::CACHE_CONTROL)
        .or_insert(HeaderValue::from_static("no-store"));
    r
}

async fn route(s: &Arc<Served>, req: &request::Parts) -> Response {
    let (method, uri) = (&req.method, &req.uri);
    let mut hosts = req.headers.get_all(header::HOST).iter();
    let host = hosts.next();
    if hosts.next().is_some() {
        return text(StatusCode::BAD_REQUEST, "more than one Host header\n");
    }
    if host.is_none() && req.version == Version::HTTP_11 {
        return text(
            StatusCode::BAD_REQUEST,
            "an HTTP/1.1 request needs a Host header\n",
        );
    }
    if method != Method::GET && method != Method::HEAD {
        let mut r = text(
            StatusCode::METHOD_NOT_ALLOWED,
            "granular serve is read-only: GET and HEAD only\n",
        );
        r.headers_mut()
            .insert(header::ALLOW, HeaderValue::from_static("GET, HEAD"));
        return r;
    }
    // An absolute request target's authority overrides Host: both must name this machine.
    if s.loopback
        && !(local_host(host) && uri.authority().is_none_or(|a| local_host_name(a.as_str())))
    {
        return text(
            StatusCode::FORBIDDEN,
            "the Host header must name this machine (localhost or an IP address)\n",
        );
    }
    let head = method == Method::HEAD;
    match uri.path() {
        "/" | "/index.html" => match blocking(s, |s| s.page()).await.and_then(|r| r) {
            Ok(page) => html(dashboard(&page)),
            Err(e) => unavailable(&e),
        },
        "/api/status" => match blocking(s, |s| {
            *s.watched.lock().unwrap_or_else(|e| e.into_inner()) = Some(Instant::now());
            s.status_json(true)
        })
        .await
        .and_then(|r| r)
        {
            Ok(j) => json(j.as_str().to_owned()),
            Err(e) => unavailable(&e),
        },
        "/report.html" => match blocking(s, |s| s.page()).await.and_then(|r| r) {
            Ok(page) => {
                let mut r = html(page.as_str().to_owned());
                r.headers_mut().insert(
                    header::CONTENT_DISPOSITION,
                    HeaderValue::from_static("attachment; filename=\"report.html\""),
                );
                r
            }
            Err(e) => unavailable(&e),
        },
        "/tables" => {
            let mut r = text(StatusCode::MOVED_PERMANENTLY, "/tables/\n");
            r.headers_mut()
                .insert(header::LOCATION, HeaderValue::from_static("/tables/"));
            r
        }
        "/tables/" => match blocking(s, |s| list_tables(&s.root)).await {
            Ok(files) => html(tables_page(&files)),
            Err(e) => unavailable(&e),
        },
        "/api/tables" => match blocking(s, |s| list_tables(&s.root)).await {
            Ok(files) => json(tables_json(&files)),
            Err(e) => unavailable(&e),
        },
        p => match p.strip_prefix("/tables/") {
            Some(rest) => table_file(s, rest.to_owned(), head).await,
            None => text(StatusCode::NOT_FOUND, "not found\n"),
        },
    }
}

/// Whether a Host header names this machine: `localhost` or an IP literal, any port.
fn local_host(h: Option<&HeaderValue>) -> bool {
    match h {
        // HTTP/1.0 without Host: no browser sends that.
        None => true,
        Some(h) => h.to_str().is_ok_and(local_host_name),
    }
}

/// Whether `host[:port]` is `localhost` or an IP literal.
fn local_host_name(h: &str) -> bool {
    let host = if let Some(v6) = h.strip_prefix('[') {
        return v6
            .split(']')
            .next()
            .is_some_and(|a| a.parse::<std::net::Ipv6Addr>().is_ok());
    } else {
        h.rsplit_once(':').map_or(h, |(a, _)| a)
    };
    host.eq_ignore_ascii_case("localhost") || host.parse::<std::net::Ipv4Addr>().is_ok()
}

fn response(code: StatusCode, ctype: &'static str, body: impl Into<Body>) -> Response {
    let mut r = Response::new(body.into());
    *r.status_mut() = code;
    r.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(ctype));
    r
}

fn text(code: StatusCode, body: impl Into<String>) -> Response {
    response(code, "text/plain; charset=utf-8", body.into())
}

fn html(body: String) -> Response {
    let mut r = response(StatusCode::OK, "text/html; charset=utf-8", body);
    // The page may run its own inline script and fetch from this server, nothing else.
    r.headers_mut().insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; \
             img-src data:; connect-src 'self'; base-uri 'none'; form-action 'none'",
        ),
    );
    r
}

fn json(body: String) -> Response {
    response(StatusCode::OK, "application/json", body)
}

fn unavailable(e: &Unavailable) -> Response {
    text(StatusCode::SERVICE_UNAVAILABLE, format!("error: {e}\n"))
}

/// The live part of the dashboard: a status line, and the script that keeps the page current.
const LIVE: &str = r##"<style>
#live{position:fixed;top:.5em;right:.5em;padding:.2em .6em;border-radius:4px;font-size:85%;background:#eee;border:1px solid #ccc}
#live.ok{background:#e6f4e6;border-color:#2ca02c}#live.down{background:#fde8e8;border-color:#d62728;color:#900}
</style>
<div id="live" class="wait" role="status">live: connecting…</div>
<script>
(function () {
  "use strict";
  var EVERY = 2000, RELOAD_EVERY = 10000, SECTIONS = ["sec-headline", "sec-campaign", "sec-progress", "sec-targets", "sec-shards", "sec-failures", "sec-figures", "sec-analysis", "sec-manifest"];
  var live = document.getElementById("live"), shown = null, downSince = null, busy = false;
  var dirty = false, reloaded = 0;
  function time(d) { return d.toLocaleTimeString(); }
  function counts(n, k) {
    var s = n + ": " + k.done + " done, " + k.failed + " failed, " + k.running + " running, " +
      k.pending + " pending (" + k.checkpointed + " with checkpoints)";
    if (k.dropped > 0) { s += ", " + k.dropped + " dropped"; }
    return s;
  }
  function bar(k) {
    var n = k.done + k.failed + k.running + k.pending + k.dropped, d = document.createElement("div");
    if (n === 0) { return null; }
    d.className = "bar";
    ["done", "failed", "running", "pending", "dropped"].forEach(function (c) {
      if (k[c] > 0) {
        var s = document.createElement("span");
        s.className = c; s.style.width = (100 * k[c] / n).toFixed(2) + "%"; s.title = k[c] + " " + c;
        d.appendChild(s);
      }
    });
    return d;
  }
  function setText(id, t) { var e = document.getElementById(id); if (e) { e.textContent = t; } }
  // What, when it changes, asks for the whole page again (new figures, failures, shards).
  function pageKey(s) {
    return JSON.stringify([s.runs, s.done, s.failed, s.current_runs, s.manifests, s.points.length,
      s.live_shards, s.damage || [], s.slurm || [], s.targets ? [s.targets.rounds, s.targets.verdict] : null]);
  }
  function update(s) {
    var k = s.current, over = k.done + k.failed >= s.current_runs;
    ["done", "failed", "running", "pending"].forEach(function (c) { setText("hl-" + c, k[c]); });
    setText("hl-runs", s.current_runs);
    if (!(s.damage && s.damage.length)) {
      setText("hl-state", over ? "complete" : (k.running > 0 || s.live_shards.length > 0) ? "running" : "stopped, unfinished");
    }
    setText("progress-counts", counts(s.runs, s));
    setText("campaign-runs", counts(s.runs, s));
    setText("campaign-current", counts(s.current_runs, s.current));
    s.points.forEach(function (p) {
      var row = document.querySelector('tr[data-point="' + p.point_id + '"]');
      if (!row || row.cells.length < 9) { return; }
      var b = bar(p), cell = row.cells[2];
      while (cell.firstChild) { cell.removeChild(cell.firstChild); }
      if (b) { cell.appendChild(b); }
      ["done", "failed", "running", "pending", "dropped", "checkpointed"].forEach(function (c, i) {
        row.cells[3 + i].textContent = p[c];
      });
    });
  }
  function reloadSections() {
    reloaded = Date.now();
    return fetch("/", {cache: "no-store"}).then(function (r) {
      if (!r.ok) { throw new Error("HTTP " + r.status); }
      return r.text();
    }).then(function (t) {
      var doc = new DOMParser().parseFromString(t, "text/html");
      SECTIONS.forEach(function (id) {
        var a = document.getElementById(id), b = doc.getElementById(id);
        if (a && b && a.innerHTML !== b.innerHTML) { a.innerHTML = b.innerHTML; }
      });
    }).catch(function () { dirty = true; });
  }
  function poll() {
    if (busy) { return; }
    busy = true;
    fetch("/api/status", {cache: "no-store"}).then(function (r) {
      if (!r.ok) { return r.text().then(function (t) { throw new Error(t || ("HTTP " + r.status)); }); }
      return r.json();
    }).then(function (s) {
      // The page again when it changed: at once when every run has finished (the figures),
      // else at most every RELOAD_EVERY (a campaign committing every run at once).
      var key = pageKey(s), wait = null, over = s.current.done + s.current.failed >= s.current_runs;
      if (shown !== null && key !== shown) { dirty = true; }
      shown = key;
      if (dirty && (over || Date.now() - reloaded >= RELOAD_EVERY)) { dirty = false; wait = reloadSections(); }
      return Promise.resolve(wait).then(function () {
        update(s);
        downSince = null;
        live.className = "ok";
        live.textContent = "live: " + s.done + " of " + s.runs + " runs done, " + s.running +
          " running; updated " + time(new Date());
      });
    }).catch(function (e) {
      if (downSince === null) { downSince = new Date(); }
      live.className = "down";
      live.textContent = "server unreachable since " + time(downSince) + " (retrying): " + e.message;
    }).then(function () { busy = false; });
  }
  poll();
  setInterval(poll, EVERY);
})();
</script>
"##;

/// The report page with the live part before `</body>`.
fn dashboard(page: &str) -> String {
    match page.rfind("</body>") {
        Some(i) => format!("{}{LIVE}{}", &page[..i], &page[i..]),
        None => format!("{page}{LIVE}"),
    }
}

/// One table file that may be served.
#[derive(Debug, Clone, PartialEq)]
pub struct TableFile {
    pub table: String,
    pub file: String,
    pub bytes: u64,
}

/// Why a table path is refused.
#[derive(Debug, PartialEq)]
pub enum Refused {
    /// A malformed or forbidden path (400).
    BadPath(&'static str),
    /// No such servable file (404): missing, not a regular file, a symbolic link, or reached
    /// through one that is not a table's generation link.
    NotFound,
}

/// Percent-decode one path segment; `None` for a malformed escape.
fn percent_decode(s: &str) -> Option<Vec<u8>> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    Some(out)
}

/// Why a (decoded) name may not be a table's or a table file's.
fn segment_refused(seg: &str) -> Option<&'static str> {
    if seg.is_empty() {
        return Some("an empty path segment");
    }
    if seg.starts_with('.') {
        return Some("a hidden, `.` or `..` path segment");
    }
    if seg.contains(['/', '\\', '\0']) || seg.chars().any(char::is_control) {
        return Some("an encoded separator or control character");
    }
    None
}

/// The decoded segments of a raw request path under `/tables/` (`table/file`).
pub fn table_segments(raw: &str) -> Result<Vec<String>, Refused> {
    if raw.contains('\\') || raw.contains('\0') {
        return Err(Refused::BadPath("backslash or NUL in the path"));
    }
    let mut out = Vec::new();
    for seg in raw.split('/') {
        let bytes = percent_decode(seg).ok_or(Refused::BadPath("malformed percent-encoding"))?;
        let seg = String::from_utf8(bytes).map_err(|_| Refused::BadPath("not UTF-8"))?;
        if let Some(why) = segment_refused(&seg) {
            return Err(Refused::BadPath(why));
        }
        out.push(seg);
    }
    if out.len() < 2 {
        return Err(Refused::BadPath("expected /tables/<table>/<file>"));
    }
    Ok(out)
}

/// Opening without following links: `openat(2)` relative to a directory descriptor, one
/// name (no `/`) at a time.
mod nofollow {
    use super::*;

    fn cstr(name: &str) -> io::Result<CString> {
        if name.contains('/') {
            return Err(io::Error::from(io::ErrorKind::InvalidInput));
        }
        CString::new(name).map_err(|_| io::Error::from(io::ErrorKind::InvalidInput))
    }

    fn owned(fd: libc::c_int) -> io::Result<OwnedFd> {
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: a descriptor just returned by the kernel, owned by no one else.
        Ok(unsafe { OwnedFd::from_raw_fd(fd) })
    }

    /// The directory `root` (following a link: it is the one the user named).
    pub fn open_root(root: &Path) -> io::Result<OwnedFd> {
        use std::os::unix::fs::OpenOptionsExt;
        let f = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_DIRECTORY)
            .open(root)?;
        Ok(OwnedFd::from(f))
    }

    /// The directory `name` in `dir`; a link there fails (`ELOOP` or `ENOTDIR`).
    pub fn open_dir(dir: &OwnedFd, name: &str) -> io::Result<OwnedFd> {
        let c = cstr(name)?;
        // SAFETY: a valid descriptor and C string.
        owned(unsafe {
            libc::openat(
                dir.as_raw_fd(),
                c.as_ptr(),
                libc::O_RDONLY | libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC,
            )
        })
    }

    /// The regular file `name` in `dir` and its length; a link, a FIFO (opened without
    /// waiting for a writer), a device or a directory fails.
    pub fn open_file(dir: &OwnedFd, name: &str) -> io::Result<(std::fs::File, u64)> {
        let c = cstr(name)?;
        // SAFETY: a valid descriptor and C string.
        let fd = owned(unsafe {
            libc::openat(
                dir.as_raw_fd(),
                c.as_ptr(),
                libc::O_RDONLY
                    | libc::O_NOFOLLOW
                    | libc::O_NONBLOCK
                    | libc::O_NOCTTY
                    | libc::O_CLOEXEC,
            )
        })?;
        // O_NONBLOCK does not change how a regular file is read.
        let f = std::fs::File::from(fd);
        let m = f.metadata()?;
        if !m.is_file() {
            return Err(io::Error::from(io::ErrorKind::NotFound));
        }
        Ok((f, m.len()))
    }

    /// The target of the link `name` in `dir`.
    pub fn read_link(dir: &OwnedFd, name: &str) -> io::Result<Vec<u8>> {
        let c = cstr(name)?;
        let mut buf = vec![0u8; 4096];
        // SAFETY: a valid descriptor, C string and buffer of that length.
        let n = unsafe {
            libc::readlinkat(
                dir.as_raw_fd(),
                c.as_ptr(),
                buf.as_mut_ptr().cast(),
                buf.len(),
            )
        };
        if n < 0 {
            return Err(io::Error::last_os_error());
        }
        buf.truncate(n as usize);
        Ok(buf)
    }

    /// The length of `name` in `dir` if it is a regular file (not following a link).
    pub fn regular_len(dir: &OwnedFd, name: &str) -> Option<u64> {
        let c = cstr(name).ok()?;
        let mut st = std::mem::MaybeUninit::<libc::stat>::uninit();
        // SAFETY: a valid descriptor, C string and stat buffer.
        let rc = unsafe {
            libc::fstatat(
                dir.as_raw_fd(),
                c.as_ptr(),
                st.as_mut_ptr(),
                libc::AT_SYMLINK_NOFOLLOW,
            )
        };
        if rc != 0 {
            return None;
        }
        // SAFETY: filled by fstatat.
        let st = unsafe { st.assume_init() };
        (st.st_mode & libc::S_IFMT == libc::S_IFREG).then(|| st.st_size as u64)
    }

    /// The names in `dir` (UTF-8 ones, sorted; `.` and `..` left out).
    pub fn names(dir: &OwnedFd) -> io::Result<Vec<String>> {
        // fdopendir takes its descriptor over (closedir closes it): give it a duplicate.
        let fd = dir.try_clone()?.into_raw_fd();
        // SAFETY: `fd` is an open directory descriptor that the stream now owns.
        let d = unsafe { libc::fdopendir(fd) };
        if d.is_null() {
            let e = io::Error::last_os_error();
            // SAFETY: not taken over by a stream.
            unsafe { libc::close(fd) };
            return Err(e);
        }
        let mut out = Vec::new();
        // SAFETY: `d` is a valid stream until closedir; each entry is read before the next
        // readdir call.
        unsafe {
            // A duplicate shares the offset of its original: from the start.
            libc::rewinddir(d);
            loop {
                let e = libc::readdir(d);
                if e.is_null() {
                    break;
                }
                let name = CStr::from_ptr((*e).d_name.as_ptr());
                if let Ok(n) = name.to_str() {
                    if n != "." && n != ".." {
                        out.push(n.to_string());
                    }
                }
            }
            libc::closedir(d);
        }
        out.sort();
        Ok(out)
    }
}

/// `<table>.<n>` if `target` is `.gen/<table>.<n>`: the form of the only links granular
/// writes (`store::layout`).
pub fn generation_of(table: &str, target: &[u8]) -> Option<String> {
    let target = std::str::from_utf8(target).ok()?;
    let (dir, name) = target.split_once('/')?;
    let n = name.strip_prefix(table)?.strip_prefix('.')?;
    (dir == GEN_DIR && !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        .then(|| name.to_string())
}

/// `root/tables`, a directory (not a link).
fn open_tables(root: &Path) -> io::Result<OwnedFd> {
    nofollow::open_dir(&nofollow::open_root(root)?, "tables")
}

/// The directory of `table` under `tables`: a plain directory, or the generation its link
/// names (`.gen/<table>.<n>`), opened as such under `tables` (so a link swapped in since it
/// was read leads nowhere else).
fn open_table_dir(tables: &OwnedFd, table: &str) -> io::Result<OwnedFd> {
    match nofollow::open_dir(tables, table) {
        Err(e) if matches!(e.raw_os_error(), Some(libc::ELOOP | libc::ENOTDIR)) => {
            let target = nofollow::read_link(tables, table)?;
            let gen = generation_of(table, &target)
                .ok_or_else(|| io::Error::from(io::ErrorKind::NotFound))?;
            nofollow::open_dir(&nofollow::open_dir(tables, GEN_DIR)?, &gen)
        }
        r => r,
    }
}

/// Open the regular file `root/tables/<table>/<file>`, following no link but the table's
/// generation link (see the module's documentation).
pub fn open_table_file(root: &Path, segments: &[String]) -> Result<(std::fs::File, u64), Refused> {
    let [table, file] = segments else {
        return Err(Refused::NotFound);
    };
    if segment_refused(table).is_some() || segment_refused(file).is_some() {
        return Err(Refused::NotFound);
    }
    let tables = open_tables(root).map_err(|_| Refused::NotFound)?;
    let dir = open_table_dir(&tables, table).map_err(|_| Refused::NotFound)?;
    nofollow::open_file(&dir, file).map_err(|_| Refused::NotFound)
}

/// Every servable table file: `tables/<table>/<file>`, hidden names skipped, found as a
/// download would open it.
pub fn list_tables(root: &Path) -> Vec<TableFile> {
    let Ok(tables) = open_tables(root) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for t in nofollow::names(&tables).unwrap_or_default() {
        if segment_refused(&t).is_some() {
            continue;
        }
        let Ok(dir) = open_table_dir(&tables, &t) else {
            continue;
        };
        for f in nofollow::names(&dir).unwrap_or_default() {
            if segment_refused(&f).is_some() {
                continue;
            }
            if let Some(bytes) = nofollow::regular_len(&dir, &f) {
                out.push(TableFile {
                    table: t.clone(),
                    file: f,
                    bytes,
                });
            }
        }
    }
    out
}

/// What the report and the status read of the campaign directory, below this depth.
const WALK_DEPTH: usize = 3;
/// The entries of the campaign directory that the report and the status read (besides
/// `tables`); `checkpoints` and `finals` only by name.
const READ_ENTRIES: [&str; 8] = [
    "campaign.json",
    "manifest.json",
    "manifests",
    "ledger",
    "locks",
    "sums",
    "slurm",
    "analysis",
];

/// Every symbolic link (and FIFO, socket or device) where the report and the status of `root`
/// read granular's own files and directories, but the generation links `tables/<t>` ->
/// `.gen/<t>.<n>`; hidden names (files being written) are not read and not looked at. As
/// `PATH: what` (PATH as the readers reach it: `tables/<t>/<file>`), sorted.
pub fn links_out(root: &Path) -> Vec<String> {
    fn walk(real: &Path, shown: &Path, depth: usize, out: &mut Vec<String>) {
        let Ok(m) = std::fs::symlink_metadata(real) else {
            return;
        };
        let t = m.file_type();
        if t.is_symlink() {
            out.push(format!("{}: a symbolic link", shown.display()));
        } else if t.is_dir() {
            if depth < WALK_DEPTH {
                for n in visible_names(real) {
                    walk(&real.join(&n), &shown.join(&n), depth + 1, out);
                }
            }
        } else if !t.is_file() {
            out.push(format!(
                "{}: not a regular file (a FIFO, socket or device)",
                shown.display()
            ));
        }
    }
    fn visible_names(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .map(|it| {
                it.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| !n.starts_with('.'))
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }
    let mut out = Vec::new();
    for name in READ_ENTRIES {
        walk(&root.join(name), &root.join(name), 0, &mut out);
    }
    let tables = root.join("tables");
    match std::fs::symlink_metadata(&tables) {
        Ok(m) if m.is_dir() => {
            let gens = tables.join(GEN_DIR);
            for t in visible_names(&tables) {
                let p = tables.join(&t);
                let Ok(m) = std::fs::symlink_metadata(&p) else {
                    continue;
                };
                if !m.file_type().is_symlink() {
                    walk(&p, &p, 1, &mut out);
                    continue;
                }
                let gen = std::fs::read_link(&p)
                    .ok()
                    .and_then(|l| generation_of(&t, l.as_os_str().as_encoded_bytes()));
                let Some(gen) = gen else {
                    out.push(format!("{}: a symbolic link", p.display()));
                    continue;
                };
                match std::fs::symlink_metadata(&gens) {
                    Ok(g) if g.file_type().is_symlink() => {
                        out.push(format!("{}: a symbolic link", gens.display()));
                    }
                    Ok(g) if g.is_dir() => {
                        let dir = gens.join(&gen);
                        if std::fs::symlink_metadata(&dir).is_ok_and(|m| m.file_type().is_symlink())
                        {
                            out.push(format!("{}: a symbolic link", dir.display()));
                        } else {
                            walk(&dir, &p, 1, &mut out);
                        }
                    }
                    _ => {}
                }
            }
        }
        _ => walk(&tables, &tables, WALK_DEPTH, &mut out),
    }
    out.sort();
    out.dedup();
    out
}

/// The refusal of the page and the status while [`links_out`] finds something.
fn links_refusal(links: &[String]) -> String {
    const SHOWN: usize = 20;
    let mut s = format!(
        "granular serve reads no campaign file through a symbolic link (granular writes none \
         but tables/<table> -> .gen/<table>.<n>), so it shows no page or status while the \
         campaign directory has one: {}",
        links[..links.len().min(SHOWN)].join("; ")
    );
    if links.len() > SHOWN {
        s.push_str(&format!("; and {} more", links.len() - SHOWN));
    }
    s
}

/// A path segment percent-encoded for a link.
fn encode(s: &str) -> String {
    let mut out = String::new();
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

fn tables_page(files: &[TableFile]) -> String {
    use std::fmt::Write as _;
    let mut h = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>tables</title>\n\
         <style>body{font-family:sans-serif;margin:2em auto;max-width:1000px}\
         td,th{padding:.1em .6em;text-align:left}td.n{text-align:right}</style>\n</head>\n<body>\n\
         <p><a href=\"/\">dashboard</a> · <a href=\"/api/tables\">JSON</a></p>\n<h1>Tables</h1>\n",
    );
    if files.is_empty() {
        h.push_str("<p>No table files yet.</p>\n");
    } else {
        h.push_str("<table>\n<tr><th>table</th><th>file</th><th>bytes</th></tr>\n");
        for f in files {
            let _ = writeln!(
                h,
                "<tr><td>{t}</td><td><a href=\"/tables/{}/{}\">{f}</a></td><td class=\"n\">{}</td></tr>",
                encode(&f.table),
                encode(&f.file),
                f.bytes,
                t = report::escape(&f.table),
                f = report::escape(&f.file),
            );
        }
        h.push_str("</table>\n");
    }
    h.push_str("</body>\n</html>\n");
    h
}

fn tables_json(files: &[TableFile]) -> String {
    let v: Vec<serde_json::Value> = files
        .iter()
        .map(|f| serde_json::json!({"table": f.table, "file": f.file, "bytes": f.bytes}))
        .collect();
    serde_json::to_string_pretty(&v).expect("json")
}

fn content_type(file: &str) -> &'static str {
    match file.rsplit_once('.').map(|(_, e)| e) {
        Some("parquet") => "application/vnd.apache.parquet",
        Some("json") => "application/json",
        _ => "application/octet-stream",
    }
}

/// A table file, streamed in 64 KiB chunks (HEAD: its headers only).
async fn table_file(s: &Arc<Served>, raw: String, head: bool) -> Response {
    let segments = match table_segments(&raw) {
        Ok(v) => v,
        Err(Refused::BadPath(why)) => return text(StatusCode::BAD_REQUEST, format!("{why}\n")),
        Err(Refused::NotFound) => return text(StatusCode::NOT_FOUND, "not found\n"),
    };
    let name = segments.last().cloned().unwrap_or_default();
    let opened = blocking(s, move |s| open_table_file(&s.root, &segments)).await;
    let (file, len) = match opened {
        Ok(Ok(x)) => x,
        Ok(Err(Refused::BadPath(why))) => return text(StatusCode::BAD_REQUEST, format!("{why}\n")),
        Ok(Err(Refused::NotFound)) => return text(StatusCode::NOT_FOUND, "not found\n"),
        Err(e) => return unavailable(&e),
    };
    let body = if head {
        Body::empty()
    } else {
        // Each chunk read on a blocking thread (as tokio::fs does).
        let stream = futures_util::stream::unfold(Some(file), |f| async move {
            let mut f = f?;
            let read = tokio::task::spawn_blocking(move || {
                use std::io::Read;
                let mut buf = vec![0u8; 64 * 1024];
                let n = f.read(&mut buf);
                (f, buf, n)
            })
            .await;
            match read {
                Ok((_, _, Ok(0))) => None,
                Ok((f, mut buf, Ok(n))) => {
                    buf.truncate(n);
                    Some((Ok(Bytes::from(buf)), Some(f)))
                }
                Ok((_, _, Err(e))) => Some((Err::<Bytes, io::Error>(e), None)),
                Err(e) => Some((Err(io::Error::other(e)), None)),
            }
        });
        Body::from_stream(stream)
    };
    let mut r = response(StatusCode::OK, content_type(&name), body);
    let h = r.headers_mut();
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    // The name is a checked segment; quotes and non-ASCII are left out of the header.
    let safe: String = name
        .chars()
        .filter(|c| c.is_ascii_graphic() && *c != '"' && *c != '\\')
        .collect();
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{safe}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures_util::FutureExt;

    /// Every `<section id="sec-...">` the report writes is one the live script swaps.
    #[test]
    fn live_script_swaps_every_report_section() {
        let report = include_str!("report.rs");
        let mut ids = Vec::new();
        for (i, _) in report.match_indices("<section id=\\\"sec-") {
            let rest = &report[i + "<section id=\\\"".len()..];
            ids.push(&rest[..rest.find('\\').unwrap()]);
        }
        assert!(ids.contains(&"sec-targets"), "{ids:?}");
        assert!(ids.len() >= 9, "{ids:?}");
        for id in ids {
            assert!(
                LIVE.contains(&format!("\"{id}\"")),
                "{id} not swapped by the live page"
            );
        }
    }

    #[test]
    fn traversal_segments_refused() {
        for raw in [
            "../campaign.json",
            "%2e%2e/campaign.json",
            "%2E%2E/campaign.json",
            "runs/%2e%2e%2f%2e%2e%2fcampaign.json",
            "..%2fcampaign.json",
            "runs/..",
            "runs/.",
            "runs//x",
            "/etc/passwd",
            "runs/..\\..\\campaign.json",
            "runs%5c..%5ccampaign.json",
            "runs/x%00",
            "runs/x\0",
            "runs/%zz",
            "runs/%2",
            ".gen/runs.1/part.parquet",
            "runs/.part-s1of1-1.parquet.pending",
            "runs",
            "",
            "runs/%ff",
        ] {
            assert!(
                matches!(table_segments(raw), Err(Refused::BadPath(_))),
                "{raw:?} accepted"
            );
        }
        assert_eq!(
            table_segments("runs/part-s1of1-000001.parquet").unwrap(),
            vec!["runs", "part-s1of1-000001.parquet"]
        );
        assert_eq!(
            table_segments("dsmc%5Fspecies/a%20b.parquet").unwrap(),
            vec!["dsmc_species", "a b.parquet"]
        );
    }

    #[test]
    fn symlinks_out_of_tables_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("c");
        let gen = root.join("tables/.gen/runs.1");
        std::fs::create_dir_all(&gen).unwrap();
        std::os::unix::fs::symlink(".gen/runs.1", root.join("tables/runs")).unwrap();
        std::fs::write(gen.join("part.parquet"), b"PAR1").unwrap();
        std::fs::write(root.join("campaign.json"), b"{}").unwrap();
        std::fs::create_dir_all(tmp.path().join("outside")).unwrap();
        std::fs::write(tmp.path().join("outside/secret"), b"secret").unwrap();
        std::os::unix::fs::symlink("../../../campaign.json", gen.join("up.parquet")).unwrap();
        std::os::unix::fs::symlink(tmp.path().join("outside"), root.join("tables/out")).unwrap();
        std::os::unix::fs::symlink(tmp.path().join("outside/secret"), gen.join("s")).unwrap();
        std::fs::create_dir_all(gen.join("sub")).unwrap();
        let segs = |a: &str, b: &str| vec![a.to_string(), b.to_string()];
        let (_, n) = open_table_file(&root, &segs("runs", "part.parquet")).unwrap();
        assert_eq!(n, 4);
        for (a, b) in [
            ("runs", "up.parquet"),
            ("out", "secret"),
            ("runs", "s"),
            ("runs", "sub"),
            ("runs", "missing"),
        ] {
            assert_eq!(
                open_table_file(&root, &segs(a, b)).unwrap_err(),
                Refused::NotFound,
                "{a}/{b}"
            );
        }
        let listed = list_tables(&root);
        assert_eq!(
            listed,
            vec![TableFile {
                table: "runs".into(),
                file: "part.parquet".into(),
                bytes: 4
            }]
        );
    }

    #[test]
    fn host_header_must_be_local() {
        let h = |s: &'static str| Some(HeaderValue::from_static(s));
        for ok in [
            "localhost:8080",
            "LOCALHOST",
            "127.0.0.1:9000",
            "[::1]:8080",
            "[::1]",
            "10.0.0.7:80",
        ] {
            assert!(local_host(h(ok).as_ref()), "{ok}");
        }
        for bad in [
            "evil.example:8080",
            "evil.example",
            "localhost.evil:80",
            "[x]:1",
        ] {
            assert!(!local_host(h(bad).as_ref()), "{bad}");
        }
        assert!(local_host(None));
    }

    #[test]
    fn only_generation_links_of_the_table_are_followed() {
        assert_eq!(
            generation_of("runs", b".gen/runs.00000003").as_deref(),
            Some("runs.00000003")
        );
        for bad in [
            &b".gen/points.00000003"[..],
            b".gen/runs.",
            b".gen/runs.3/x",
            b".gen/runs.3x",
            b"../.gen/runs.3",
            b"/c/tables/.gen/runs.3",
            b".gen/../runs.3",
            b"gen/runs.3",
            b".gen/runs",
            b"runs.3",
        ] {
            assert_eq!(
                generation_of("runs", bad),
                None,
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
    }

    #[test]
    fn plain_table_directories_are_served() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
        std::fs::create_dir_all(root.join("tables/points")).unwrap();
        std::fs::write(root.join("tables/points/points.parquet"), b"PAR1PAR1").unwrap();
        std::fs::write(root.join("tables/points/.points.parquet.1.tmp"), b"x").unwrap();
        let segs = vec!["points".to_string(), "points.parquet".to_string()];
        assert_eq!(open_table_file(root, &segs).unwrap().1, 8);
        assert_eq!(list_tables(root).len(), 1);
        assert!(links_out(root).is_empty(), "{:?}", links_out(root));
    }

    #[test]
    fn links_out_of_the_campaign_are_found() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("c");
        let gen = root.join("tables/.gen/runs.00000001");
        std::fs::create_dir_all(&gen).unwrap();
        std::fs::create_dir_all(root.join("ledger/s1of1")).unwrap();
        std::fs::create_dir_all(root.join("analysis/figures")).unwrap();
        std::fs::write(root.join("campaign.json"), b"{}").unwrap();
        std::os::unix::fs::symlink(".gen/runs.00000001", root.join("tables/runs")).unwrap();
        std::fs::write(gen.join("part.parquet"), b"PAR1").unwrap();
        // Being written (hidden): not read, not looked at.
        std::os::unix::fs::symlink(".gen/runs.00000002", root.join("tables/.runs.7.tmp")).unwrap();
        assert_eq!(links_out(&root), Vec::<String>::new());
        let outside = tmp.path().join("outside");
        std::fs::create_dir_all(&outside).unwrap();
        std::os::unix::fs::symlink(&outside, gen.join("x.parquet")).unwrap();
        std::os::unix::fs::symlink(&outside, root.join("ledger/s1of1/commit-1.json")).unwrap();
        std::os::unix::fs::symlink(&outside, root.join("analysis/figures/f.svg")).unwrap();
        std::os::unix::fs::symlink(".gen/runs.00000001", root.join("tables/other")).unwrap();
        let c = std::ffi::CString::new(root.join("analysis/a.parquet").to_str().unwrap()).unwrap();
        // SAFETY: a valid path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let r = root.display();
        assert_eq!(
            links_out(&root),
            vec![
                format!("{r}/analysis/a.parquet: not a regular file (a FIFO, socket or device)"),
                format!("{r}/analysis/figures/f.svg: a symbolic link"),
                format!("{r}/ledger/s1of1/commit-1.json: a symbolic link"),
                format!("{r}/tables/other: a symbolic link"),
                format!("{r}/tables/runs/x.parquet: a symbolic link"),
            ]
        );
        // `tables` itself a link: that is all that is said of it.
        std::fs::rename(root.join("tables"), tmp.path().join("t")).unwrap();
        std::os::unix::fs::symlink(tmp.path().join("t"), root.join("tables")).unwrap();
        assert!(links_out(&root).contains(&format!("{r}/tables: a symbolic link")));
        assert!(list_tables(&root).is_empty());
    }

    #[test]
    fn the_connection_cap_follows_the_limit_of_open_files() {
        assert_eq!(connection_cap(None), MAX_CONNECTIONS);
        assert_eq!(connection_cap(Some(1 << 20)), MAX_CONNECTIONS);
        assert_eq!(connection_cap(Some(64)), 16);
        assert_eq!(connection_cap(Some(1024)), 496.min(MAX_CONNECTIONS));
        assert_eq!(connection_cap(Some(10)), MIN_CONNECTIONS);
    }

    #[test]
    fn a_full_server_closes_the_connection_idle_longest() {
        let conns = Conns::new(2);
        let admit = || conns.admit(conns.slot().now_or_never().unwrap().unwrap());
        let a = admit();
        let b = admit();
        a.last.store(5, Ordering::Relaxed);
        b.last.store(1, Ordering::Relaxed);
        // b has waited longest: told to close, and its slot waited for until it has.
        let mut room = std::pin::pin!(conns.slot());
        assert!(room.as_mut().now_or_never().is_none());
        assert!(b.evict.notified().now_or_never().is_some());
        assert!(a.evict.notified().now_or_never().is_none());
        assert!(room.as_mut().now_or_never().is_none());
        drop(b);
        let c = conns.admit(room.now_or_never().unwrap().unwrap());
        // Both left computing an answer: no room is made, the new one is refused.
        let (_x, _y) = (Busy::enter(&a), Busy::enter(&c));
        assert!(conns.slot().now_or_never().unwrap().is_none());
        conns.leave(c.id);
        drop(_y);
        drop(c);
        assert!(conns.slot().now_or_never().unwrap().is_some());
    }

    #[test]
    fn live_part_goes_before_the_end_of_the_body() {
        let page = dashboard("<html><body><p>x</p></body>\n</html>\n");
        assert!(page.contains("<p>x</p><style>"));
        assert!(page.trim_end().ends_with("</script>\n</body>\n</html>"));
    }
}
