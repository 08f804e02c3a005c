//! Where a store's bytes come from: a memory map, a file read with `pread`, or bytes in memory.
//!
//! Every parser works on `&[u8]`. A [`Source`] only hands out byte ranges: borrowed from a
//! mapping or a buffer (zero-copy), or owned after a read. The store asks a source whether
//! its bytes can change after they were checked (`stable`). A file read with `pread` can be
//! rewritten by another process, so every page read from it is checked again. A new kind of
//! source (HTTP ranges, object storage) is one more implementation of this trait.

use std::borrow::Cow;
use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

use memmap2::Mmap;

use crate::error::{Error, Result};

/// A readable, fixed-length run of bytes.
pub trait Source: Send + Sync {
    /// Total bytes.
    fn len(&self) -> u64;

    /// Whether the source is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes `offset .. offset + len` as the source holds them now, past anything it keeps
    /// in memory: what error triage reads (the commit slots) to tell a superseded or
    /// replaced state from damage. The default is [`Source::read_at`], for sources that keep
    /// nothing.
    fn read_fresh(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        self.read_at(offset, len)
    }

    /// Bytes `offset .. offset + len`. Callers check the range against [`Source::len`]
    /// first; a range beyond it is an error, never a panic.
    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>>;

    /// Whether bytes once checked stay as they were, so pages validated at open need no
    /// second check (true for a mapping under the [`super::Store::open_mapped`] contract, and
    /// for memory).
    fn stable(&self) -> bool;

    /// What errors call the source: its path, or a description such as `<memory>`.
    fn name(&self) -> &Path;

    /// Registers this source as a reader of state `txn`, so that writers in other processes
    /// keep every page that state reaches (format §11.6), and drops any earlier registration
    /// of this source. `Ok(false)` when the source cannot register: its bytes are not a file
    /// a writer changes in place (memory), or the system has no open-file-description locks.
    /// The default registers nothing.
    fn register_reader(&self, txn: u64) -> io::Result<bool> {
        let _ = txn;
        Ok(false)
    }

    /// The length now, for a source whose length can change (a file a writer grows): what
    /// [`Source::len`] says from then on. The default is [`Source::len`], fixed.
    fn refresh_len(&self) -> io::Result<u64> {
        Ok(self.len())
    }

    /// Whether a writer holds the file open (a commit may be running): `None` when the
    /// source cannot tell.
    fn writer_present(&self) -> io::Result<Option<bool>> {
        Ok(None)
    }

    /// Several ranges at once, each as [`Source::read_at`] would give it, in the order
    /// asked. A source where a read costs a round trip (a remote object) fetches them
    /// together, in parallel; the default reads them in turn.
    fn read_many(&self, ranges: &[(u64, usize)]) -> io::Result<Vec<Cow<'_, [u8]>>> {
        ranges
            .iter()
            .map(|&(offset, len)| self.read_at(offset, len))
            .collect()
    }

    /// A hint from the store after opening: bytes `area` hold the state's metadata pages
    /// (the tables that lookups read a page at a time). A source where each read costs a
    /// round trip may fetch the area whole on the first read inside it. The default ignores
    /// it.
    fn advise_metadata(&self, area: std::ops::Range<u64>) {
        let _ = area;
    }

    /// What a remote source has asked its server for (requests, bytes, rounds); `None` for
    /// a local one.
    fn request_stats(&self) -> Option<RequestStats> {
        None
    }

    /// Whether [`Source::prefetch`] is worth planning for: true where each read costs a
    /// round trip (a remote object), so that a reader which knows the pages it will read
    /// next asks for them together. False (the default) where a read is a memory access:
    /// planning would only cost time.
    fn prefetches(&self) -> bool {
        false
    }

    /// A hint that `ranges` will be read soon: a source where each read costs a round trip
    /// fetches those it does not hold in one round and holds them for the reads that follow.
    /// It changes no answer: a read outside what was fetched is served as before. The
    /// default ignores it.
    fn prefetch(&self, ranges: &[(u64, usize)]) -> io::Result<()> {
        let _ = ranges;
        Ok(())
    }
}

