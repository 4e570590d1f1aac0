//! Durable file operations: every file becomes visible atomically (write to a temporary
//! name in the same directory, fsync, rename, fsync the directory).
//!
//! And the closed world of a campaign directory. [`Dir`] is a directory opened without
//! following a symbolic link (`openat` with `O_NOFOLLOW`, one name at a time): its entries are
//! listed with what each is (`lstat`: a link is reported, never followed), its files opened
//! with `O_NOFOLLOW` (regular files only), and entries created, removed and renamed relative to
//! the opened directory (`mkdirat`, `unlinkat`, `renameat`: they act on the entry itself, a
//! link included, never on what it points to). So a link put where granular keeps its own
//! file or directory, or one swapped in while granular works, is never followed out of the
//! campaign directory: the primitive refuses it with a [`NotOwn`] error naming it. The
//! campaign directory itself, as given on the command line, may be a link (the user's
//! choice): [`Dir::open`] follows it, once, at the top.

use std::ffi::{CStr, CString, OsString};
use std::fmt;
use std::fs::{self, File};
use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, FromRawFd, IntoRawFd, OwnedFd, RawFd};
use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// The temporary name used while `path` is being written: hidden (leading `.`) and ending in
/// `.tmp`, so dataset readers (DuckDB globs, pyarrow's ignore_prefixes) never pick it up.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(temp_name(&name))
}

/// The temporary name of the file `name` (see [`temp_path`]).
pub fn temp_name(name: &str) -> String {
    // pid, clock and host: unique among processes sharing a file system, and recognisable as
    // this host's when a crashed process's leftovers are cleaned up.
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!(".{name}.{}-{nanos}@{}.tmp", std::process::id(), host_tag())
}

/// This host's name, reduced to characters safe in a file name.
pub fn host_tag() -> String {
    let h = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .unwrap_or_else(|_| "unknown".into());
    h.trim()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// fsync a directory so that a rename inside it is durable. The empty path (the parent of a
/// bare file name such as `report.html`) is the current directory.
pub fn sync_dir(dir: &Path) -> std::io::Result<()> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    File::open(dir)?.sync_all()
}

/// Write `bytes` to `path` atomically and durably.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_parts(path, &[bytes])
}

/// [`write_atomic`] of the concatenation of `parts`, written one after the other.
pub fn write_atomic_parts(path: &Path, parts: &[&[u8]]) -> std::io::Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = File::create(&tmp)?;
        for p in parts {
            f.write_all(p)?;
        }
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        if let Some(dir) = path.parent() {
            sync_dir(dir)?;
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Create a directory (and parents), then fsync its parent so the entry is durable.
pub fn create_dir_durable(dir: &Path) -> std::io::Result<()> {
    if dir.is_dir() {
        return Ok(());
    }
    fs::create_dir_all(dir)?;
    if let Some(parent) = dir.parent() {
        let _ = sync_dir(parent);
    }
    Ok(())
}

/// What a directory entry is, seen without following a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    File,
    Dir,
    Link,
    /// A FIFO, socket or device.
    Other,
}

impl Kind {
    fn of_mode(mode: libc::mode_t) -> Kind {
        match mode & libc::S_IFMT {
            libc::S_IFREG => Kind::File,
            libc::S_IFDIR => Kind::Dir,
            libc::S_IFLNK => Kind::Link,
            _ => Kind::Other,
        }
    }

    fn of(meta: &fs::Metadata) -> Kind {
        let t = meta.file_type();
        if t.is_symlink() {
            Kind::Link
        } else if t.is_dir() {
            Kind::Dir
        } else if t.is_file() {
            Kind::File
        } else {
            Kind::Other
        }
    }
}

/// What is at `path`, without following a link there (`lstat`); `None` if nothing is.
pub fn kind(path: &Path) -> io::Result<Option<Kind>> {
    match fs::symlink_metadata(path) {
        Ok(m) => Ok(Some(Kind::of(&m))),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e),
    }
}

/// Something that is not granular's own where granular keeps its own file or directory: a
/// symbolic link (never followed), or an entry of the wrong kind (a file where a directory
/// belongs, say). Every primitive of this module that meets one refuses it with an
/// `io::Error` carrying this ([`not_own`] finds it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotOwn {
    /// The entry.
    pub path: PathBuf,
    /// What is there, for people: "a symbolic link to /data/x", "a regular file", ...
    pub found: String,
    /// What granular keeps there: "file", "directory", ...
    pub expected: &'static str,
}

