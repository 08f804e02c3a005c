//! The reader table shared between processes: which states readers hold, kept by the kernel
//! as byte-range locks on the container file itself (format §11.6).
//!
//! A writer must not reuse a page while any reader, in any process, may still follow a
//! reference into it. LMDB keeps a table of reader slots in a shared lock file, and needs
//! `mdb_reader_check` to clear the slots of readers that died. fmrh lets the kernel keep the
//! table instead: a reader of the state with txn id `t` holds a *shared* open-file-description
//! lock (Linux `F_OFD_SETLK`) on byte [`LOCK_BASE`]` + t` of the container, and a writer holds
//! an *exclusive* one on byte [`LOCK_BASE`] itself. The bytes lie far past any real file's end
//! (locks need no data there), so nothing else is ever locked by accident.
//!
//! * A writer finds the oldest reader with `F_OFD_GETLK` probes over the reader bytes: no
//!   shared memory, no file beside the container, nothing to clean up.
//! * A reader that dies, even by `kill -9`, releases its lock when the kernel closes its file:
//!   a dead reader's registration is reclaimed at once, with no stale-slot check.
//! * Open-file-description locks belong to the open file, not the process, so two stores
//!   opened by one process are two readers, and closing an unrelated descriptor of the same
//!   file (the trap of classic POSIX locks) releases nothing.
//!
//! On systems without OFD locks every function here reports "cannot register", and the
//! store falls back to the binding of pages to their state (format §4): an unprotected
//! reader of a superseded state gets `Error::Superseded`, never another state's data.

use std::fs::File;
use std::io;

/// The byte whose exclusive lock marks a writer; reader `t` locks byte `LOCK_BASE + t`.
pub const LOCK_BASE: u64 = 1 << 62;

/// Whether this system can register readers (Linux: open-file-description locks).
pub const SUPPORTED: bool = cfg!(target_os = "linux");

/// The lock byte of a reader of state `txn`, if `txn` has one (`1 ..= 2^62 - 1`).
fn reader_byte(txn: u64) -> Option<u64> {
    (1..LOCK_BASE).contains(&txn).then(|| LOCK_BASE + txn)
}

#[cfg(target_os = "linux")]
// libc types the lock constants (0, 1, 2, SEEK_SET = 0) as `c_int` and the fields that take
// them as `c_short`: the casts cannot truncate.
#[allow(clippy::cast_possible_truncation)]
mod ofd {
    use std::fs::File;
    use std::io;
    use std::os::unix::io::AsRawFd;

    /// One `fcntl` lock request or probe on `len` bytes from `start`.
    fn request(kind: libc::c_short, start: u64, len: u64) -> libc::flock {
        // SAFETY: `flock` is a plain C struct of integers, for which all-zero is valid; OFD
        // requests require `l_pid` to be 0.
        let mut l: libc::flock = unsafe { std::mem::zeroed() };
        l.l_type = kind;
        l.l_whence = libc::SEEK_SET as libc::c_short;
        // Both are below 2^63: the lock bytes are `LOCK_BASE + t` with `t < 2^62`.
        l.l_start = i64::try_from(start).unwrap_or(i64::MAX);
        l.l_len = i64::try_from(len).unwrap_or(i64::MAX);
        l
    }

    fn fcntl(file: &File, cmd: libc::c_int, l: &mut libc::flock) -> io::Result<()> {
        // SAFETY: `file` is an open descriptor for the duration of the call, and `l` points to
        // a valid, exclusively borrowed `flock` that the kernel reads and (for GETLK) writes.
        let r = unsafe { libc::fcntl(file.as_raw_fd(), cmd, l as *mut libc::flock) };
        if r == -1 {
            Err(io::Error::last_os_error())
        } else {
            Ok(())
        }
    }

    /// Takes (`F_RDLCK`, `F_WRLCK`) or drops (`F_UNLCK`) a lock without waiting.
    pub fn set(file: &File, kind: libc::c_short, start: u64, len: u64) -> io::Result<bool> {
        let mut l = request(kind, start, len);
        match fcntl(file, libc::F_OFD_SETLK, &mut l) {
            Ok(()) => Ok(true),
            Err(e) if matches!(e.raw_os_error(), Some(libc::EAGAIN | libc::EACCES)) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// The start of a lock another open file holds that would block a `kind` lock on the
    /// range, if any.
    pub fn probe(
        file: &File,
        kind: libc::c_short,
        start: u64,
        len: u64,
    ) -> io::Result<Option<u64>> {
        let mut l = request(kind, start, len);
        fcntl(file, libc::F_OFD_GETLK, &mut l)?;
        if l.l_type == libc::F_UNLCK as libc::c_short {
            Ok(None)
        } else {
            Ok(Some(u64::try_from(l.l_start).unwrap_or(0)))
        }
    }

    pub const SHARED: libc::c_short = libc::F_RDLCK as libc::c_short;
    pub const EXCLUSIVE: libc::c_short = libc::F_WRLCK as libc::c_short;
    pub const UNLOCK: libc::c_short = libc::F_UNLCK as libc::c_short;
}

/// Registers the open `file` as a reader of state `txn`, then drops its registration for
/// `previous` (in that order, so the reader is never unprotected in between). `Ok(false)` when
/// this system or this txn id cannot register.
pub fn register_reader(file: &File, txn: u64, previous: Option<u64>) -> io::Result<bool> {
    let Some(byte) = reader_byte(txn) else {
        return Ok(false);
    };
    #[cfg(target_os = "linux")]
    {
        // A shared lock is never refused by another shared lock, and writers never lock
        // reader bytes: `false` here would be a kernel surprise, reported as "cannot".
        if !ofd::set(file, ofd::SHARED, byte, 1)? {
            return Ok(false);
        }
        if let Some(old) = previous.filter(|&p| p != txn).and_then(reader_byte) {
            ofd::set(file, ofd::UNLOCK, old, 1)?;
        }
        Ok(true)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (file, byte, previous);
        Ok(false)
    }
}

/// Marks the open `file` as a writer's. `Ok(false)` if another open file already is one; on
/// systems without OFD locks, `Ok(true)` (exclusion then rests on `flock` alone).
pub fn hold_writer(file: &File) -> io::Result<bool> {
    #[cfg(target_os = "linux")]
    {
        ofd::set(file, ofd::EXCLUSIVE, LOCK_BASE, 1)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = file;
        Ok(true)
    }
}

/// Drops the writer mark of [`hold_writer`] (closing the file drops it too, but a child
/// process forked meanwhile shares the open file until it execs).
pub fn release_writer(file: &File) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        ofd::set(file, ofd::UNLOCK, LOCK_BASE, 1).map(|_| ())
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = file;
        Ok(())
    }
}

