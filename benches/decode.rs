//! Decode throughput per block encoding, on the payloads real containers store: how many
//! nanoseconds one core spends per decoded sample, for each encoding id of
//! `format-spec/container.md` §7, beside what the same samples cost pco alone and zlib
//! inflate (issue 44: ≤ 4 ns per sample for every encoding).
//!
//! For each DEM of `benches/common/dems.rs` (Puget Sound 1k bundled; Puget Sound 4k and
//! SRTM1 S46W066 from `../shared/data` when present), and dem_hills (float heights, from
//! `../shared/data`), it builds the default container, then
//! takes every stored payload (each physical block and each node's grid) with the grid it
//! is coded against, decoded once beforehand, as a reader holding its ancestors has it. Per
//! encoding it times, on one thread, the median of 5 passes over those payloads:
//!
//! - **payload**: `format::payload::decode`, the stored bytes to the layout a reader draws
//!   (length field, samples' code, stand-ins or void bitmap), what a scene pays per block
//!   once its ancestors are decoded;
//! - **codec**: the samples' code alone (`codec::decode` or `codec::parent::decode_against`
//!   into a reused buffer), the part the encoding decides;
//! - **codec, baseline kernels**: the same with the decoders' row kernels forced to their
//!   baseline x86-64 build (`codec::with_baseline_kernels`) where the CPU would run their AVX2
//!   build, the passes alternated with the previous column's;
//! - **coder alone**: only the residual stream inside that code, decoded by its coder: pco
//!   (encodings 2 to 8, into a new vector) or format 7's tANS stream (9 to 15, into a
//!   reused buffer), the floor under the encoding;
//! - **inflate**: the same samples as raw little-endian `f32`, DEFLATE-coded (flate2,
//!   default level), inflated: a COG tile's decoder without its predictor.
//!
//! `FMRH_CODER_STUDY=1` prints instead, per DEM and encoding, the residual streams coded by
//! the candidate coder (`fmrh::codec::tans`, planned for format 7) beside pco: bytes, and ns a number decoded, the
//! two decoders' passes alternated (`FMRH_CODER_LOOP=DEM:ID` adds 10 s of the candidate
//! alone on those streams, to profile); then a table of the lattice streams rebuilt into
//! samples by the planar rule after pco, after the candidate, and fused with the candidate.
//!
//! `FMRH_PREDICT_STUDY=1` prints instead, per DEM, encoding 5's blocks rebuilt by two
//! stand-alone kernels, the parent interpolated from its heights in `f64` (format 6) and from
//! its lattice codes in `i32` (a candidate for format 7), ns a sample, passes alternated,
//! beside the codec's own decoding of the same payloads (`common/predict.rs`).
//!
//! `FMRH_RECODE_STUDY=tans` (or `=pco`) prints instead, per DEM and stored encoding, the
//! same payloads coded again with that coder (`tans`: as format 7's writer codes them,
//! residuals in the tANS stream, encodings 9 to 15, pco where they do not fit; `pco`: as
//! format 6's did, encodings 2 to 8; alone or against the same grid, the smaller, as the writer
//! keeps), beside the stored ones: bytes a sample, the encodings they became, and ns a decoded
//! sample for the codec and the whole payload, the two codings' passes alternated. Since the
//! writer writes format 7, `=pco` is the comparison with format 6.
//!
//! Every payload is checked bit for bit against its first decoding before it is timed.
//! Times are ns per decoded sample; on a noisy machine read the ratios within a row.
//!
//!     cargo bench --bench decode

#[path = "common/dems.rs"]
mod dems;
#[path = "common/predict.rs"]
mod predict;
#[path = "common/tans.rs"]
mod tans;

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::sync::Arc;
use std::time::Instant;

use fmrh::codec::tans::{self as coder, Decoder};
use fmrh::codec::{self, voids, Encoding};
use fmrh::format::payload::{self, ParentGrid, Placement};
use fmrh::store::Store;

/// The codes the bench's payloads are decoded with: every one (it reads files of every
/// version this reader writes or has written, and recodes them as format 7).
const ALL_CODES: payload::Codes = payload::Codes::PcoOrTans;

/// One stored payload and all it decodes with.
#[derive(Clone)]
struct Sample {
    stored: Vec<u8>,
    placement: Placement,
    parent: Option<Arc<ParentGrid>>,
    /// Values its samples' code holds (a grid thinned by area: its kept columns).
    coded: usize,
    /// Samples along a row of the code.
    width: usize,
    /// Its decoded layout, for the check.
    layout: Vec<u8>,
}