/// A borrowed source reads what it borrows (the validator opens a store on a source it keeps).
impl<S: Source + ?Sized> Source for &S {
    fn len(&self) -> u64 {
        (**self).len()
    }

    #[inline]
    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        (**self).read_at(offset, len)
    }

    fn read_fresh(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        (**self).read_fresh(offset, len)
    }

    #[inline]
    fn stable(&self) -> bool {
        (**self).stable()
    }

    fn name(&self) -> &Path {
        (**self).name()
    }

    fn register_reader(&self, txn: u64) -> io::Result<bool> {
        (**self).register_reader(txn)
    }

    fn refresh_len(&self) -> io::Result<u64> {
        (**self).refresh_len()
    }

    fn writer_present(&self) -> io::Result<Option<bool>> {
        (**self).writer_present()
    }

    fn read_many(&self, ranges: &[(u64, usize)]) -> io::Result<Vec<Cow<'_, [u8]>>> {
        (**self).read_many(ranges)
    }

    fn advise_metadata(&self, area: std::ops::Range<u64>) {
        (**self).advise_metadata(area)
    }

    fn request_stats(&self) -> Option<RequestStats> {
        (**self).request_stats()
    }

    fn prefetches(&self) -> bool {
        (**self).prefetches()
    }

    fn prefetch(&self, ranges: &[(u64, usize)]) -> io::Result<()> {
        (**self).prefetch(ranges)
    }
}

/// What a remote source has asked its server for ([`Source::request_stats`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RequestStats {
    /// Range requests sent (retries included).
    pub requests: u64,
    /// Body bytes received.
    pub bytes: u64,
    /// Sequential waits for the network: a batch of `n` requests over `c` connections counts
    /// `ceil(n / c)`.
    pub rounds: u64,
    /// Requests that were retries.
    pub retries: u64,
}

impl RequestStats {
    /// What was asked between `earlier` and `self`.
    pub fn since(&self, earlier: &RequestStats) -> RequestStats {
        RequestStats {
            requests: self.requests.saturating_sub(earlier.requests),
            bytes: self.bytes.saturating_sub(earlier.bytes),
            rounds: self.rounds.saturating_sub(earlier.rounds),
            retries: self.retries.saturating_sub(earlier.retries),
        }
    }

    /// Both together.
    pub fn plus(&self, other: &RequestStats) -> RequestStats {
        RequestStats {
            requests: self.requests + other.requests,
            bytes: self.bytes + other.bytes,
            rounds: self.rounds + other.rounds,
            retries: self.retries + other.retries,
        }
    }
}

/// A file's registration as a reader (see [`super::lock`]): the txn id it holds, 0 for none.
#[derive(Debug, Default)]
struct Registration(std::sync::atomic::AtomicU64);

impl Registration {
    fn register(&self, file: &File, txn: u64) -> io::Result<bool> {
        use std::sync::atomic::Ordering;
        let previous = Some(self.0.load(Ordering::Acquire)).filter(|&t| t != 0);
        let done = super::lock::register_reader(file, txn, previous)?;
        if done {
            self.0.store(txn, Ordering::Release);
        }
        Ok(done)
    }
}

#[inline]
fn slice_at(bytes: &[u8], offset: u64, len: usize) -> io::Result<&[u8]> {
    usize::try_from(offset)
        .ok()
        .and_then(|o| Some(o..o.checked_add(len)?))
        .and_then(|r| bytes.get(r))
        .ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::UnexpectedEof,
                format!("{len} bytes at offset {offset} lie past the end"),
            )
        })
}

/// Bytes in memory. Errors call it `<memory>`.
#[derive(Clone, Debug)]
pub struct Bytes<T>(pub T);

/// The name of every [`Bytes`] source.
const MEMORY: &str = "<memory>";

impl<T: AsRef<[u8]> + Send + Sync> Source for Bytes<T> {
    fn len(&self) -> u64 {
        self.0.as_ref().len() as u64
    }

    #[inline]
    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        slice_at(self.0.as_ref(), offset, len).map(Cow::Borrowed)
    }

    #[inline]
    fn stable(&self) -> bool {
        true
    }

    fn name(&self) -> &Path {
        Path::new(MEMORY)
    }
}