impl NotOwn {
    /// "{found}, where granular keeps its own {expected} (not followed)".
    pub fn what(&self) -> String {
        format!(
            "{}, where granular keeps its own {} (not followed)",
            self.found, self.expected
        )
    }

    pub fn into_io(self) -> io::Error {
        io::Error::other(self)
    }
}

impl fmt::Display for NotOwn {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.what())
    }
}

impl std::error::Error for NotOwn {}

/// The [`NotOwn`] that `e` refuses, if it is such a refusal.
pub fn not_own(e: &io::Error) -> Option<&NotOwn> {
    e.get_ref()?.downcast_ref::<NotOwn>()
}

/// What the entry at `path` of kind `k` is, for people.
fn describe_path(path: &Path, k: Kind) -> String {
    match k {
        Kind::Link => match fs::read_link(path) {
            Ok(t) => format!("a symbolic link to {}", t.display()),
            Err(_) => "a symbolic link".into(),
        },
        other => describe_kind(other).into(),
    }
}

/// What an entry of kind `k` is, for people ("a regular file").
pub fn describe_kind(k: Kind) -> &'static str {
    match k {
        Kind::File => "a regular file",
        Kind::Dir => "a directory",
        Kind::Link => "a symbolic link",
        Kind::Other => "a special file (FIFO, socket or device)",
    }
}

/// Open the regular file at `path` for reading without following a link at its last name
/// (`O_NOFOLLOW`) and without blocking on a FIFO: anything but a regular file is refused
/// ([`NotOwn`]). The directories on the way are the caller's to trust; [`Dir`] trusts none.
pub fn open_regular(path: &Path) -> io::Result<File> {
    let f = fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path);
    let refuse = |k: Kind| {
        NotOwn {
            path: path.to_path_buf(),
            found: describe_path(path, k),
            expected: "file",
        }
        .into_io()
    };
    match f {
        Ok(f) => match Kind::of(&f.metadata()?) {
            Kind::File => Ok(f),
            k => Err(refuse(k)),
        },
        Err(e) => match kind(path) {
            Ok(Some(k)) if k != Kind::File => Err(refuse(k)),
            _ => Err(e),
        },
    }
}

/// The text of the regular file `name` in the directory `root` (followed: the directory the
/// user named), refusing a link or anything but a regular file there (an error that names
/// it and says what to do): how `campaign.json` is read.
pub fn read_inside(root: &Path, name: &str) -> io::Result<String> {
    let opened = Dir::open(root)?.open_file(name).map_err(|e| match not_own(&e) {
        Some(n) => io::Error::other(format!(
            "{n}; granular reads only its own files inside the campaign directory: put the file itself there in place of the {}",
            if n.found.starts_with("a symbolic link") { "link" } else { "entry" }
        )),
        None => e,
    })?;
    match opened {
        Some(mut f) => {
            let mut s = String::new();
            f.read_to_string(&mut s)?;
            Ok(s)
        }
        None => Err(io::Error::from_raw_os_error(libc::ENOENT)),
    }
}

/// A single name of a directory entry as a C string (no `/`, not `.` or `..`, no NUL).
fn cname(name: &str) -> io::Result<CString> {
    if name.is_empty() || name == "." || name == ".." || name.contains('/') {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{name:?} is not the name of a directory entry"),
        ));
    }
    CString::new(name).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{name:?} holds a NUL byte"),
        )
    })
}

