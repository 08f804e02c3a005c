//! A source that is whichever its name says: a local file, or (with the `remote` feature) an
//! object read with range requests. Datasets read their manifest and tiles through it, so one
//! reader serves a directory and a URL alike.

use std::borrow::Cow;
use std::io;
use std::path::Path;

use super::source::{FileSource, RequestStats, Source};
use crate::error::Result;

/// A file or, with the `remote` feature, a remote object: whichever its name says
/// ([`AnySource::open`]). A dataset reads its manifest and its tiles through it, so one
/// dataset reader serves a directory and a URL alike.
#[derive(Debug)]
pub enum AnySource {
    /// A local file, read with positioned reads.
    File(FileSource),
    /// An object read with HTTP range requests (`http://`, `https://`, `s3://`).
    #[cfg(feature = "remote")]
    Remote(Box<super::remote::HttpSource>),
}

impl AnySource {
    /// Opens `location`: a URL (`http://`, `https://`, `s3://`) as a remote object, anything
    /// else as a file path.
    pub fn open(location: &Path) -> Result<AnySource> {
        AnySource::open_tile(location, None)
    }

    /// As [`AnySource::open`], for a tile of the dataset whose manifest `manifest` reads
    /// (`None`: not a tile). A remote tile fetches a large metadata area in chunks
    /// (`RemoteOptions::for_tiles`, feature `remote`), and asks for ranges the way the
    /// manifest's server was found to answer them (one request for many, or one each).
    pub fn open_tile(location: &Path, manifest: Option<&AnySource>) -> Result<AnySource> {
        if let Some(url) = location.to_str().filter(|t| is_url(t)) {
            #[cfg(feature = "remote")]
            {
                use super::remote::{HttpSource, RemoteOptions};
                let options = match manifest {
                    Some(AnySource::Remote(m)) => RemoteOptions {
                        multi_range: m.multi_range(),
                        ..RemoteOptions::for_tiles()
                    },
                    Some(_) => RemoteOptions::for_tiles(),
                    None => RemoteOptions::default(),
                };
                return Ok(AnySource::Remote(Box::new(HttpSource::open_with(
                    url, options,
                )?)));
            }
            #[cfg(not(feature = "remote"))]
            {
                let _ = manifest;
                return Err(crate::error::Error::unsupported(
                    location,
                    format!("{url}: this fmrh was built without the `remote` feature"),
                ));
            }
        }
        Ok(AnySource::File(FileSource::open(location)?))
    }

    /// Whether it is a remote object.
    pub fn is_remote(&self) -> bool {
        !matches!(self, AnySource::File(_))
    }
}

/// Whether `text` names a remote object: `http://`, `https://` or `s3://`.
pub fn is_url(text: &str) -> bool {
    text.starts_with("http://") || text.starts_with("https://") || text.starts_with("s3://")
}

macro_rules! any_source {
    ($self:ident, $s:ident => $e:expr) => {
        match $self {
            AnySource::File(file) => {
                let $s: &dyn Source = file;
                $e
            }
            #[cfg(feature = "remote")]
            AnySource::Remote(remote) => {
                let $s: &dyn Source = &**remote;
                $e
            }
        }
    };
}

impl Source for AnySource {
    fn len(&self) -> u64 {
        any_source!(self, s => s.len())
    }

    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        any_source!(self, s => s.read_at(offset, len))
    }

    fn read_fresh(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        any_source!(self, s => s.read_fresh(offset, len))
    }

    fn stable(&self) -> bool {
        any_source!(self, s => s.stable())
    }

    fn name(&self) -> &Path {
        any_source!(self, s => s.name())
    }

    fn register_reader(&self, txn: u64) -> io::Result<bool> {
        any_source!(self, s => s.register_reader(txn))
    }

    fn refresh_len(&self) -> io::Result<u64> {
        any_source!(self, s => s.refresh_len())
    }

    fn writer_present(&self) -> io::Result<Option<bool>> {
        any_source!(self, s => s.writer_present())
    }

    fn read_many(&self, ranges: &[(u64, usize)]) -> io::Result<Vec<Cow<'_, [u8]>>> {
        any_source!(self, s => s.read_many(ranges))
    }

    fn advise_metadata(&self, area: std::ops::Range<u64>) {
        any_source!(self, s => s.advise_metadata(area))
    }

    fn request_stats(&self) -> Option<RequestStats> {
        any_source!(self, s => s.request_stats())
    }

    fn prefetches(&self) -> bool {
        any_source!(self, s => s.prefetches())
    }

    fn prefetch(&self, ranges: &[(u64, usize)]) -> io::Result<()> {
        any_source!(self, s => s.prefetch(ranges))
    }
}