/// A read-only memory map of a file (see [`super::Store::open_mapped`] for the contract).
#[derive(Debug)]
pub struct MmapSource {
    map: Mmap,
    /// Kept open: the reader's registration lives as long as the file does.
    file: File,
    registration: Registration,
    path: PathBuf,
}

impl MmapSource {
    /// Maps `file`, which is at `path`.
    ///
    /// # Safety
    /// The caller promises what [`super::Store::open_mapped`] documents: nobody modifies or
    /// truncates the pages a registered state reaches while the mapping lives.
    pub unsafe fn new(file: &File, path: &Path) -> Result<MmapSource> {
        // SAFETY: forwarded to our caller's contract (no concurrent modification or
        // truncation of what the mapping is used to read, for its lifetime).
        let map = unsafe { Mmap::map(file) }.map_err(|e| Error::io(path, e))?;
        Ok(MmapSource {
            map,
            // The same open file description, so the registration is this file's.
            file: file.try_clone().map_err(|e| Error::io(path, e))?,
            registration: Registration::default(),
            path: path.to_path_buf(),
        })
    }
}

impl Source for MmapSource {
    fn len(&self) -> u64 {
        self.map.len() as u64
    }

    #[inline]
    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        slice_at(&self.map, offset, len).map(Cow::Borrowed)
    }

    #[inline]
    fn stable(&self) -> bool {
        true
    }

    fn name(&self) -> &Path {
        &self.path
    }

    fn register_reader(&self, txn: u64) -> io::Result<bool> {
        self.registration.register(&self.file, txn)
    }

    fn writer_present(&self) -> io::Result<Option<bool>> {
        super::lock::writer_present(&self.file)
    }
}

/// A file read with positioned reads: safe whatever other processes do to the file (a
/// changed page fails its checksum instead of crashing the reader).
#[derive(Debug)]
pub struct FileSource {
    file: File,
    /// The file's length when last looked at (it changes under a writer).
    len: std::sync::atomic::AtomicU64,
    registration: Registration,
    path: PathBuf,
}

impl FileSource {
    /// Wraps `file`, open at `path`; its length is read once.
    pub fn new(file: File, path: &Path) -> Result<FileSource> {
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        Ok(FileSource {
            file,
            len: len.into(),
            registration: Registration::default(),
            path: path.to_path_buf(),
        })
    }

    /// Opens the file at `path` for reading.
    pub fn open(path: &Path) -> Result<FileSource> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        FileSource::new(file, path)
    }
}

impl Source for FileSource {
    fn len(&self) -> u64 {
        self.len.load(std::sync::atomic::Ordering::Acquire)
    }

    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        if offset
            .checked_add(len as u64)
            .is_none_or(|end| end > self.len())
        {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                format!("{len} bytes at offset {offset} lie past the end"),
            ));
        }
        let mut buf = vec![0u8; len];
        read_exact_at(&self.file, &mut buf, offset)?;
        Ok(Cow::Owned(buf))
    }

    fn stable(&self) -> bool {
        false
    }

    fn name(&self) -> &Path {
        &self.path
    }

    fn refresh_len(&self) -> io::Result<u64> {
        let len = self.file.metadata()?.len();
        self.len.store(len, std::sync::atomic::Ordering::Release);
        Ok(len)
    }

    fn register_reader(&self, txn: u64) -> io::Result<bool> {
        self.registration.register(&self.file, txn)
    }

    fn writer_present(&self) -> io::Result<Option<bool>> {
        super::lock::writer_present(&self.file)
    }
}

/// A source that counts the reads that pass through it: calls and bytes. What a store
/// reads is also in [`super::Store::read_stats`]; this counts what the source itself sees
/// (tests, benchmarks, and the open path).
#[derive(Debug)]
pub struct Counted<S> {
    inner: S,
    calls: std::sync::atomic::AtomicU64,
    bytes: std::sync::atomic::AtomicU64,
}

impl<S: Source> Counted<S> {
    /// Counts the reads of `inner`.
    pub fn new(inner: S) -> Counted<S> {
        Counted {
            inner,
            calls: 0.into(),
            bytes: 0.into(),
        }
    }