fn cvt(r: libc::c_int) -> io::Result<()> {
    if r == -1 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

fn openat(dir: RawFd, name: &CStr, flags: libc::c_int, mode: libc::mode_t) -> io::Result<OwnedFd> {
    loop {
        // SAFETY: `name` is NUL-terminated; the descriptor returned is owned by nobody else.
        let fd = unsafe {
            libc::openat(
                dir,
                name.as_ptr(),
                flags | libc::O_CLOEXEC,
                mode as libc::c_uint,
            )
        };
        if fd >= 0 {
            // SAFETY: a fresh descriptor.
            return Ok(unsafe { OwnedFd::from_raw_fd(fd) });
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

/// `lstat` of `name` in `dir`; `None` if there is no such entry.
fn lstat_at(dir: RawFd, name: &CStr) -> io::Result<Option<libc::stat>> {
    let mut st = std::mem::MaybeUninit::<libc::stat>::uninit();
    // SAFETY: `name` is NUL-terminated and `st` is large enough for a `stat`.
    let r = unsafe {
        libc::fstatat(
            dir,
            name.as_ptr(),
            st.as_mut_ptr(),
            libc::AT_SYMLINK_NOFOLLOW,
        )
    };
    if r == 0 {
        // SAFETY: fstatat filled it.
        return Ok(Some(unsafe { st.assume_init() }));
    }
    let e = io::Error::last_os_error();
    if e.kind() == io::ErrorKind::NotFound {
        Ok(None)
    } else {
        Err(e)
    }
}

/// A directory of the campaign, opened without following a symbolic link (see the module's
/// text). Errors carry no path, except the [`NotOwn`] refusals, which name the entry.
#[derive(Debug)]
pub struct Dir {
    fd: OwnedFd,
    /// How it was reached, for messages and for the readers that take paths.
    path: PathBuf,
}

impl Dir {
    /// Open the directory at `path`, following links on the way: the campaign directory as
    /// the user named it (below it, use [`Dir::sub`]).
    pub fn open(path: &Path) -> io::Result<Dir> {
        let f = fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_DIRECTORY)
            .open(path)?;
        Ok(Dir {
            fd: f.into(),
            path: path.to_path_buf(),
        })
    }

    /// Open the directory at `path`, refusing a link (or anything but a directory) at its
    /// last name; the directories on the way are the caller's to trust.
    pub fn open_nofollow(path: &Path) -> io::Result<Dir> {
        let f = fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_DIRECTORY | libc::O_NOFOLLOW)
            .open(path);
        match f {
            Ok(f) => Ok(Dir {
                fd: f.into(),
                path: path.to_path_buf(),
            }),
            Err(e) => match kind(path) {
                Ok(Some(k)) if k != Kind::Dir => Err(NotOwn {
                    path: path.to_path_buf(),
                    found: describe_path(path, k),
                    expected: "directory",
                }
                .into_io()),
                _ => Err(e),
            },
        }
    }

    /// How this directory was reached.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The same directory, named `path` in messages (a table's generation directory named by
    /// the table's link, say).
    pub fn named(self, path: PathBuf) -> Dir {
        Dir { path, ..self }
    }

    pub fn try_clone(&self) -> io::Result<Dir> {
        Ok(Dir {
            fd: self.fd.try_clone()?,
            path: self.path.clone(),
        })
    }

    fn raw(&self) -> RawFd {
        self.fd.as_raw_fd()
    }

    /// What the entry `name` is (`None`: there is none); a link is reported, not followed.
    pub fn kind(&self, name: &str) -> io::Result<Option<Kind>> {
        let c = cname(name)?;
        Ok(lstat_at(self.raw(), &c)?.map(|st| Kind::of_mode(st.st_mode)))
    }

    /// What the entry `name` of kind `k` is, for people ("a symbolic link to /data/x").
    pub fn describe(&self, name: &str, k: Kind) -> String {
        match k {
            Kind::Link => match self.read_link(name) {
                Ok(t) => format!("a symbolic link to {}", t.display()),
                Err(_) => "a symbolic link".into(),
            },
            other => describe_kind(other).into(),
        }
    }

    /// The refusal of the entry `name` of kind `k` where granular keeps its own `expected`.
    pub fn not_own(&self, name: &str, k: Kind, expected: &'static str) -> io::Error {
        NotOwn {
            path: self.path.join(name),
            found: self.describe(name, k),
            expected,
        }
        .into_io()
    }

    /// After `e` opening `name`: a [`NotOwn`] refusal if the entry is not of kind `want`,
    /// `Ok(None)` if it is gone, else `e`.
    fn refuse<T>(
        &self,
        name: &str,
        want: Kind,
        expected: &'static str,
        e: io::Error,
    ) -> io::Result<Option<T>> {
        if e.kind() == io::ErrorKind::NotFound {
            return Ok(None);
        }
        match self.kind(name)? {
            None => Ok(None),
            Some(k) if k != want => Err(self.not_own(name, k, expected)),
            Some(_) => Err(e),
        }
    }

    /// The directory `name` inside this one, opened without following a link: `None` if
    /// there is none; a link or anything but a directory is refused ([`NotOwn`]).
    pub fn sub(&self, name: &str) -> io::Result<Option<Dir>> {
        let c = cname(name)?;
        match openat(
            self.raw(),
            &c,
            libc::O_RDONLY | libc::O_DIRECTORY | libc::O_NOFOLLOW,
            0,
        ) {
            Ok(fd) => Ok(Some(Dir {
                fd,
                path: self.path.join(name),
            })),
            Err(e) => self.refuse(name, Kind::Dir, "directory", e),
        }
    }

    /// The directory at `rel` (names separated by `/`; empty: this one), each name opened as
    /// by [`Dir::sub`]; `None` if one is missing.
    pub fn walk(&self, rel: &str) -> io::Result<Option<Dir>> {
        let mut cur = self.try_clone()?;
        for name in rel.split('/').filter(|n| !n.is_empty()) {
            match cur.sub(name)? {
                Some(d) => cur = d,
                None => return Ok(None),
            }
        }
        Ok(Some(cur))
    }

    /// The entries (without `.` and `..`) and what each is, sorted by name. A name that is
    /// not UTF-8 is given lossily.
    pub fn entries(&self) -> io::Result<Vec<(String, Kind)>> {
        // A descriptor of its own, so that listing twice starts from the beginning twice.
        let fd = openat(self.raw(), c".", libc::O_RDONLY | libc::O_DIRECTORY, 0)?;
        let raw = fd.into_raw_fd();
        // SAFETY: fdopendir takes `raw` over on success; on failure it is closed here.
        let dirp = unsafe { libc::fdopendir(raw) };
        if dirp.is_null() {
            let e = io::Error::last_os_error();
            // SAFETY: `raw` is still ours.
            unsafe { libc::close(raw) };
            return Err(e);
        }
        struct Stream(*mut libc::DIR);
        impl Drop for Stream {
            fn drop(&mut self) {
                // SAFETY: opened by fdopendir above, closed once.
                unsafe { libc::closedir(self.0) };
            }
        }
        let stream = Stream(dirp);
        let mut names: Vec<CString> = Vec::new();
        loop {
            // SAFETY: a valid stream; the entry is copied before the next call.
            let ent = unsafe { libc::readdir(stream.0) };
            if ent.is_null() {
                break;
            }
            // SAFETY: d_name is NUL-terminated.
            let name = unsafe { CStr::from_ptr((*ent).d_name.as_ptr()) };
            let b = name.to_bytes();
            if b != b"." && b != b".." {
                names.push(name.to_owned());
            }
        }
        drop(stream);
        let mut out = Vec::with_capacity(names.len());
        for c in names {
            // An entry gone since it was listed is not listed.
            if let Some(st) = lstat_at(self.raw(), &c)? {
                out.push((
                    String::from_utf8_lossy(c.to_bytes()).into_owned(),
                    Kind::of_mode(st.st_mode),
                ));
            }
        }
        out.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(out)
    }

    /// Where the link `name` points (the link is read, not followed).
    pub fn read_link(&self, name: &str) -> io::Result<PathBuf> {
        let c = cname(name)?;
        let mut buf = vec![0u8; 256];
        loop {
            // SAFETY: `buf` is writable for its length.
            let n = unsafe {
                libc::readlinkat(self.raw(), c.as_ptr(), buf.as_mut_ptr().cast(), buf.len())
            };
            if n < 0 {
                return Err(io::Error::last_os_error());
            }
            let n = n as usize;
            if n < buf.len() {
                buf.truncate(n);
                return Ok(PathBuf::from(OsString::from_vec(buf)));
            }
            buf.resize(buf.len() * 4, 0);
        }
    }

    /// Open the regular file `name` for reading, not following a link (`O_NOFOLLOW`) and not
    /// blocking on a FIFO: `None` if there is none; anything but a regular file is refused
    /// ([`NotOwn`]).
    pub fn open_file(&self, name: &str) -> io::Result<Option<File>> {
        let c = cname(name)?;
        let fd = match openat(
            self.raw(),
            &c,
            libc::O_RDONLY | libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_NOCTTY,
            0,
        ) {
            Ok(fd) => fd,
            Err(e) => return self.refuse(name, Kind::File, "file", e),
        };
        let f = File::from(fd);
        match Kind::of(&f.metadata()?) {
            Kind::File => Ok(Some(f)),
            k => Err(self.not_own(name, k, "file")),
        }
    }

    /// The bytes of the regular file `name` (as [`Dir::open_file`]).
    pub fn read(&self, name: &str) -> io::Result<Option<Vec<u8>>> {
        match self.open_file(name)? {
            Some(mut f) => {
                let mut v = Vec::new();
                f.read_to_end(&mut v)?;
                Ok(Some(v))
            }
            None => Ok(None),
        }
    }

    /// Create the new file `name` for writing: never an existing entry, never through a link
    /// (`O_CREAT | O_EXCL | O_NOFOLLOW`).
    pub fn create_new(&self, name: &str) -> io::Result<File> {
        let c = cname(name)?;
        let fd = openat(
            self.raw(),
            &c,
            libc::O_WRONLY | libc::O_CREAT | libc::O_EXCL | libc::O_NOFOLLOW,
            0o666,
        )?;
        Ok(File::from(fd))
    }

    /// Remove the entry `name`, a file or a link (`unlinkat` removes the link itself, never
    /// what it points to); false if there was none.
    pub fn remove_file(&self, name: &str) -> io::Result<bool> {
        let c = cname(name)?;
        // SAFETY: `c` is NUL-terminated.
        match cvt(unsafe { libc::unlinkat(self.raw(), c.as_ptr(), 0) }) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Remove the entry `name` and, if it is a directory, everything below it, never
    /// following a link (a link is removed itself).
    pub fn remove_tree(&self, name: &str) -> io::Result<()> {
        match self.kind(name)? {
            None => Ok(()),
            Some(Kind::Dir) => {
                if let Some(d) = self.sub(name)? {
                    for (n, k) in d.entries()? {
                        if k == Kind::Dir {
                            d.remove_tree(&n)?;
                        } else {
                            d.remove_file(&n)?;
                        }
                    }
                }
                let c = cname(name)?;
                // SAFETY: `c` is NUL-terminated.
                match cvt(unsafe { libc::unlinkat(self.raw(), c.as_ptr(), libc::AT_REMOVEDIR) }) {
                    Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
                    _ => Ok(()),
                }
            }
            Some(_) => self.remove_file(name).map(|_| ()),
        }
    }

    /// Move the entry `name` (a link itself, never what it points to) to `to_name` in `to`,
    /// replacing what is there; false if there was none.
    pub fn rename(&self, name: &str, to: &Dir, to_name: &str) -> io::Result<bool> {
        let (a, b) = (cname(name)?, cname(to_name)?);
        // SAFETY: both names are NUL-terminated.
        match cvt(unsafe { libc::renameat(self.raw(), a.as_ptr(), to.raw(), b.as_ptr()) }) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// A hard link `to_name` in `to` of the entry `name` (a link itself, not followed).
    pub fn hard_link(&self, name: &str, to: &Dir, to_name: &str) -> io::Result<()> {
        let (a, b) = (cname(name)?, cname(to_name)?);
        // SAFETY: both names are NUL-terminated; flags 0: a link is not followed.
        cvt(unsafe { libc::linkat(self.raw(), a.as_ptr(), to.raw(), b.as_ptr(), 0) })
    }

    /// Copy the regular file `name` to the new file `to_name` in `to` (fsynced).
    pub fn copy_file(&self, name: &str, to: &Dir, to_name: &str) -> io::Result<()> {
        let mut from = self
            .open_file(name)?
            .ok_or_else(|| io::Error::from_raw_os_error(libc::ENOENT))?;
        let mut out = to.create_new(to_name)?;
        io::copy(&mut from, &mut out)?;
        out.sync_all()
    }

    /// The link `name` pointing to `target`.
    pub fn symlink(&self, target: &Path, name: &str) -> io::Result<()> {
        let t = CString::new(target.as_os_str().as_bytes())
            .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "a NUL byte in a link"))?;
        let c = cname(name)?;
        // SAFETY: both are NUL-terminated.
        cvt(unsafe { libc::symlinkat(t.as_ptr(), self.raw(), c.as_ptr()) })
    }

    /// The directory `name` (created, durably, unless it exists); a link or anything but a
    /// directory there is refused ([`NotOwn`]).
    pub fn create_dir(&self, name: &str) -> io::Result<Dir> {
        let c = cname(name)?;
        // SAFETY: `c` is NUL-terminated.
        match cvt(unsafe { libc::mkdirat(self.raw(), c.as_ptr(), 0o777) }) {
            Ok(()) => self.sync()?,
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e),
        }
        self.sub(name)?
            .ok_or_else(|| io::Error::from_raw_os_error(libc::ENOENT))
    }

    /// The directories of `rel` (names separated by `/`), each created as by
    /// [`Dir::create_dir`].
    pub fn create_dirs(&self, rel: &str) -> io::Result<Dir> {
        let mut cur = self.try_clone()?;
        for name in rel.split('/').filter(|n| !n.is_empty()) {
            cur = cur.create_dir(name)?;
        }
        Ok(cur)
    }

    /// fsync the directory (its entries' renames and removals durable).
    pub fn sync(&self) -> io::Result<()> {
        // SAFETY: a valid descriptor.
        cvt(unsafe { libc::fsync(self.raw()) })
    }

    /// Write the file `name` atomically and durably: a new temporary file (never through a
    /// link), fsynced, renamed over `name` (a link there is replaced, not followed), the
    /// directory fsynced.
    pub fn write_atomic(&self, name: &str, bytes: &[u8]) -> io::Result<()> {
        let tmp = temp_name(name);
        let result = (|| {
            let mut f = self.create_new(&tmp)?;
            f.write_all(bytes)?;
            f.sync_all()?;
            drop(f);
            if !self.rename(&tmp, self, name)? {
                return Err(io::Error::from_raw_os_error(libc::ENOENT));
            }
            self.sync()
        })();
        if result.is_err() {
            let _ = self.remove_file(&tmp);
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dir_lists_links_as_links_and_never_follows_them() {
        let d = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        fs::write(outside.path().join("secret"), b"s").unwrap();
        let root = d.path().join("c");
        fs::create_dir_all(root.join("real")).unwrap();
        fs::write(root.join("real/f"), b"f").unwrap();
        std::os::unix::fs::symlink(outside.path(), root.join("out")).unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret"), root.join("real/s")).unwrap();
        let dir = Dir::open(&root).unwrap();
        assert_eq!(
            dir.entries().unwrap(),
            vec![
                ("out".to_string(), Kind::Link),
                ("real".to_string(), Kind::Dir)
            ]
        );
        // Listing twice starts from the beginning twice.
        assert_eq!(dir.entries().unwrap().len(), 2);
        let e = dir.sub("out").unwrap_err();
        let n = not_own(&e).expect("a NotOwn refusal");
        assert!(n.found.contains("symbolic link to"), "{e}");
        assert_eq!(n.path, root.join("out"));
        let real = dir.sub("real").unwrap().unwrap();
        assert!(real.open_file("f").unwrap().is_some());
        assert!(not_own(&real.open_file("s").unwrap_err()).is_some());
        assert!(not_own(&dir.open_file("real").unwrap_err()).is_some());
        assert!(real.open_file("none").unwrap().is_none());
        assert!(dir.walk("real").unwrap().is_some());
        assert!(not_own(&dir.walk("out/x").unwrap_err()).is_some());
        assert!(not_own(&open_regular(&root.join("real/s")).unwrap_err()).is_some());
        // Moving and removing act on the link itself.
        let q = dir.create_dirs("q/a").unwrap();
        assert!(dir.rename("out", &q, "out").unwrap());
        assert!(!dir.rename("out", &q, "out").unwrap());
        assert_eq!(q.kind("out").unwrap(), Some(Kind::Link));
        assert!(real.remove_file("s").unwrap());
        q.remove_tree("out").unwrap();
        dir.remove_tree("q").unwrap();
        assert_eq!(dir.kind("q").unwrap(), None);
        assert_eq!(fs::read(outside.path().join("secret")).unwrap(), b"s");
        // A link where a directory is to be created is refused, nothing created through it.
        std::os::unix::fs::symlink(outside.path(), root.join("made")).unwrap();
        assert!(not_own(&dir.create_dir("made").unwrap_err()).is_some());
        dir.write_atomic("made", b"x").unwrap();
        assert_eq!(dir.kind("made").unwrap(), Some(Kind::File));
        assert_eq!(fs::read_dir(outside.path()).unwrap().count(), 1);
    }

    #[test]
    fn read_inside_refuses_a_link() {
        let d = tempfile::tempdir().unwrap();
        fs::write(d.path().join("elsewhere.json"), b"{}").unwrap();
        fs::create_dir(d.path().join("c")).unwrap();
        std::os::unix::fs::symlink(
            d.path().join("elsewhere.json"),
            d.path().join("c/campaign.json"),
        )
        .unwrap();
        let e = read_inside(&d.path().join("c"), "campaign.json").unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        let e = read_inside(&d.path().join("c"), "none.json").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::NotFound);
    }
}