impl Sample {
    fn code(&self) -> &[u8] {
        let len = u32::from_le_bytes([
            self.stored[0],
            self.stored[1],
            self.stored[2],
            self.stored[3],
        ]) as usize;
        &self.stored[4..4 + len]
    }

    fn encoding(&self) -> Encoding {
        Encoding::of(self.code()).expect("an encoding id")
    }

    fn decode_codec(&self, out: &mut [f32]) {
        let code = self.code();
        match &self.parent {
            None => codec::decode(code, self.width, out).expect("decodes"),
            Some(p) => {
                let (cols, rows) = self.placement.axes();
                codec::parent::decode_against(
                    code,
                    codec::parent::Axes {
                        cols: &cols,
                        rows: &rows,
                    },
                    p.parent(),
                    out,
                )
                .expect("decodes")
            }
        }
    }

    /// The pco stream inside the samples' code, and its number type: `None` for the
    /// encodings without one (raw, constant).
    fn pco_stream(&self) -> Option<(&[u8], char)> {
        let code = self.code();
        let body = &code[1..];
        let (n, w) = (self.coded, self.width);
        fn after_voids(b: &[u8], n: usize, w: usize) -> &[u8] {
            voids::read(b[0], &b[1..], n, w).expect("voids").1
        }
        match self.encoding() {
            Encoding::Raw | Encoding::Constant => None,
            Encoding::FloatPco => Some((body, 'f')),
            Encoding::FloatPredicted => Some((body, 'u')),
            Encoding::Lattice | Encoding::LatticeFromParent | Encoding::LatticePlanarFromParent => {
                Some((after_voids(&body[8..], n, w), 'i'))
            }
            Encoding::FloatFromParent | Encoding::FloatPlanarFromParent => {
                Some((after_voids(body, n, w), 'u'))
            }
            // tANS (format 7): no pco stream.
            _ => None,
        }
    }

    /// The tANS stream inside the samples' code (format 7's encodings 9 to 15), after a
    /// lattice code's common factor: `None` for the others.
    fn tans_stream(&self) -> Option<&[u8]> {
        let code = self.code();
        let body = &code[1..];
        let (n, w) = (self.coded, self.width);
        fn after_voids(b: &[u8], n: usize, w: usize) -> &[u8] {
            voids::read(b[0], &b[1..], n, w).expect("voids").1
        }
        fn after_factor(b: &[u8]) -> &[u8] {
            let len = b.iter().position(|&x| x & 0x80 == 0).expect("a factor") + 1;
            &b[len..]
        }
        match self.encoding() {
            Encoding::FloatPredictedTans => Some(body),
            Encoding::LatticeTans
            | Encoding::LatticeFromParentTans
            | Encoding::LatticePlanarFromParentTans
            | Encoding::LatticeFromParentCodes => Some(after_factor(after_voids(&body[8..], n, w))),
            Encoding::FloatFromParentTans | Encoding::FloatPlanarFromParentTans => {
                Some(after_voids(body, n, w))
            }
            _ => None,
        }
    }
}

/// Decodes the tANS stream `stream` alone (its codes, no residual rebuilt) into `out`,
/// which is at least as long as its count; the count of codes.
fn tans_alone(decoder: &mut Decoder, stream: &[u8], out: &mut [u32]) -> usize {
    let (mut count, mut shift) = (0usize, 0);
    for &b in stream.iter().take(5) {
        count |= usize::from(b & 0x7f) << shift;
        shift += 7;
        if b & 0x80 == 0 {
            break;
        }
    }
    decoder
        .decode(stream, &mut out[..count], |v| v)
        .expect("a stored stream decodes");
    count
}

fn pco_alone(stream: &[u8], kind: char) -> usize {
    use pco::standalone::simple_decompress;
    match kind {
        'i' => simple_decompress::<i64>(stream).expect("pco").len(),
        'u' => simple_decompress::<u32>(stream).expect("pco").len(),
        _ => simple_decompress::<f32>(stream).expect("pco").len(),
    }
}

/// Decodes the pco stream `src` of exactly `out.len()` numbers into `out`, as the codec does
/// (no allocation sized by the stream).
fn pco_into<T: pco::data_types::Number>(src: &[u8], out: &mut [T]) {
    use pco::standalone::{DecompressorItem, FileDecompressor};
    let (file, mut rest) = FileDecompressor::new(src).expect("pco");
    let mut done = 0;
    loop {
        match file.chunk_decompressor::<T, &[u8]>(rest).expect("pco") {
            DecompressorItem::Chunk(mut chunk) => {
                let n = chunk.n();
                chunk.read(&mut out[done..done + n]).expect("pco");
                done += n;
                rest = chunk.into_src();
            }
            DecompressorItem::EndOfData(_) => return,
        }
    }
}

