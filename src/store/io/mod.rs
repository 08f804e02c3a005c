//! The byte device under a writable container: a real file, or a simulated disk that can lose
//! power.
//!
//! [`Io`] is the whole contract the commit protocol relies on: positioned reads and writes,
//! `sync` (after it returns, every earlier write and length change is durable), and
//! `set_len`. Nothing written since the last `sync` is promised to survive a crash, in whole
//! or in part.
//!
//! `SimDisk` (in `sim`, compiled for the crate's own tests and with the `testing` feature)
//! makes that promise literal for tests: it crashes with every unsynced write kept, dropped
//! or torn, loses power after the `n`th operation, and fails chosen operations.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

#[cfg(any(test, feature = "testing"))]
mod sim;
#[cfg(any(test, feature = "testing"))]
pub use sim::{Damage, Fault, OpKind, SimDisk, SimPower, SECTOR};

/// A byte device with durable writes on `sync`.
pub trait Io: Send + Sync {
    /// Current length in bytes (what reads see).
    fn len(&self) -> io::Result<u64>;
    /// Whether the device holds no byte.
    fn is_empty(&self) -> io::Result<bool> {
        Ok(self.len()? == 0)
    }
    /// Fills `buf` from `offset`; fails if the range passes the end.
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<()>;
    /// Writes `data` at `offset`, extending the device if needed.
    fn write_at(&self, offset: u64, data: &[u8]) -> io::Result<()>;
    /// Makes every earlier write and length change durable.
    fn sync(&self) -> io::Result<()>;
    /// Sets the length, cutting or zero-extending.
    fn set_len(&self, len: u64) -> io::Result<()>;
    /// A name for messages.
    fn name(&self) -> &Path;
    /// The lowest txn id `<= up_to` that readers in other processes hold (format §11.6), if
    /// any. Devices no other process reads have none.
    fn oldest_reader(&self, up_to: u64) -> io::Result<Option<u64>> {
        let _ = up_to;
        Ok(None)
    }
}

/// A shared device is the device: what the commit protocol writes through one handle it
/// writes through all (a dataset reads a tile's slots, then gives the same device to its
/// container).
impl<I: Io + ?Sized> Io for std::sync::Arc<I> {
    fn len(&self) -> io::Result<u64> {
        (**self).len()
    }

    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<()> {
        (**self).read_at(offset, buf)
    }

    fn write_at(&self, offset: u64, data: &[u8]) -> io::Result<()> {
        (**self).write_at(offset, data)
    }

    fn sync(&self) -> io::Result<()> {
        (**self).sync()
    }

    fn set_len(&self, len: u64) -> io::Result<()> {
        (**self).set_len(len)
    }

    fn name(&self) -> &Path {
        (**self).name()
    }

    fn oldest_reader(&self, up_to: u64) -> io::Result<Option<u64>> {
        (**self).oldest_reader(up_to)
    }
}

/// A real file: `pread`/`pwrite`, `fsync` (`File::sync_all`), `ftruncate`.
#[derive(Debug)]
pub struct FileIo {
    file: File,
    path: PathBuf,
}

impl FileIo {
    /// Opens `path` for reading and writing, and takes an exclusive advisory lock on it
    /// (`flock` / `LockFileEx`) for as long as the `FileIo` lives, so that a second writer,
    /// in this process or another, is refused instead of corrupting the file. Readers that
    /// open the file without a `Container` take no lock and are not protected (see
    /// `format-spec/container.md` §11.6).
    ///
    /// A file replaced at `path` between the open and the lock (`fmrh compact` renames a
    /// rewritten file over the old one while it holds the lock) is opened again: a writer
    /// never commits to a file that is no longer at its path.
    pub fn open(path: &Path) -> io::Result<FileIo> {
        for _ in 0..8 {
            let io = FileIo::open_once(path)?;
            if still_at(&io.file, path)? {
                return Ok(io);
            }
        }
        Err(io::Error::new(
            io::ErrorKind::WouldBlock,
            "the file was replaced at its path eight times while it was opened",
        ))
    }

    fn open_once(path: &Path) -> io::Result<FileIo> {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(io::Error::new(
                    io::ErrorKind::WouldBlock,
                    "another writer has the file open (it is locked)",
                ))
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(e),
        }
        // Also marks the file as a writer's for readers in other processes, who can then
        // tell a running commit from damage (`verify`), without taking any lock that would
        // stand in a writer's way.
        if !super::lock::hold_writer(&file)? {
            return Err(io::Error::new(
                io::ErrorKind::WouldBlock,
                "another writer has the file open (it is locked)",
            ));
        }
        Ok(FileIo {
            file,
            path: path.to_path_buf(),
        })
    }
}

/// Whether `path` still names the file `file` is open on (the same device and inode).
#[cfg(unix)]
fn still_at(file: &std::fs::File, path: &Path) -> io::Result<bool> {
    use std::os::unix::fs::MetadataExt;
    let (open, named) = (file.metadata()?, std::fs::metadata(path));
    Ok(named.is_ok_and(|n| n.dev() == open.dev() && n.ino() == open.ino()))
}

/// Elsewhere a path is not replaced under an open file in the same way (Windows refuses to
/// rename over an open file).
#[cfg(not(unix))]
fn still_at(_file: &std::fs::File, _path: &Path) -> io::Result<bool> {
    Ok(true)
}

impl Drop for FileIo {
    fn drop(&mut self) {
        // Release the locks on the open file description itself, not only by closing our
        // descriptor: a child process that another thread forked meanwhile shares the
        // description until it execs, and would keep the file locked against the next writer
        // for that moment. Best effort: closing releases them in any case.
        let _ = super::lock::release_writer(&self.file);
        let _ = self.file.unlock();
    }
}

impl Io for FileIo {
    fn len(&self) -> io::Result<u64> {
        Ok(self.file.metadata()?.len())
    }

    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<()> {
        super::source::read_exact_at(&self.file, buf, offset)
    }

    fn write_at(&self, offset: u64, data: &[u8]) -> io::Result<()> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileExt;
            self.file.write_all_at(data, offset)
        }
        #[cfg(windows)]
        {
            use std::os::windows::fs::FileExt;
            let mut done = 0usize;
            while done < data.len() {
                let n = self.file.seek_write(&data[done..], offset + done as u64)?;
                if n == 0 {
                    return Err(io::ErrorKind::WriteZero.into());
                }
                done += n;
            }
            Ok(())
        }
    }

    fn sync(&self) -> io::Result<()> {
        self.file.sync_all()
    }

    fn set_len(&self, len: u64) -> io::Result<()> {
        self.file.set_len(len)
    }

    fn name(&self) -> &Path {
        &self.path
    }

    fn oldest_reader(&self, up_to: u64) -> io::Result<Option<u64>> {
        super::lock::oldest_reader(&self.file, up_to)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_while_the_first_holds_the_file() {
        let f = tempfile::NamedTempFile::new().unwrap();
        let first = FileIo::open(f.path()).unwrap();
        let second = FileIo::open(f.path()).unwrap_err();
        assert_eq!(second.kind(), io::ErrorKind::WouldBlock, "{second}");
        drop(first);
        FileIo::open(f.path()).unwrap();
    }
}
