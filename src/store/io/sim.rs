//! A simulated disk that can lose power (for tests; the `testing` feature exports it).
//!
//! [`SimDisk`] keeps the durable image and the list of operations since the last sync. At a
//! crash ([`SimDisk::crash_image`]) every pending write is independently *kept*, *dropped* or
//! *torn* (each 512-byte sector written, left alone, or filled with garbage), and every
//! pending length change kept or dropped, in combinations drawn from a seed. It can also lose
//! power after the `n`th mutating operation ([`SimDisk::power_off_after`]), and fail chosen
//! operations ([`Fault`]) once or from then on, which is how the error paths of the commit
//! protocol are tested.

// An in-memory test device: offsets index a buffer already in memory, and garbage bytes are
// meant to be truncated random words.
#![allow(clippy::cast_possible_truncation)]

use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use super::Io;

/// The kinds of mutating operation, for fault injection and counting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum OpKind {
    /// `write_at`.
    Write,
    /// `sync`.
    Sync,
    /// `set_len`.
    SetLen,
}

/// Fail the `nth` (1-based) operation of `kind`; with `sticky`, every later one too.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fault {
    /// Which operations.
    pub kind: OpKind,
    /// The first one to fail, counting from 1.
    pub nth: u64,
    /// Whether every later operation of `kind` fails too.
    pub sticky: bool,
}

/// What happens to the operations pending at a crash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Damage {
    /// Every pending operation reached the disk.
    KeepAll,
    /// None did.
    DropAll,
    /// Each write kept, dropped or torn, each length change kept or dropped, from this seed.
    Random(u64),
}

/// The sector size torn writes are cut into.
pub const SECTOR: usize = 512;

#[derive(Clone, Debug)]
enum Pending {
    Write(u64, Vec<u8>),
    SetLen(u64),
}

#[derive(Debug, Default)]
struct SimState {
    durable: Vec<u8>,
    current: Vec<u8>,
    pending: Vec<Pending>,
    /// Mutating operations so far (write, sync, set_len), counting failed ones.
    ops: u64,
    counts: [u64; 3],
    power_off_after: Option<u64>,
    powered_off: bool,
    faults: Vec<Fault>,
}

/// An in-memory disk that records every write and sync and can crash at any point. Clones
/// share the same disk.
#[derive(Clone, Debug, Default)]
pub struct SimDisk {
    state: Arc<Mutex<SimState>>,
    name: PathBuf,
    power: Option<SimPower>,
}

#[derive(Debug, Default)]
struct PowerState {
    ops: u64,
    power_off_after: Option<u64>,
    powered_off: bool,
}

/// One power supply for several disks (the files of a dataset): their mutating operations
/// are counted together, and power goes off for all of them at once.
#[derive(Clone, Debug, Default)]
pub struct SimPower(Arc<Mutex<PowerState>>);

impl SimPower {
    /// A supply that stays on.
    pub fn new() -> SimPower {
        SimPower::default()
    }

    fn lock(&self) -> MutexGuard<'_, PowerState> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Loses power after `ops` more mutating operations on any of its disks.
    pub fn power_off_after(&self, ops: u64) {
        let mut s = self.lock();
        s.power_off_after = Some(s.ops + ops);
    }

    /// Mutating operations so far, on all its disks.
    pub fn ops(&self) -> u64 {
        self.lock().ops
    }

    /// Whether power is off.
    pub fn powered_off(&self) -> bool {
        self.lock().powered_off
    }

    /// Counts an operation; `false` when power is (now) off.
    fn tick(&self) -> bool {
        let mut s = self.lock();
        s.ops += 1;
        if s.powered_off || s.power_off_after.is_some_and(|at| s.ops > at) {
            s.powered_off = true;
        }
        !s.powered_off
    }
}

fn kind_index(k: OpKind) -> usize {
    match k {
        OpKind::Write => 0,
        OpKind::Sync => 1,
        OpKind::SetLen => 2,
    }
}