/// One residual stream of the coder study: pco's bytes, the candidate's, and the codes.
struct Stream<'a> {
    pco: &'a [u8],
    kind: char,
    codes: Vec<u32>,
    /// The candidate's stream.
    candidate: Vec<u8>,
    /// The bytes its encoding stores before the stream: the factor's LEB128 (lattice).
    prefix: usize,
    factor: i64,
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// `FMRH_CODER_STUDY=1`: the residual streams of each encoding coded by the candidate
/// (`fmrh::codec::tans`) beside pco: bytes, and ns a number decoded (passes alternated).
fn coder_study(dem: &str, by: &BTreeMap<u8, Vec<&Sample>>, fusion: &mut Vec<String>) {
    use pco::standalone::simple_decompress;
    for (id, group) in by {
        let mut streams = Vec::new();
        let mut skipped = 0usize;
        for (pco, kind) in group.iter().filter_map(|s| s.pco_stream()) {
            // The lattice residuals divided by their greatest common divisor first (pco finds
            // such a multiplier too: Puget 4k's are all multiples of 256), which the
            // candidate's encodings store before the stream (counted below as its LEB128).
            let (codes, factor): (Option<Vec<u32>>, i64) = match kind {
                'i' => {
                    let r = simple_decompress::<i64>(pco).expect("pco");
                    let g = r.iter().fold(0u64, |g, &x| gcd(g, x.unsigned_abs())).max(1) as i64;
                    let codes = r
                        .iter()
                        .map(|&x| u32::try_from(tans::zigzag(x / g)).ok())
                        .collect();
                    (codes, g)
                }
                'u' => (Some(simple_decompress::<u32>(pco).expect("pco")), 1),
                _ => (None, 1),
            };
            let Some(codes) = codes else {
                skipped += 1;
                continue;
            };
            if codes.is_empty() {
                continue; // no numbers: pco's empty stream is all either would store
            }
            let mut candidate = Vec::new();
            coder::encode(&codes, &mut candidate);
            let mut back = vec![0u32; codes.len()];
            Decoder::default()
                .decode(&candidate, &mut back, |v| v)
                .expect("the coder's own stream");
            assert_eq!(back, codes, "{dem}: the candidate coder lost a code");
            let prefix = match kind {
                'i' => (64 - factor.leading_zeros() as usize).div_ceil(7).max(1),
                _ => 0,
            };
            streams.push(Stream {
                pco,
                kind,
                codes,
                candidate,
                prefix,
                factor,
            });
        }
        if streams.is_empty() {
            continue;
        }
        if std::env::var("FMRH_CODER_LOOP").is_ok_and(|l| l == format!("{dem}:{id}")) {
            // To profile the candidate alone: its decoding of these streams for 10 s.
            let mut decoder = Decoder::default();
            let mut out = vec![0u32; 1 << 17];
            let t = Instant::now();
            while t.elapsed().as_secs_f64() < 10.0 {
                for s in &streams {
                    let decoded = decoder.decode(&s.candidate, &mut out[..s.codes.len()], |z| z);
                    std::hint::black_box((&out, decoded.is_ok()));
                }
            }
        }
        let numbers: usize = streams.iter().map(|s| s.codes.len()).sum();
        let pco_bytes: usize = streams.iter().map(|s| s.pco.len()).sum();
        let cand_bytes: usize = streams.iter().map(|s| s.prefix + s.candidate.len()).sum();
        let (mut wide, mut narrow) = (vec![0i64; 1 << 17], vec![0u32; 1 << 17]);
        let (mut wide2, mut narrow2) = (wide.clone(), narrow.clone());
        let mut decoder = Decoder::default();
        let (pco_t, cand_t) = timed_pair(
            || {
                for s in &streams {
                    let n = s.codes.len();
                    match s.kind {
                        'i' => pco_into(s.pco, &mut wide[..n]),
                        _ => pco_into(s.pco, &mut narrow[..n]),
                    }
                    std::hint::black_box((&wide, &narrow));
                }
            },
            || {
                for s in &streams {
                    let n = s.codes.len();
                    let decoded = match s.kind {
                        // As pco gives them: the residual, not its zigzag code.
                        'i' => decoder.decode(&s.candidate, &mut wide2[..n], |z| {
                            tans::residual(z) * s.factor
                        }),
                        _ => decoder.decode(&s.candidate, &mut narrow2[..n], |z| z),
                    };
                    std::hint::black_box((&wide2, &narrow2, decoded.is_ok()));
                }
            },
        );
        // Where the lattice residuals share a factor: pco on them divided by it (what a writer
        // whose `q` took the factor in would store), beside pco as stored.
        let divided: Vec<(Vec<u8>, usize, &[u8])> = streams
            .iter()
            .filter(|s| s.kind == 'i' && s.factor > 1)
            .map(|s| {
                let r: Vec<i64> = s.codes.iter().map(|&z| tans::residual(z)).collect();
                let config = pco::ChunkConfig::default().with_delta_spec(pco::DeltaSpec::NoOp);
                let coded = pco::standalone::simple_compress(&r, &config).expect("pco");
                (coded, r.len(), s.pco)
            })
            .collect();
        if !divided.is_empty() {
            let (mut a, mut b) = (vec![0i64; 1 << 17], vec![0i64; 1 << 17]);
            let (as_stored, after) = timed_pair(
                || {
                    for (_, n, stored) in &divided {
                        pco_into(stored, &mut a[..*n]);
                        std::hint::black_box(&a);
                    }
                },
                || {
                    for (coded, n, _) in &divided {
                        pco_into(coded, &mut b[..*n]);
                        std::hint::black_box(&b);
                    }
                },
            );
            let stored: usize = divided.iter().map(|d| d.2.len()).sum();
            let recoded: usize = divided.iter().map(|d| d.0.len()).sum();
            let numbers: usize = divided.iter().map(|d| d.1).sum();
            println!(
                "| {dem} | {id}, pco on residuals divided by their common factor | {} | | | {stored} | {:.3} | {:.2} | {:.2} (pco) | {:.2} |",
                divided.len(),
                recoded as f64 / stored as f64,
                1e9 * as_stored / numbers as f64,
                1e9 * after / numbers as f64,
                after / as_stored,
            );
        }
        let lattice: Vec<&Stream> = streams.iter().filter(|s| s.kind == 'i').collect();
        if !lattice.is_empty() {
            fusion.push(fused_rebuild(dem, *id, &lattice));
        }
        let ns = |t: f64| 1e9 * t / numbers as f64;
        println!(
            "| {dem} | {id} {:?} | {} | {} | {} | {} | {:.3} | {:.2} | {:.2} | {:.2} |",
            Encoding::from_id(*id).expect("an id"),
            streams.len(),
            skipped,
            numbers,
            pco_bytes,
            cand_bytes as f64 / pco_bytes as f64,
            ns(pco_t),
            ns(cand_t),
            cand_t / pco_t,
        );
    }
}

