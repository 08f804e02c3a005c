//! What an input may claim before fmrh believes it: a memory budget for the build, a ceiling
//! on samples, and a ceiling on samples per byte of input.
//!
//! A header is a promise the file may not keep. A 525 KB GeoTIFF can declare 65536² `f32`
//! samples whose tiles all point at one small deflate stream: every tile decodes, and a
//! reader that believes the header sizes a 16 GiB grid. So every reader checks the declared
//! grid here, right after its header and before any buffer is sized from it:
//!
//! * **The budget.** Building holds the grid and the model beside it: about
//!   [`BUILD_BYTES_PER_SAMPLE`] bytes a sample at peak (measured: 4.8 on Puget Sound 4k from
//!   `.f32` and from a deflate GeoTIFF; 6 leaves room for 16-bit sources, whose raw samples
//!   sit beside the `f32` grid while they convert). A grid whose build would need more than
//!   the budget ([`IngestLimits::max_memory`], by default half of the machine's memory) is
//!   refused with the figures, before anything is read.
//! * **The proportion.** Past [`RATIO_FLOOR`] samples (small grids cost little whatever they
//!   claim), a grid that declares more than [`IngestLimits::max_samples_per_byte`] samples a
//!   byte of input (256 by default) is refused as out of all proportion to its bytes, in the
//!   spirit of Pillow's `MAX_IMAGE_PIXELS`. Real DEMs take 0.1 to 10 samples a byte (Puget
//!   Sound 4k as a deflate GeoTIFF: 3.6; an SRTM `.hgt.gz` of open sea, the extreme: ~500,
//!   but its 13 M samples are under the floor). The bombs above take 529 to 8,192.
//!
//! Both are the user's to raise (`--max-memory`, `--max-samples-per-byte`, 0 for no
//! ceiling) when a file really is that large or that uniform.

use std::path::Path;

use crate::error::{Error, Result};

/// Peak bytes a build holds per sample of its grid (see the module doc).
pub const BUILD_BYTES_PER_SAMPLE: u64 = 6;

/// Grids of at most this many samples (2^24, 64 MiB of `f32`) pass the proportion check
/// whatever their bytes: what they can cost is small.
pub const RATIO_FLOOR: u64 = 1 << 24;

/// The default ceiling on declared samples per byte of input.
pub const DEFAULT_SAMPLES_PER_BYTE: f64 = 256.0;

/// What a memory budget defaults to when the machine's memory cannot be read.
const UNKNOWN_MACHINE_MEMORY: u64 = 8 << 30;

/// The limits an input's declared size is checked against.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IngestLimits {
    /// Bytes a build may hold (a build takes about 6 bytes a sample); `None`: half of the
    /// machine's memory, or of its cgroup's limit where that is less.
    pub max_memory: Option<u64>,
    /// Declared samples per byte of input allowed past 2^24 samples (smaller grids pass
    /// whatever their bytes); `None`: 256; `0` or infinite: no ceiling.
    pub max_samples_per_byte: Option<f64>,
}

impl IngestLimits {
    /// No ceilings but the format's own (for tools that know their input).
    pub fn none() -> Self {
        IngestLimits {
            max_memory: Some(u64::MAX),
            max_samples_per_byte: Some(0.0),
        }
    }

    /// The memory budget in bytes.
    pub fn budget(&self) -> u64 {
        self.max_memory.unwrap_or_else(|| machine_memory() / 2)
    }

    /// Whether a build of `samples` samples fits the budget.
    pub fn holds(&self, samples: u64) -> bool {
        samples.saturating_mul(BUILD_BYTES_PER_SAMPLE) <= self.budget()
    }

    /// Checks a grid of `width × height` samples that `path`, of `input_bytes` bytes,
    /// declares, before anything is sized from it.
    pub fn check_declared(
        &self,
        path: &Path,
        width: u64,
        height: u64,
        input_bytes: u64,
    ) -> Result<()> {
        let samples = width.saturating_mul(height);
        if !self.holds(samples) {
            let (need, budget) = (samples.saturating_mul(BUILD_BYTES_PER_SAMPLE), self.budget());
            return Err(Error::TooLarge {
                what: path.display().to_string(),
                detail: format!(
                    "{width} x {height} samples need about {} to build ({BUILD_BYTES_PER_SAMPLE} \
                     bytes a sample), more than the memory budget of {} (--max-memory; by \
                     default half of this machine's {}). Raise it, or build a dataset of it \
                     (fmrh dataset build -o DIR FILE), which reads a GeoTIFF or .f32 in \
                     windows that fit the budget",
                    human(need),
                    human(budget),
                    human(machine_memory())
                ),
            });
        }
        self.check_proportion(path, width, height, input_bytes)
    }