/// A small deterministic generator (SplitMix64) for damage patterns.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn apply(image: &mut Vec<u8>, op: &Pending) {
    match op {
        Pending::Write(offset, data) => {
            let end = *offset as usize + data.len();
            if image.len() < end {
                image.resize(end, 0);
            }
            image[*offset as usize..end].copy_from_slice(data);
        }
        Pending::SetLen(len) => image.resize(*len as usize, 0),
    }
}

impl SimDisk {
    /// A disk holding `bytes`, all durable.
    pub fn new(bytes: Vec<u8>) -> SimDisk {
        SimDisk {
            state: Arc::new(Mutex::new(SimState {
                durable: bytes.clone(),
                current: bytes,
                ..SimState::default()
            })),
            name: PathBuf::from("<simulated disk>"),
            power: None,
        }
    }

    /// A disk holding `bytes`, named `name`, on the shared supply `power`.
    pub fn on_power(bytes: Vec<u8>, name: &Path, power: &SimPower) -> SimDisk {
        SimDisk {
            name: name.to_path_buf(),
            power: Some(power.clone()),
            ..SimDisk::new(bytes)
        }
    }

    fn lock(&self) -> MutexGuard<'_, SimState> {
        // A panic while holding the lock leaves consistent state (every method mutates
        // after its checks), so a poisoned lock is still usable.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Loses power after `ops` more mutating operations: the next operations fail, as if the
    /// process had died there. The disk keeps its pending operations for
    /// [`SimDisk::crash_image`].
    pub fn power_off_after(&self, ops: u64) {
        let mut s = self.lock();
        s.power_off_after = Some(s.ops + ops);
    }

    /// Adds a fault.
    pub fn inject(&self, fault: Fault) {
        self.lock().faults.push(fault);
    }

    /// Mutating operations so far.
    pub fn ops(&self) -> u64 {
        self.lock().ops
    }

    /// Operations of `kind` so far.
    pub fn count(&self, kind: OpKind) -> u64 {
        self.lock().counts[kind_index(kind)]
    }

    /// Whether the disk has lost power.
    pub fn powered_off(&self) -> bool {
        self.lock().powered_off
    }

    /// The bytes reads see now.
    pub fn current(&self) -> Vec<u8> {
        self.lock().current.clone()
    }

    /// The bytes that survive a crash with `damage` to the operations since the last sync.
    pub fn crash_image(&self, damage: Damage) -> Vec<u8> {
        let s = self.lock();
        let mut image = s.durable.clone();
        let mut rng = match damage {
            Damage::Random(seed) => seed,
            _ => 0,
        };
        for op in &s.pending {
            match damage {
                Damage::KeepAll => apply(&mut image, op),
                Damage::DropAll => {}
                Damage::Random(_) => match (op, splitmix(&mut rng) % 3) {
                    (_, 0) => {}
                    (_, 1) => apply(&mut image, op),
                    (Pending::SetLen(_), _) => apply(&mut image, op),
                    (Pending::Write(offset, data), _) => {
                        // Torn: sector by sector, written, skipped or garbage.
                        let end = *offset as usize + data.len();
                        if image.len() < end && splitmix(&mut rng).is_multiple_of(2) {
                            image.resize(end, 0);
                        }
                        let mut at = 0usize;
                        while at < data.len() {
                            let start = *offset as usize + at;
                            let next = (start / SECTOR + 1) * SECTOR - *offset as usize;
                            let stop = next.min(data.len());
                            let fate = splitmix(&mut rng) % 3;
                            if fate != 0 {
                                if image.len() < *offset as usize + stop {
                                    image.resize(*offset as usize + stop, 0);
                                }
                                for (i, b) in data[at..stop].iter().enumerate() {
                                    image[start + i] = if fate == 1 {
                                        *b
                                    } else {
                                        splitmix(&mut rng) as u8
                                    };
                                }
                            }
                            at = stop;
                        }
                    }
                },
            }
        }
        image
    }