/// The lattice streams of one encoding rebuilt into samples by encoding 2's planar rule (each
/// stream taken as a square grid where its length is a square, else one row: the work of
/// encodings 2 and 7, not their exact layout), three ways: pco then the rebuild, the
/// candidate then the rebuild, and the candidate fused with it (`tans::decode_planar`). The three are checked bit for bit against each other first; a row of ns
/// a number, the three passes alternated.
fn fused_rebuild(dem: &str, id: u8, streams: &[&Stream]) -> String {
    let q = 0.1;
    let width = |n: usize| {
        let w = (n as f64).sqrt() as usize;
        if w * w == n {
            w
        } else {
            n
        }
    };
    let mut decoder = Decoder::default();
    let mut r = vec![0i64; 1 << 17];
    let mut above = vec![0i64; 1 << 17];
    let (mut out, mut check) = (vec![0f32; 1 << 17], vec![0f32; 1 << 17]);
    let same_bits = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(a, b)| a.to_bits() == b.to_bits());
    for s in streams {
        let (n, w) = (s.codes.len(), width(s.codes.len()));
        pco_into(s.pco, &mut r[..n]);
        above[..w].fill(0);
        tans::planar(&r[..n], w, q, &mut above[..w], &mut check[..n]);
        decoder
            .decode(&s.candidate, &mut r[..n], |z| tans::residual(z) * s.factor)
            .expect("the coder's own stream");
        above[..w].fill(0);
        tans::planar(&r[..n], w, q, &mut above[..w], &mut out[..n]);
        assert!(
            same_bits(&out[..n], &check[..n]),
            "{dem}: the candidate's rebuild differs"
        );
        above[..w].fill(0);
        tans::decode_planar(
            &mut decoder,
            &s.candidate,
            s.factor,
            w,
            q,
            &mut above[..w],
            &mut out[..n],
        );
        assert!(
            same_bits(&out[..n], &check[..n]),
            "{dem}: the fused rebuild differs"
        );
    }
    let mut pass = |way: usize| {
        for s in streams {
            let (n, w) = (s.codes.len(), width(s.codes.len()));
            above[..w].fill(0);
            match way {
                0 => {
                    pco_into(s.pco, &mut r[..n]);
                    tans::planar(&r[..n], w, q, &mut above[..w], &mut out[..n]);
                }
                1 => {
                    let decoded =
                        decoder.decode(&s.candidate, &mut r[..n], |z| tans::residual(z) * s.factor);
                    std::hint::black_box(decoded.is_ok());
                    tans::planar(&r[..n], w, q, &mut above[..w], &mut out[..n]);
                }
                _ => tans::decode_planar(
                    &mut decoder,
                    &s.candidate,
                    s.factor,
                    w,
                    q,
                    &mut above[..w],
                    &mut out[..n],
                ),
            }
            std::hint::black_box(&out);
        }
    };
    let mut times = [Vec::new(), Vec::new(), Vec::new()];
    for way in 0..3 {
        pass(way); // warm
    }
    for _ in 0..5 {
        for (way, t) in times.iter_mut().enumerate() {
            let start = Instant::now();
            pass(way);
            t.push(start.elapsed().as_secs_f64());
        }
    }
    let numbers: usize = streams.iter().map(|s| s.codes.len()).sum();
    let [a, b, c] = times.map(|t| 1e9 * median(t) / numbers as f64);
    format!(
        "| {dem} | {id} | {} | {numbers} | {a:.2} | {b:.2} | {c:.2} | {:.2} | {:.2} |",
        streams.len(),
        b / a,
        c / a
    )
}

