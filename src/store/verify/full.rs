//! Full mode: the semantics. Every cluster is its cut (I-13: cover, bound, minimality), the
//! adjacency lists are the cuts' edge nodes (I-14), and everything derived equals a fresh
//! build from the physical blocks (I-15).

use super::{Checks, Loaded};
use crate::curve::HilbertKey;
use crate::error::Result;
use crate::format::payload::GridView;
use crate::format::Invariant;
use crate::heightfield::Heightfield;
use crate::model::{cluster, BuildOptions, Model, ThinByArea, Thresholds, NO_PARENT};
use crate::progress::Progress;
use crate::store::write::tables::{clipped_grid, node_id};
use crate::store::{Source, Store};

pub(super) fn check_cuts<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = Invariant::ClusterIndex;
    let d = store.domain();
    let finest = d.finest_level();
    let (cols, rows) = d.nodes_across(finest);
    let total = u64::from(cols) * u64::from(rows);
    for (c, (info, entries)) in store.clusters().iter().zip(&l.indexes).enumerate() {
        let delta = info.threshold;
        let mut covered = 0u64;
        let mut prev_end = 0u64;
        for (k, e) in entries.iter().enumerate() {
            let at = format!("cluster {c} entry {k}");
            let Some(n) = l.nodes.get(e.node.get() as usize) else {
                continue;
            };
            let (key, level) = (n.key.get(), n.level);
            if key < prev_end {
                checks.fail(
                    id,
                    format!("{at}: overlaps the node before it (no overlap)"),
                );
            }
            prev_end = key.saturating_add(HilbertKey::span(finest, level));
            let side = 1u64 << (finest - level);
            let (x0, y0) = (u64::from(n.x.get()) * side, u64::from(n.y.get()) * side);
            covered += ((x0 + side).min(u64::from(cols)) - x0.min(u64::from(cols)))
                * ((y0 + side).min(u64::from(rows)) - y0.min(u64::from(rows)));
            let m = n.monotone_error.get();
            if m > delta {
                checks.fail(
                    id,
                    format!("{at}: e* {m} exceeds the threshold {delta} (bound)"),
                );
            }
            let parent = n.parent.get();
            if parent != NO_PARENT
                && l.nodes
                    .get(parent as usize)
                    .is_some_and(|p| p.monotone_error.get() <= delta)
            {
                checks.fail(
                    id,
                    format!("{at}: its parent already meets {delta} (minimality)"),
                );
            }
        }
        if covered != total {
            checks.fail(
                id,
                format!("cluster {c}: covers {covered} of {total} physical blocks (cover)"),
            );
        }
    }
}

pub(super) fn check_adjacency<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let d = store.domain();
    for (c, entries) in l.indexes.iter().enumerate() {
        let cut: Vec<u32> = entries.iter().map(|e| e.node.get()).collect();
        let want = cluster::edge_nodes_by(d, &cut, |i| {
            let n = &l.nodes[i as usize];
            d.footprint(n.level, n.x.get(), n.y.get())
        });
        for (edge, (stored, want)) in l.adjacency[c].iter().zip(want).enumerate() {
            if *stored != want {
                checks.fail(
                    Invariant::Adjacency,
                    format!(
                        "cluster {c} {} edge: {} nodes stored, {} touch it (or the order differs)",
                        cluster::EDGES[edge],
                        stored.len(),
                        want.len()
                    ),
                );
            }
        }
    }
    checks.pass(Invariant::Adjacency);
}

