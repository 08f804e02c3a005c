//! The page cache of a committed state: a [`Source`] over an [`Io`] that keeps the pages
//! opening checked and serves them zero-copy afterwards.
//!
//! Opening a state reads and checks every table and blob page it reaches. The source keeps
//! those page-shaped reads (a power-of-two length from 1024 to 65536 at a multiple of it), and
//! once the state is open it [freezes](IoSource::freeze) them: lookups then borrow pages from
//! memory instead of making a system call. That is sound because no page a state reaches
//! changes while anything can read that state (format §11.5): what the cache serves is what
//! was checked, so the source is `stable` and lookups skip a second check. Payloads are read
//! from the device each time, and [`crate::Store::payload`] checks every one's CRC.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

use super::lock;
use crate::format;
use crate::store::io::Io;
use crate::store::Source;

/// A [`Source`] over an [`Io`], for the states a container hands out (see the module docs).
pub struct IoSource<I: Io> {
    io: Arc<I>,
    len: u64,
    filling: Mutex<HashMap<u64, Box<[u8]>>>,
    frozen: OnceLock<HashMap<u64, Box<[u8]>>>,
}

impl<I: Io> IoSource<I> {
    /// A source of the first `len` bytes of `io`.
    pub(crate) fn new(io: Arc<I>, len: u64) -> Self {
        IoSource {
            io,
            len,
            filling: Mutex::new(HashMap::new()),
            frozen: OnceLock::new(),
        }
    }

    /// Ends the filling: from now on the pages read so far are served from memory and
    /// nothing more is kept.
    pub(crate) fn freeze(&self) {
        let pages = std::mem::take(&mut *lock(&self.filling));
        let _ = self.frozen.set(pages);
    }
}

fn page_shaped(offset: u64, len: usize) -> bool {
    len.is_power_of_two()
        && (format::MIN_PAGE_SIZE as usize..=format::MAX_PAGE_SIZE as usize).contains(&len)
        && offset.is_multiple_of(len as u64)
}

impl<I: Io> Source for IoSource<I> {
    fn len(&self) -> u64 {
        self.len
    }

    #[inline]
    fn read_at(&self, offset: u64, len: usize) -> std::io::Result<Cow<'_, [u8]>> {
        // The common case, a table page of the open state, stays small enough to inline.
        if let Some(page) = self
            .frozen
            .get()
            .and_then(|f| f.get(&offset))
            .filter(|p| p.len() == len)
        {
            return Ok(Cow::Borrowed(page));
        }
        self.read_device(offset, len)
    }

    fn stable(&self) -> bool {
        true
    }

    fn name(&self) -> &Path {
        self.io.name()
    }
}

impl<I: Io> IoSource<I> {
    /// Reads from the device, keeping page-shaped reads while the state is being opened.
    fn read_device(&self, offset: u64, len: usize) -> std::io::Result<Cow<'_, [u8]>> {
        if offset.checked_add(len as u64).is_none_or(|e| e > self.len) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!("{len} bytes at offset {offset} lie past the end"),
            ));
        }
        let frozen = self.frozen.get();
        let mut buf = vec![0u8; len];
        self.io.read_at(offset, &mut buf)?;
        if frozen.is_none() && page_shaped(offset, len) {
            lock(&self.filling)
                .entry(offset)
                .or_insert_with(|| buf.clone().into_boxed_slice());
        }
        Ok(Cow::Owned(buf))
    }
}