/// Every payload of `store`, with the grid it is coded against.
fn payloads(store: &Store) -> Vec<Sample> {
    let domain = *store.domain();
    let finest = domain.finest_level();
    let mut out = Vec::new();
    let mut push = |stored: Vec<u8>, placement: Placement, parent: Option<Arc<ParentGrid>>| {
        let layout = payload::decode(&stored, &placement, parent.as_deref(), ALL_CODES)
            .expect("a payload decodes");
        let (cols, rows) = placement.axes();
        out.push(Sample {
            stored,
            placement,
            parent,
            coded: cols.len() * rows.len(),
            width: cols.len(),
            layout,
        });
    };
    for node in store.nodes().expect("nodes") {
        if node.level >= finest {
            continue;
        }
        let stored = store.payload(node.payload).expect("reads").into_owned();
        let parent = store
            .grid_against_node(&node)
            .expect("its parent")
            .map(|(i, p)| store.parent_grid(i, &p).expect("parent grid"));
        push(stored, Placement::grid(&domain, &node), parent);
    }
    let (bx, by) = domain.nodes_across(finest);
    for y in 0..by {
        for x in 0..bx {
            if !domain.exists(finest, x, y) {
                continue;
            }
            let Ok(info) = store.stored_block(x, y) else {
                continue;
            };
            let rect = domain
                .footprint(finest, x, y)
                .intersect(&domain.data_rect())
                .expect("inside the data");
            let stored = store.payload(info.payload).expect("reads").into_owned();
            let parent = store
                .against_node(x, y, &info)
                .expect("its parent")
                .map(|(i, p)| store.parent_grid(i, &p).expect("parent grid"));
            push(stored, Placement::block(rect, info.void_count), parent);
        }
    }
    out
}

/// `s` coded again with residuals by `coder`, as a writer does: alone, and against its
/// grid when it has one, the smaller kept (a tie goes to alone).
fn recoded(s: &Sample, coder: codec::Coder) -> Sample {
    let coding = payload::Coding {
        coder,
        ..payload::Coding::default()
    };
    let alone = payload::encode(&s.layout, &s.placement, coding, None).expect("codes");
    let against = s
        .parent
        .as_ref()
        .and_then(|p| payload::encode(&s.layout, &s.placement, coding, Some(p)));
    let (stored, parent) = match against {
        Some(a) if a.len() < alone.len() => (a, s.parent.clone()),
        _ => (alone, None),
    };
    let again =
        payload::decode(&stored, &s.placement, parent.as_deref(), ALL_CODES).expect("decodes");
    assert_eq!(again, s.layout, "a recoded payload decoded differently");
    Sample {
        stored,
        parent,
        ..s.clone()
    }
}

/// The samples' codes of `all` decoded into `buf`.
fn codecs<'a>(all: impl Iterator<Item = &'a Sample>, buf: &mut [f32]) {
    for s in all {
        s.decode_codec(&mut buf[..s.coded]);
        std::hint::black_box(&buf);
    }
}

/// The payloads of `all` decoded to their layouts.
fn payloads_decoded<'a>(all: impl Iterator<Item = &'a Sample>) {
    for s in all {
        std::hint::black_box(
            payload::decode(&s.stored, &s.placement, s.parent.as_deref(), ALL_CODES)
                .expect("decodes"),
        );
    }
}