    /// The source it counts.
    pub fn inner(&self) -> &S {
        &self.inner
    }

    /// Reads so far (as metadata: this wrapper does not know what it reads).
    pub fn stats(&self) -> super::ReadStats {
        use std::sync::atomic::Ordering::Relaxed;
        super::ReadStats {
            metadata_reads: self.calls.load(Relaxed),
            metadata_bytes: self.bytes.load(Relaxed),
            payload_reads: 0,
            payload_bytes: 0,
        }
    }
}

impl<S: Source> Source for Counted<S> {
    fn len(&self) -> u64 {
        self.inner.len()
    }

    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        use std::sync::atomic::Ordering::Relaxed;
        self.calls.fetch_add(1, Relaxed);
        self.bytes.fetch_add(len as u64, Relaxed);
        self.inner.read_at(offset, len)
    }

    fn read_fresh(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        use std::sync::atomic::Ordering::Relaxed;
        self.calls.fetch_add(1, Relaxed);
        self.bytes.fetch_add(len as u64, Relaxed);
        self.inner.read_fresh(offset, len)
    }

    fn stable(&self) -> bool {
        self.inner.stable()
    }

    fn name(&self) -> &Path {
        self.inner.name()
    }

    fn register_reader(&self, txn: u64) -> io::Result<bool> {
        self.inner.register_reader(txn)
    }

    fn refresh_len(&self) -> io::Result<u64> {
        self.inner.refresh_len()
    }

    fn writer_present(&self) -> io::Result<Option<bool>> {
        self.inner.writer_present()
    }

    fn read_many(&self, ranges: &[(u64, usize)]) -> io::Result<Vec<Cow<'_, [u8]>>> {
        use std::sync::atomic::Ordering::Relaxed;
        self.calls.fetch_add(ranges.len() as u64, Relaxed);
        let bytes: u64 = ranges.iter().map(|&(_, len)| len as u64).sum();
        self.bytes.fetch_add(bytes, Relaxed);
        self.inner.read_many(ranges)
    }

    fn advise_metadata(&self, area: std::ops::Range<u64>) {
        self.inner.advise_metadata(area)
    }

    fn request_stats(&self) -> Option<RequestStats> {
        self.inner.request_stats()
    }

    fn prefetches(&self) -> bool {
        self.inner.prefetches()
    }

    fn prefetch(&self, ranges: &[(u64, usize)]) -> io::Result<()> {
        self.inner.prefetch(ranges)
    }
}

/// The error of a failed read of `len` bytes at `offset` from the file at `path`. A read
/// past the end means the file is shorter than its commit record says (I-3): corruption. Any
/// other failure is the operating system's and stays an I/O error.
pub(crate) fn read_error(path: &Path, offset: u64, len: usize, e: io::Error) -> Error {
    if e.kind() == io::ErrorKind::UnexpectedEof {
        crate::format::Violation::new(
            crate::format::Invariant::FileLength,
            format!("byte {offset}"),
            format!("{len} bytes there lie past the end of the file"),
        )
        .in_file(path)
    } else {
        Error::io(path, e)
    }
}

/// Reads several ranges of `src` at once ([`Source::read_many`]), as a store error.
pub(crate) fn read_many<'a, S: Source + ?Sized>(
    src: &'a S,
    ranges: &[(u64, usize)],
) -> Result<Vec<Cow<'a, [u8]>>> {
    src.read_many(ranges).map_err(|e| {
        let (offset, len) = ranges.first().copied().unwrap_or((0, 0));
        read_error(src.name(), offset, len, e)
    })
}

/// Reads `len` bytes at `offset` of `src`, as a store error (see [`read_error`]).
pub(crate) fn read<S: Source + ?Sized>(src: &S, offset: u64, len: usize) -> Result<Cow<'_, [u8]>> {
    src.read_at(offset, len)
        .map_err(|e| read_error(src.name(), offset, len, e))
}

#[cfg(unix)]
pub(crate) fn read_exact_at(file: &File, buf: &mut [u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(windows)]
pub(crate) fn read_exact_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, offset) {
            Ok(0) => return Err(io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}