    /// Checks only that `width × height` declared samples are in proportion to the
    /// `input_bytes` of `path` (a reader of windows, which never holds the whole grid, checks
    /// each window against the budget instead).
    pub fn check_proportion(
        &self,
        path: &Path,
        width: u64,
        height: u64,
        input_bytes: u64,
    ) -> Result<()> {
        let samples = width.saturating_mul(height);
        let ceiling = self
            .max_samples_per_byte
            .unwrap_or(DEFAULT_SAMPLES_PER_BYTE);
        if samples > RATIO_FLOOR && ceiling > 0.0 && ceiling.is_finite() {
            // Exact in f64: both are below 2^53 in any file that passed the format's limits,
            // and a ratio is all that is compared.
            let ratio = samples as f64 / input_bytes.max(1) as f64;
            if ratio > ceiling {
                return Err(Error::input(
                    path,
                    format!(
                        "declares {width} x {height} samples in {input_bytes} bytes: {ratio:.0} \
                         samples a byte, out of all proportion to its data (real DEMs take at \
                         most a few dozen; a decompression bomb takes thousands). Refused before \
                         decoding; --max-samples-per-byte {} accepts it",
                        ratio.ceil()
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The machine's memory in bytes: the least of `MemTotal` and the cgroup's limit where
/// Linux says; 8 GiB where nothing says.
pub fn machine_memory() -> u64 {
    let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        m.lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map(|kb| kb.saturating_mul(1024))
    });
    // cgroup v2, then v1; "max" (no limit) does not parse.
    let cgroup = ["/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"]
        .iter()
        .find_map(|p| std::fs::read_to_string(p).ok()?.trim().parse::<u64>().ok());
    match (total, cgroup) {
        (Some(t), Some(c)) => t.min(c),
        (Some(t), None) => t,
        (None, Some(c)) => c,
        (None, None) => UNKNOWN_MACHINE_MEMORY,
    }
}

/// Parses a byte size: a number with an optional `K`, `M`, `G` or `T` (powers of 1024, an
/// optional `B` or `iB` after it), e.g. `12G`, `512MiB`, `1500000000`.
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let upper = t.to_ascii_uppercase();
    let body = upper
        .strip_suffix("IB")
        .or_else(|| upper.strip_suffix('B'))
        .unwrap_or(&upper);
    let (digits, shift) = match body.chars().last() {
        Some('K') => (&body[..body.len() - 1], 10),
        Some('M') => (&body[..body.len() - 1], 20),
        Some('G') => (&body[..body.len() - 1], 30),
        Some('T') => (&body[..body.len() - 1], 40),
        _ => (body, 0),
    };
    let value: f64 = digits
        .trim()
        .parse()
        .map_err(|_| format!("{text:?}: expected a size such as 12G, 512M or 1500000000"))?;
    let bytes = value * (1u64 << shift) as f64;
    if !bytes.is_finite() || bytes < 1.0 || bytes >= u64::MAX as f64 {
        return Err(format!("{text:?}: expected a size of at least one byte"));
    }
    Ok(bytes as u64)
}

/// `bytes` for a person: `1.5 GiB`.
fn human(bytes: u64) -> String {
    let b = bytes as f64;
    match bytes {
        0..=1023 => format!("{bytes} B"),
        1024..=1_048_575 => format!("{:.1} KiB", b / 1024.0),
        1_048_576..=1_073_741_823 => format!("{:.1} MiB", b / 1_048_576.0),
        _ => format!("{:.1} GiB", b / 1_073_741_824.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_in_powers_of_1024() {
        assert_eq!(parse_size("12G"), Ok(12 << 30));
        assert_eq!(parse_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_size("1.5k"), Ok(1536));
        assert_eq!(parse_size("1500000000"), Ok(1_500_000_000));
        for bad in ["", "G", "-1G", "0", "12X", "nan", "1e30T"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_budget_and_the_proportion_refuse_what_they_should_and_only_that() {
        let p = Path::new("x.tif");
        let limits = IngestLimits {
            max_memory: Some(6 << 20),
            max_samples_per_byte: None,
        };
        // 1 Mi samples cost 6 MiB: at the budget, allowed; one row more is not.
        assert!(limits.check_declared(p, 1024, 1024, 1).is_ok());
        assert!(matches!(
            limits.check_declared(p, 1024, 1025, 1 << 30),
            Err(Error::TooLarge { .. })
        ));
        let roomy = IngestLimits {
            max_memory: Some(u64::MAX),
            max_samples_per_byte: None,
        };
        // Past the floor, 256 samples a byte is allowed and more is not.
        let (w, h) = (8192u64, 4096u64);
        assert!(roomy.check_declared(p, w, h, w * h / 256).is_ok());
        assert!(matches!(
            roomy.check_declared(p, w, h, w * h / 256 - 1),
            Err(Error::Input { .. })
        ));
        // Under the floor, any proportion.
        assert!(roomy.check_declared(p, 4096, 4096, 1).is_ok());
        // 0 lifts the ceiling.
        let lifted = IngestLimits {
            max_samples_per_byte: Some(0.0),
            ..roomy
        };
        assert!(lifted.check_declared(p, w, h, 1).is_ok());
        assert!(IngestLimits::none().check_declared(p, 1 << 16, 1 << 16, 1).is_ok());
    }
}