/// I-15: rebuilds the model from the physical blocks and compares everything derived.
pub(super) fn check_measured<S: Source>(
    store: &Store<S>,
    l: &Loaded,
    checks: &mut Checks,
    progress: &dyn Progress,
) -> Result<()> {
    let id = Invariant::Measured;
    let d = *store.domain();
    let finest = d.finest_level();
    let (cols, _) = d.nodes_across(finest);
    // Assemble the samples; blocks that share an edge must agree on it.
    let mut disagreements = Vec::new();
    let assembled = store.assemble(
        d.data_rect(),
        |x, y, n| disagreements.push((x, y, n)),
        progress,
    );
    let Some(samples) = checks.absorb(assembled)? else {
        return Ok(());
    };
    for (x, y, n) in disagreements {
        checks.fail(
            id,
            format!("block ({x}, {y}): {n} samples differ from its neighbours' copies"),
        );
    }
    let hf = match Heightfield::new(d.width(), d.height(), samples) {
        Ok(hf) => hf,
        Err(e) => {
            checks.fail(id, format!("stored samples: {e}"));
            return Ok(());
        }
    };
    let options = BuildOptions {
        block_size: d.block_size(),
        thresholds: Thresholds::Explicit(store.clusters().iter().map(|c| c.threshold).collect()),
        precision: store.header().precision,
        thin: match store.header().thinning() {
            Some(spacing) => ThinByArea::Spacing(spacing),
            None => ThinByArea::Off,
        },
    };
    let model = match Model::build_with_progress(hf, &options, progress) {
        Ok(m) => m,
        Err(e) => {
            checks.fail(id, format!("rebuilding: {e}"));
            return Ok(());
        }
    };
    let tree = model.tree();
    if tree.nodes().len() != l.nodes.len() {
        checks.fail(
            id,
            format!(
                "{} nodes stored, the blocks give {}",
                l.nodes.len(),
                tree.nodes().len()
            ),
        );
        return Ok(());
    }
    for (i, (s, n)) in l.nodes.iter().zip(tree.nodes()).enumerate() {
        let same = s.key.get() == n.key.0
            && s.level == n.level
            && s.child_mask == n.child_mask
            && s.static_error.get().to_bits() == n.static_error.to_bits()
            && s.monotone_error.get().to_bits() == n.monotone_error.to_bits()
            && s.min_height.get().to_bits() == n.min_height.to_bits()
            && s.max_height.get().to_bits() == n.max_height.to_bits()
            && s.valid_samples.get() == n.valid_samples
            && s.decode().grid_thin == if n.level < finest { n.thin } else { 0 };
        if !same {
            checks.fail(id, format!("node {i}: stored error/range/count/thinning differ from the blocks' (stored e {} e* {} thinned by 2^{}, measured e {} e* {} thinned by 2^{})", s.static_error.get(), s.monotone_error.get(), s.decode().grid_thin, n.static_error, n.monotone_error, n.thin));
            continue;
        }
        if n.level < finest {
            let node = s.decode();
            let Some(grid) = checks.absorb(store.grid(&node))? else {
                continue;
            };
            let index = node_id(i);
            let full = model.node_grid(index);
            let (clipped, gw, _) = clipped_grid(&model, index);
            let b = full.size;
            let ok = {
                let v: GridView<'_> = grid.view();
                node.grid_has_voids == clipped.void.iter().any(|&x| x)
                    && v.stored_width == gw
                    && v.stored()
                        .iter()
                        .zip(&clipped.heights)
                        .all(|(a, b)| a.get().to_bits() == b.to_bits())
                    && (0..b * b).all(|k| {
                        let (gi, gj) = (k % b, k / b);
                        v.is_void(gi, gj) == full.void[k as usize]
                            && v.height(gi, gj).to_bits() == full.heights[k as usize].to_bits()
                    })
            };
            if !ok {
                checks.fail(
                    id,
                    format!("node {i}: its grid is not the decimation of the blocks"),
                );
            }
        }
    }
    for (c, (mine, entries)) in model.clusters().iter().zip(&l.indexes).enumerate() {
        if mine.nodes.len() != entries.len()
            || mine
                .nodes
                .iter()
                .zip(entries)
                .any(|(a, e)| *a != e.node.get())
        {
            checks.fail(
                id,
                format!("cluster {c}: the stored cut differs from the rebuilt one"),
            );
        }
    }
    // Stand-ins: each void's mended height.
    let raster = model.raster();
    let mut parent = None;
    for (i, b) in l.blocks.iter().enumerate() {
        if b.void_count.get() == 0 {
            continue;
        }
        let (x, y) = super::block_xy(i, cols);
        let Some(block) = checks.absorb(store.block_reusing(x, y, &mut parent))? else {
            continue;
        };
        let view = block.view();
        let r = block.rect;
        let mut k = 0usize;
        let mut wrong = 0u64;
        for row in r.row0..=r.row1 {
            for col in r.col0..=r.col1 {
                if !raster.is_valid(col, row) {
                    let stored = view.stand_ins().get(k).map(|v| v.get().to_bits());
                    wrong += u64::from(stored != Some(raster.value(col, row).to_bits()));
                    k += 1;
                }
            }
        }
        if wrong > 0 {
            checks.fail(
                id,
                format!("block ({x}, {y}): {wrong} void stand-ins are not the mended heights"),
            );
        }
    }
    checks.pass(id);
    Ok(())
}