    /// Counts a mutating operation and decides whether it fails.
    fn begin(&self, s: &mut SimState, kind: OpKind) -> io::Result<()> {
        s.ops += 1;
        let i = kind_index(kind);
        s.counts[i] += 1;
        let n = s.counts[i];
        if self.power.as_ref().is_some_and(|p| !p.tick()) {
            s.powered_off = true;
        }
        if s.powered_off || s.power_off_after.is_some_and(|at| s.ops > at) {
            s.powered_off = true;
            return Err(io::Error::other("simulated power loss"));
        }
        let failing = s
            .faults
            .iter()
            .any(|f| f.kind == kind && (n == f.nth || (f.sticky && n > f.nth)));
        if failing {
            return Err(io::Error::other(format!("injected {kind:?} failure #{n}")));
        }
        Ok(())
    }
}

impl Io for SimDisk {
    fn len(&self) -> io::Result<u64> {
        Ok(self.lock().current.len() as u64)
    }

    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<()> {
        let s = self.lock();
        let range = usize::try_from(offset)
            .ok()
            .and_then(|o| Some(o..o.checked_add(buf.len())?))
            .filter(|r| r.end <= s.current.len())
            .ok_or_else(|| io::Error::new(io::ErrorKind::UnexpectedEof, "read past the end"))?;
        buf.copy_from_slice(&s.current[range]);
        Ok(())
    }

    fn write_at(&self, offset: u64, data: &[u8]) -> io::Result<()> {
        let mut s = self.lock();
        self.begin(&mut s, OpKind::Write)?;
        let op = Pending::Write(offset, data.to_vec());
        apply(&mut s.current, &op);
        s.pending.push(op);
        Ok(())
    }

    fn sync(&self) -> io::Result<()> {
        let mut s = self.lock();
        self.begin(&mut s, OpKind::Sync)?;
        let pending = std::mem::take(&mut s.pending);
        for op in &pending {
            apply(&mut s.durable, op);
        }
        Ok(())
    }

    fn set_len(&self, len: u64) -> io::Result<()> {
        let mut s = self.lock();
        self.begin(&mut s, OpKind::SetLen)?;
        let op = Pending::SetLen(len);
        apply(&mut s.current, &op);
        s.pending.push(op);
        Ok(())
    }

    fn name(&self) -> &Path {
        &self.name
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sync_makes_writes_durable() {
        let d = SimDisk::new(vec![0; 8]);
        d.write_at(0, &[1, 2]).unwrap();
        assert_eq!(d.crash_image(Damage::DropAll), vec![0; 8]);
        d.sync().unwrap();
        d.write_at(4, &[9]).unwrap();
        assert_eq!(d.crash_image(Damage::DropAll), vec![1, 2, 0, 0, 0, 0, 0, 0]);
        assert_eq!(d.crash_image(Damage::KeepAll), vec![1, 2, 0, 0, 9, 0, 0, 0]);
    }

    #[test]
    fn torn_writes_mix_sectors() {
        let d = SimDisk::new(vec![0; 4 * SECTOR]);
        d.write_at(0, &vec![7u8; 4 * SECTOR]).unwrap();
        let mut kinds = std::collections::HashSet::new();
        for seed in 0..200 {
            let img = d.crash_image(Damage::Random(seed));
            assert_eq!(img.len(), 4 * SECTOR);
            for s in img.chunks(SECTOR) {
                kinds.insert(if s.iter().all(|&b| b == 7) {
                    "new"
                } else if s.iter().all(|&b| b == 0) {
                    "old"
                } else {
                    "garbage"
                });
            }
        }
        assert_eq!(kinds.len(), 3, "{kinds:?}");
    }

    #[test]
    fn faults_and_power_loss() {
        let d = SimDisk::new(Vec::new());
        d.inject(Fault {
            kind: OpKind::Sync,
            nth: 2,
            sticky: false,
        });
        d.sync().unwrap();
        assert!(d.sync().is_err());
        d.sync().unwrap();
        d.power_off_after(1);
        d.write_at(0, &[1]).unwrap();
        assert!(d.write_at(1, &[1]).is_err());
        assert!(d.sync().is_err());
        assert!(d.powered_off());
        assert_eq!(d.crash_image(Damage::DropAll), Vec::<u8>::new());
    }
}