/// Whether a writer (another open file) holds the container open: `None` where this system
/// cannot tell.
pub fn writer_present(file: &File) -> io::Result<Option<bool>> {
    #[cfg(target_os = "linux")]
    {
        Ok(Some(
            ofd::probe(file, ofd::EXCLUSIVE, LOCK_BASE, 1)?.is_some(),
        ))
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = file;
        Ok(None)
    }
}

/// The lowest txn id `<= up_to` that a reader (another open file) has registered, if any.
/// Each probe returns some blocking lock, not necessarily the lowest, so the range shrinks
/// below each one found until none is left: at most one probe per registered state.
pub fn oldest_reader(file: &File, up_to: u64) -> io::Result<Option<u64>> {
    let mut hi = up_to.min(LOCK_BASE - 1);
    let mut found = None;
    while hi >= 1 {
        match probe_readers(file, 1, hi)? {
            Some(txn) => {
                found = Some(txn);
                hi = txn - 1;
            }
            None => break,
        }
    }
    Ok(found)
}

/// Every txn id `<= up_to` that readers have registered, ascending (for `fmrh info`).
#[cfg(any(test, feature = "testing"))]
pub fn registered_readers(file: &File, up_to: u64) -> io::Result<Vec<u64>> {
    let mut out = Vec::new();
    let mut lo = 1;
    let hi = up_to.min(LOCK_BASE - 1);
    while lo <= hi {
        // The lowest registered txn in `lo ..= hi`, by probes that shrink the range.
        let mut top = hi;
        let mut lowest = None;
        while top >= lo {
            match probe_readers(file, lo, top)? {
                Some(txn) => {
                    lowest = Some(txn);
                    top = txn - 1;
                }
                None => break,
            }
        }
        match lowest {
            Some(t) => {
                out.push(t);
                lo = t + 1;
            }
            None => break,
        }
    }
    Ok(out)
}

/// Some registered txn id in `lo ..= hi` (`1 <= lo <= hi < LOCK_BASE`), if any.
fn probe_readers(file: &File, lo: u64, hi: u64) -> io::Result<Option<u64>> {
    #[cfg(target_os = "linux")]
    {
        Ok(
            ofd::probe(file, ofd::EXCLUSIVE, LOCK_BASE + lo, hi - lo + 1)?
                .map(|start| start.saturating_sub(LOCK_BASE))
                .filter(|t| (lo..=hi).contains(t)),
        )
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (file, lo, hi);
        Ok(None)
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn open(path: &std::path::Path) -> File {
        std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .unwrap()
    }

    #[test]
    fn readers_of_two_open_files_are_seen_and_released_on_close() {
        let f = tempfile::NamedTempFile::new().unwrap();
        let writer = open(f.path());
        assert!(hold_writer(&writer).unwrap());
        let (a, b) = (open(f.path()), open(f.path()));
        assert!(register_reader(&a, 9, None).unwrap());
        assert!(register_reader(&b, 4, None).unwrap());
        assert_eq!(oldest_reader(&writer, 100).unwrap(), Some(4));
        assert_eq!(oldest_reader(&writer, 3).unwrap(), None);
        assert_eq!(registered_readers(&writer, 100).unwrap(), vec![4, 9]);
        // Moving on registers the new state before dropping the old.
        assert!(register_reader(&b, 12, Some(4)).unwrap());
        assert_eq!(oldest_reader(&writer, 100).unwrap(), Some(9));
        drop(a);
        assert_eq!(oldest_reader(&writer, 100).unwrap(), Some(12));
        // The writer's own registrations are not other readers.
        assert!(register_reader(&writer, 2, None).unwrap());
        assert_eq!(oldest_reader(&writer, 100).unwrap(), Some(12));
        // A reader sees the writer; a second writer is refused.
        assert_eq!(writer_present(&b).unwrap(), Some(true));
        assert!(!hold_writer(&open(f.path())).unwrap());
        drop(writer);
        assert_eq!(writer_present(&b).unwrap(), Some(false));
    }
}