/// `FMRH_RECODE_STUDY=CODER`: each stored encoding's payloads beside the same coded again
/// with `coder` (tANS: format 7's writer; pco: format 6's), passes alternated.
fn recode_study(dem: &str, by: &BTreeMap<u8, Vec<&Sample>>, coder: codec::Coder) {
    let (mut bytes, mut t, mut samples) = ([0usize; 2], [0.0f64; 4], 0usize);
    for (id, group) in by {
        let tans: Vec<Sample> = group.iter().map(|s| recoded(s, coder)).collect();
        let mut became: BTreeMap<u8, usize> = BTreeMap::new();
        for s in &tans {
            *became.entry(s.encoding() as u8).or_default() += 1;
        }
        let n: usize = group.iter().map(|s| s.coded).sum();
        let b = [
            group.iter().map(|s| s.stored.len()).sum::<usize>(),
            tans.iter().map(|s| s.stored.len()).sum(),
        ];
        let (mut buf, mut buf2) = (vec![0f32; 1 << 16], vec![0f32; 1 << 16]);
        let (c6, c7) = timed_pair(
            || codecs(group.iter().copied(), &mut buf),
            || codecs(tans.iter(), &mut buf2),
        );
        let (p6, p7) = timed_pair(
            || payloads_decoded(group.iter().copied()),
            || payloads_decoded(tans.iter()),
        );
        let ns = |x: f64| 1e9 * x / n as f64;
        println!(
            "| {dem} | {id} {:?} | {} | {n} | {:.3} | {:.3} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            Encoding::from_id(*id).expect("an id"),
            group.len(),
            b[0] as f64 / n as f64,
            b[1] as f64 / n as f64,
            became
                .iter()
                .map(|(e, c)| format!("{e}: {c}"))
                .collect::<Vec<_>>()
                .join(", "),
            ns(c6),
            ns(c7),
            c7 / c6,
            ns(p6),
            ns(p7),
            p7 / p6,
        );
        bytes[0] += b[0];
        bytes[1] += b[1];
        for (slot, x) in t.iter_mut().zip([c6, c7, p6, p7]) {
            *slot += x;
        }
        samples += n;
    }
    let ns = |x: f64| 1e9 * x / samples as f64;
    println!(
        "| {dem} | all | {} | {samples} | {:.3} | {:.3} | {:.3}× bytes | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
        by.values().map(Vec::len).sum::<usize>(),
        bytes[0] as f64 / samples as f64,
        bytes[1] as f64 / samples as f64,
        bytes[1] as f64 / bytes[0] as f64,
        ns(t[0]),
        ns(t[1]),
        t[1] / t[0],
        ns(t[2]),
        ns(t[3]),
        t[3] / t[2],
    );
}

fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// The median over 5 passes of `pass`, in seconds.
fn timed(mut pass: impl FnMut()) -> f64 {
    pass(); // warm
    median(
        (0..5)
            .map(|_| {
                let t = Instant::now();
                pass();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// [`timed`] of two passes, alternated (on a noisy machine, side by side): their medians.
fn timed_pair(mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64) {
    a(); // warm
    b();
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    for _ in 0..5 {
        for (pass, times) in [(&mut a as &mut dyn FnMut(), &mut ta), (&mut b, &mut tb)] {
            let t = Instant::now();
            pass();
            times.push(t.elapsed().as_secs_f64());
        }
    }
    (median(ta), median(tb))
}

/// `FMRH_PREDICT_STUDY=1`: encoding 5's blocks of `dem` rebuilt by the `f64` and the `i32`
/// kernel of `common/predict.rs`, checked bit for bit, then timed side by side (three
/// alternated medians of five), beside the codec decoding the same payloads (a median of
/// five after each).
fn predict_study(dem: &str, by: &BTreeMap<u8, Vec<&Sample>>) {
    let Some(group) = by.get(&(Encoding::LatticeFromParent as u8)) else {
        return;
    };
    let mut blocks = Vec::new();
    let mut used = Vec::new();
    for s in group {
        let mut out = vec![0f32; s.coded];
        s.decode_codec(&mut out);
        let code = s.code();
        let q = f64::from_le_bytes(code[1..9].try_into().expect("a step"));
        if let Some(b) = predict::Block::new(&out, s.width, q) {
            assert!(
                predict::check(&b),
                "{dem}: a kernel of the study lost a sample"
            );
            blocks.push(b);
            used.push(*s);
        }
    }
    if blocks.is_empty() {
        return;
    }
    let n: usize = blocks.iter().map(|b| b.len()).sum();
    let blocks = &blocks;
    let kernel = |integer: bool| {
        let (mut scratch, mut out) = (predict::Scratch::default(), vec![0f32; 1 << 17]);
        move || {
            for b in blocks {
                predict::run(integer, b, &mut scratch, &mut out[..b.len()]);
                std::hint::black_box(&out);
            }
        }
    };
    let (mut float, mut integer) = (kernel(false), kernel(true));
    let ns = |t: f64| 1e9 * t / n as f64;
    let mut buf = vec![0f32; 1 << 17];
    for _ in 0..3 {
        let (f, i) = timed_pair(&mut float, &mut integer);
        let codec = median(
            (0..5)
                .map(|_| {
                    let t = Instant::now();
                    for s in &used {
                        s.decode_codec(&mut buf[..s.coded]);
                        std::hint::black_box(&buf);
                    }
                    t.elapsed().as_secs_f64()
                })
                .collect(),
        );
        println!(
            "| {dem} | {} | {n} | {:.2} | {:.2} | {:.2} | {:.2} |",
            blocks.len(),
            ns(codec),
            ns(f),
            ns(i),
            i / f
        );
    }
}

/// The code of `group` decoded round after round, rounds of the kernels' AVX2 build (where
/// the CPU has it) alternating with rounds of their baseline build: each one's best round's
/// ns a sample.
fn codec_loop(group: &[&Sample]) -> (f64, f64) {
    let mut buf = vec![0f32; 1 << 16];
    let mut round = || {
        let t = Instant::now();
        let mut n = 0usize;
        while t.elapsed().as_secs_f64() < 0.5 {
            for s in group {
                s.decode_codec(&mut buf[..s.coded]);
                std::hint::black_box(&buf);
                n += s.coded;
            }
        }
        1e9 * t.elapsed().as_secs_f64() / n as f64
    };
    let (mut wide, mut baseline) = (f64::MAX, f64::MAX);
    for _ in 0..12 {
        wide = wide.min(round());
        baseline = baseline.min(codec::with_baseline_kernels(&mut round));
    }
    (wide, baseline)
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let study = std::env::var_os("FMRH_CODER_STUDY").is_some();
    let recode = std::env::var("FMRH_RECODE_STUDY")
        .ok()
        .map(|c| match c.as_str() {
            "pco" => codec::Coder::Pco,
            _ => codec::Coder::Tans,
        });
    if recode.is_some() {
        println!(
            "| DEM | stored encoding | payloads | samples | bytes/sample | recoded bytes/sample | recoded encodings (payloads) | codec ns | recoded codec ns | recoded / stored | payload ns | recoded payload ns | recoded / stored |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    } else if study {
        println!(
            "| DEM | encoding | streams | left to pco | numbers | pco bytes | candidate / pco bytes | pco ns a number | candidate ns a number | candidate / pco time |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|");
    } else {
        println!(
        "| DEM | encoding | payloads | samples | bytes/sample | payload ns | codec ns | codec ns, baseline kernels | coder alone ns | inflate ns | payload / inflate |"
    );
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
    }
    let mut fusion = Vec::new();
    let mut all_dems = dems::dems();
    // Float heights off any lattice (encodings 3, 4, 6 and 8), when ../shared/data has them.
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    match fmrh::ingest::load(
        &root.join("../shared/data/gdal-rs-dem-hills/dem_hills.json"),
        &fmrh::ingest::IngestOptions::default(),
    ) {
        Ok(hf) => all_dems.push(dems::Dem::new("dem_hills", hf, 10.0)),
        Err(e) => eprintln!("skipping dem_hills: {e} (../shared/data)"),
    }
    // `FMRH_DECODE_LOOP=DEM:ID` (e.g. `puget-4k:7`): only that DEM's payloads of encoding ID,
    // their code decoded over and over for 12 s (to profile, e.g. under `perf record`), and
    // the best of twelve half-second rounds printed, for the kernels' AVX2 and baseline
    // builds in alternate rounds.
    let only = std::env::var("FMRH_DECODE_LOOP").ok();
    for dem in all_dems {
        if only
            .as_ref()
            .is_some_and(|o| !o.starts_with(&format!("{}:", dem.name)))
        {
            continue;
        }
        let path = dem.build(dir.path());
        let store = Store::open(&path).expect("opens");
        let all = payloads(&store);
        let mut by: BTreeMap<u8, Vec<&Sample>> = BTreeMap::new();
        for s in &all {
            by.entry(s.encoding() as u8).or_default().push(s);
        }
        if study {
            coder_study(dem.name, &by, &mut fusion);
            continue;
        }
        if let Some(coder) = recode {
            recode_study(dem.name, &by, coder);
            continue;
        }
        if std::env::var_os("FMRH_PREDICT_STUDY").is_some() {
            predict_study(dem.name, &by);
            continue;
        }
        let mut totals = [0.0f64; 5];
        let mut total_samples = 0usize;
        for (id, group) in &by {
            if let Some(o) = &only {
                if o.ends_with(&format!(":{id}")) {
                    let (wide, baseline) = codec_loop(group);
                    println!(
                        "{o}: codec {wide:.3} ns a sample, {baseline:.3} with the kernels' \
                         baseline build (best of 12 rounds each, alternated)"
                    );
                }
                continue;
            }
            let samples: usize = group.iter().map(|s| s.coded).sum();
            let bytes: usize = group.iter().map(|s| s.stored.len()).sum();
            // Checked once, bit for bit, against the first decoding.
            for s in group {
                let again =
                    payload::decode(&s.stored, &s.placement, s.parent.as_deref(), ALL_CODES)
                        .expect("decodes");
                assert_eq!(
                    again, s.layout,
                    "{}: a payload decoded differently",
                    dem.name
                );
            }
            let payload_t = timed(|| {
                for s in group {
                    std::hint::black_box(
                        payload::decode(&s.stored, &s.placement, s.parent.as_deref(), ALL_CODES)
                            .expect("decodes"),
                    );
                }
            });
            let decode_all = |buf: &mut [f32]| {
                for s in group {
                    s.decode_codec(&mut buf[..s.coded]);
                    std::hint::black_box(&buf);
                }
            };
            let (mut buf, mut buf2) = (vec![0f32; 1 << 16], vec![0f32; 1 << 16]);
            let (codec_t, codec_baseline_t) = timed_pair(
                || decode_all(&mut buf),
                || codec::with_baseline_kernels(|| decode_all(&mut buf2)),
            );
            let streams: Vec<(&[u8], char)> = group.iter().filter_map(|s| s.pco_stream()).collect();
            let tans_streams: Vec<&[u8]> = group.iter().filter_map(|s| s.tans_stream()).collect();
            let (mut decoder, mut codes) = (Decoder::default(), vec![0u32; 1 << 16]);
            let pco_t = timed(|| {
                for (stream, kind) in &streams {
                    std::hint::black_box(pco_alone(stream, *kind));
                }
                for stream in &tans_streams {
                    std::hint::black_box(tans_alone(&mut decoder, stream, &mut codes));
                }
            });
            let deflated: Vec<(Vec<u8>, usize)> = group
                .iter()
                .map(|s| {
                    let raw = &s.layout[..4 * s.coded.min(s.layout.len() / 4)];
                    let mut e =
                        flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                    e.write_all(raw).expect("deflate");
                    (e.finish().expect("deflate"), raw.len())
                })
                .collect();
            let mut raw = vec![0u8; 1 << 18];
            let inflate_t = timed(|| {
                for (z, n) in &deflated {
                    let mut d = flate2::read::ZlibDecoder::new(&z[..]);
                    d.read_exact(&mut raw[..*n]).expect("inflates");
                    std::hint::black_box(&raw);
                }
            });
            let ns = |t: f64| 1e9 * t / samples as f64;
            for (slot, t) in
                totals
                    .iter_mut()
                    .zip([payload_t, codec_t, codec_baseline_t, pco_t, inflate_t])
            {
                *slot += t;
            }
            total_samples += samples;
            println!(
                "| {} | {} {:?} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {:.2} | {:.2} |",
                dem.name,
                id,
                Encoding::from_id(*id).expect("an id"),
                group.len(),
                samples,
                bytes as f64 / samples as f64,
                ns(payload_t),
                ns(codec_t),
                ns(codec_baseline_t),
                if streams.is_empty() && tans_streams.is_empty() {
                    "-".to_string()
                } else {
                    format!("{:.2}", ns(pco_t))
                },
                ns(inflate_t),
                payload_t / inflate_t,
            );
        }
        let ns = |t: f64| 1e9 * t / total_samples as f64;
        println!(
            "| {} | all | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            dem.name,
            all.len(),
            total_samples,
            all.iter().map(|s| s.stored.len()).sum::<usize>() as f64 / total_samples as f64,
            ns(totals[0]),
            ns(totals[1]),
            ns(totals[2]),
            ns(totals[3]),
            ns(totals[4]),
            totals[0] / totals[4],
        );
    }
    if study {
        println!(
            "\nThe lattice streams rebuilt into samples by the planar rule, ns a number:\n\n\
             | DEM | encoding | streams | numbers | pco, then rebuild | candidate, then rebuild | candidate fused with the rebuild | candidate then / pco then | fused / pco then |"
        );
        println!("|---|---|---|---|---|---|---|---|---|");
        for row in fusion {
            println!("{row}");
        }
    }
}
