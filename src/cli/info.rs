//! `fmrh info`: what a container holds and where its bytes go.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::crs::Crs;
use serde::Serialize;

use crate::geoid::VerticalDatum;
use crate::heightfield::Georeference;
use crate::store::Layout;
use crate::Error;

#[derive(clap::Args)]
pub struct InfoArgs {
    /// The container, or a dataset's directory.
    file: PathBuf,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `info --json` prints. The golden vectors in `format-spec/vectors/` pin it.
#[derive(Serialize)]
struct Info {
    format_version: String,
    txn_id: u64,
    /// The state was committed while a writer had the file open and it was not closed
    /// cleanly since (format §3, §11.4).
    recovery_needed: bool,
    /// Transactions have replaced payloads (format §7).
    payload_slack: bool,
    commit_slot: u8,
    page_size: u32,
    file_length: u64,
    width: u32,
    height: u32,
    block_size: u32,
    levels: u8,
    finest_level: u8,
    padded_side: u64,
    padding_samples: u64,
    valid_samples: u64,
    void_samples: u64,
    /// The lowest and highest valid height (the root's range); none when every sample is void.
    height_range: Option<[f32; 2]>,
    spacing_m: Option<[f64; 2]>,
    georeference: Option<GeoInfo>,
    units: Option<String>,
    source_format: String,
    /// What the heights are above (format 6.1; older files: the reader's convention).
    vertical_datum: VerticalDatum,
    delta_min: f64,
    max_error: f64,
    /// The storage step heights were kept to (format 2.1), or null when bit for bit.
    precision: Option<f64>,
    /// How far a stored height may be from its source (0 when bit for bit).
    storage_error: f64,
    /// Whether coarse grids may be stored thinned by area (format 6).
    thinned_by_area: bool,
    /// Coarse grids stored thinned by area: every k-th column only.
    thinned_grids: u64,
    nodes: u64,
    nodes_per_level: Vec<u64>,
    physical_blocks: u64,
    clusters: Vec<ClusterInfo>,
    sections: Sections,
}

#[derive(Serialize)]
struct GeoInfo {
    crs: Option<String>,
    origin: [f64; 2],
    step: [f64; 2],
    /// The outer edges of the samples' cells in CRS units: `[min x, min y, max x, max y]`.
    bounds: [f64; 4],
    /// The same in degrees, `[west, south, east, north]`: for a geographic CRS the bounds
    /// themselves, for a projected CRS whose EPSG code is known the box around the
    /// bounds' edges projected back (16 points an edge, as their sides may curve).
    lon_lat_bounds: Option<[f64; 4]>,
}

/// A CRS for the text report: a WKT shown by its name and what fmrh made of it, the EPSG
/// code whose datum, projection and parameters it has, or that none has (the JSON report
/// has the WKT whole).
fn crs_label(crs: &str) -> String {
    if crs.contains('[') {
        let name = Crs::wkt_name(crs).map_or_else(String::new, |n| format!("\"{n}\" "));
        match Crs::from_wkt(crs) {
            Ok(Crs {
                epsg: Some(code), ..
            }) => format!("{name}(WKT, the CRS of EPSG:{code})"),
            Ok(_) => format!(
                "{name}(WKT fmrh cannot place on the ground: no EPSG code has its datum, \
                 projection and parameters; no lon/lat)"
            ),
            Err(e) => format!("{name}(WKT fmrh cannot read: {e})"),
        }
    } else {
        crs.to_owned()
    }
}

/// The longitude/latitude box of `bounds` (`[min x, min y, max x, max y]`) in CRS `name`.
fn lon_lat_bounds(name: &str, b: [f64; 4]) -> Option<[f64; 4]> {
    if name == "geographic (arc-seconds)" {
        return Some(b.map(|v| v / 3600.0));
    }
    let crs = Crs::parse(name)?;
    const STEPS: u32 = 16;
    let edges: Vec<[f64; 2]> = (0..=STEPS)
        .flat_map(|i| {
            let t = f64::from(i) / f64::from(STEPS);
            let (x, y) = (b[0] + t * (b[2] - b[0]), b[1] + t * (b[3] - b[1]));
            [[x, b[1]], [x, b[3]], [b[0], y], [b[2], y]]
        })
        .collect();
    let out = crs.to_lon_lat_all(&edges)?.into_iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |o, [lon, lat]| [o[0].min(lon), o[1].min(lat), o[2].max(lon), o[3].max(lat)],
    );
    Some(out)
}

impl GeoInfo {
    fn of(g: &Georeference, width: u32, height: u32) -> GeoInfo {
        // The origin is the centre of sample (0, 0); a cell reaches half a step each way.
        let edges = |o: f64, step: f64, n: u32| {
            let (a, b) = (o - step / 2.0, o + (f64::from(n) - 0.5) * step);
            (a.min(b), a.max(b))
        };
        let (x0, x1) = edges(g.origin[0], g.step[0], width);
        let (y0, y1) = edges(g.origin[1], g.step[1], height);
        let bounds = [x0, y0, x1, y1];
        let lon_lat_bounds = g.crs.as_deref().and_then(|c| lon_lat_bounds(c, bounds));
        GeoInfo {
            crs: g.crs.clone(),
            origin: g.origin,
            step: g.step,
            bounds,
            lon_lat_bounds,
        }
    }
}

#[derive(Serialize)]
struct ClusterInfo {
    threshold: f64,
    max_error: f64,
    nodes: u64,
    index_depth: u16,
    index_pages: u64,
    edge_nodes: [u64; 4],
}

/// Bytes per section.
#[derive(Serialize)]
struct Sections {
    commit_slots: u64,
    dataset_header: u64,
    cluster_directory: u64,
    /// The top of the tree (format 6.2): a copy of the coarsest levels' node records.
    top: u64,
    node_table: u64,
    block_table: u64,
    free_list: u64,
    free_pages: u64,
    cluster_indexes: u64,
    adjacency_lists: u64,
    block_payloads: u64,
    grid_payloads: u64,
    payload_padding: u64,
    /// Stored bytes of the metadata bundle (format 3, §6.7): tables and blobs in it are
    /// counted here, not above.
    metadata_bundle: u64,
    /// Pages the bundle decompresses to.
    metadata_bundle_pages: u64,
}

impl Sections {
    fn of(l: &Layout) -> Sections {
        let p = u64::from(l.page_size);
        let index: u64 = l.cluster_index_pages.iter().sum();
        let adjacency = l.adjacency_pages;
        let metadata_pages = l.commit_pages
            + l.dataset_header_pages
            + l.cluster_directory_pages
            + l.top_pages
            + l.node_table_pages
            + l.block_table_pages
            + l.free_list_pages
            + l.free_pages
            + index
            + adjacency;
        Sections {
            commit_slots: l.commit_pages * p,
            dataset_header: l.dataset_header_pages * p,
            cluster_directory: l.cluster_directory_pages * p,
            top: l.top_pages * p,
            node_table: l.node_table_pages * p,
            block_table: l.block_table_pages * p,
            free_list: l.free_list_pages * p,
            free_pages: l.free_pages * p,
            cluster_indexes: index * p,
            adjacency_lists: adjacency * p,
            block_payloads: l.block_bytes,
            grid_payloads: l.grid_bytes,
            payload_padding: l
                .file_length
                .saturating_sub(metadata_pages * p + l.block_bytes + l.grid_bytes + l.bundle_bytes),
            metadata_bundle: l.bundle_bytes,
            metadata_bundle_pages: l.bundle_pages,
        }
    }
}

/// What `info --json` prints for a dataset.
#[derive(Serialize)]
struct DatasetInfo {
    kind: &'static str,
    manifest_version: String,
    txn_id: u64,
    commit_slot: u8,
    manifest_bytes: u64,
    /// Bytes of the adjacent-cluster tables in the manifest's state.
    adjacency_bytes: u64,
    /// What opening the dataset read: the manifest's slots and head.
    open_reads: u64,
    open_bytes: u64,
    columns: u64,
    rows: u64,
    tile_count: u64,
    spacing_m: Option<[f64; 2]>,
    georeference: Option<GeoInfo>,
    /// What the heights are above (its tiles', which agree).
    vertical_datum: VerticalDatum,
    seam: &'static str,
    /// The manifest and every tile file, as the file system says now (a commit in progress
    /// may have appended to them); `None` for a remote dataset, whose tiles' sizes would
    /// cost a request each.
    total_bytes: Option<u64>,
    tiles: Vec<TileInfo>,
}

#[derive(Serialize)]
struct TileInfo {
    index: u64,
    name: String,
    col0: u64,
    row0: u64,
    width: u32,
    height: u32,
    height_range: [f32; 2],
    pin: crate::format::manifest::StatePin,
    file_bytes: Option<u64>,
}

fn run_dataset(args: &InfoArgs) -> Result<ExitCode, Error> {
    use crate::format::manifest::{MANIFEST_MAJOR, SEAM_FIRST, SEAM_MEAN};
    let ds = crate::dataset::Dataset::open(&args.file)?;
    let open = ds.open_reads();
    let tiles = ds.tiles()?;
    let record = ds.state().record;
    let grid = ds.grid();
    // The state's manifest length, not the file's: a commit in progress appends pages that
    // belong to no published state yet, and `info` describes one state.
    let manifest_bytes = record.file_length.get();
    let tiles: Vec<TileInfo> = tiles
        .iter()
        .map(|t| TileInfo {
            index: t.index,
            name: t.name().to_string(),
            col0: t.rect().col0,
            row0: t.rect().row0,
            width: t.record.width.get(),
            height: t.record.height.get(),
            height_range: [t.record.min_height.get(), t.record.max_height.get()],
            pin: t.pin(),
            file_bytes: std::fs::metadata(ds.tile_path(t)).ok().map(|m| m.len()),
        })
        .collect();
    let to_u32 = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
    let info = DatasetInfo {
        kind: "dataset",
        manifest_version: format!("{MANIFEST_MAJOR}.{}", record.minor.get()),
        txn_id: ds.txn_id(),
        commit_slot: ds.state().slot,
        manifest_bytes,
        adjacency_bytes: record.adjacency_len.get(),
        open_reads: open.metadata_reads,
        open_bytes: open.metadata_bytes,
        columns: grid.col1 + 1,
        rows: grid.row1 + 1,
        tile_count: ds.tile_count(),
        spacing_m: ds.spacing_m(),
        georeference: ds
            .georeference()
            .map(|g| GeoInfo::of(&g, to_u32(grid.col1 + 1), to_u32(grid.row1 + 1))),
        vertical_datum: ds.vertical_datum()?,
        seam: match record.seam {
            SEAM_FIRST => "first",
            SEAM_MEAN => "mean",
            _ => "strict",
        },
        total_bytes: tiles
            .iter()
            .map(|t| t.file_bytes)
            .sum::<Option<u64>>()
            .map(|t| t + ds.manifest_len()),
        tiles,
    };
    if args.json {
        super::print_json(&info)?;
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "{}: fmrh dataset (manifest {}), txn {}, {} tiles, {}",
        args.file.display(),
        info.manifest_version,
        info.txn_id,
        info.tile_count,
        info.total_bytes
            .map_or("remote".to_string(), |b| format!("{b} bytes in all"))
    );
    println!("  grid        {} x {} samples", info.columns, info.rows);
    println!("  heights     above {}", datum_label(info.vertical_datum));
    match info.spacing_m {
        Some(s) => println!("  spacing     {} m x {} m", s[0], s[1]),
        None => println!("  spacing     unknown (scenes need --spacing)"),
    }
    if let Some(g) = &info.georeference {
        println!(
            "  georef      {} origin {:?} step {:?}",
            g.crs.as_deref().map_or("(no CRS)".into(), crs_label),
            g.origin,
            g.step
        );
        if let Some([w, s, e, n]) = g.lon_lat_bounds {
            println!("  lon/lat     {w} .. {e} E, {s} .. {n} N");
        }
    }
    println!("  seams       {}", info.seam);
    println!(
        "  manifest    {} bytes ({} of adjacent-cluster tables); opening read {} bytes in {} \
         reads",
        info.manifest_bytes, info.adjacency_bytes, info.open_bytes, info.open_reads
    );
    const SHOWN: usize = 20;
    for t in info.tiles.iter().take(SHOWN) {
        println!(
            "  {:>5} {:<28} columns {}..={}, rows {}..={}, heights {} .. {}, {} bytes",
            t.index,
            t.name,
            t.col0,
            t.col0 + u64::from(t.width) - 1,
            t.row0,
            t.row0 + u64::from(t.height) - 1,
            t.height_range[0],
            t.height_range[1],
            t.file_bytes.map_or("(missing)".into(), |b| b.to_string())
        );
    }
    if info.tiles.len() > SHOWN {
        println!(
            "  ... and {} more (--json lists them all)",
            info.tiles.len() - SHOWN
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `fmrh info`.
pub fn run(args: &InfoArgs) -> Result<ExitCode, Error> {
    if super::is_dataset(&args.file)? {
        return run_dataset(args);
    }
    if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        return report(args, &crate::store::Store::open_url(url)?);
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    report(args, &super::open(&args.file)?)
}

/// Reports on `store`.
fn report<S: crate::store::Source>(
    args: &InfoArgs,
    store: &crate::store::Store<S>,
) -> Result<ExitCode, Error> {
    let h = store.header();
    let d = h.domain;
    let nodes = store.nodes()?;
    let mut per_level = vec![0u64; usize::from(d.levels())];
    for n in &nodes {
        if let Some(c) = per_level.get_mut(usize::from(n.level)) {
            *c += 1;
        }
    }
    let layout = store.layout()?;
    let mut clusters = Vec::new();
    for (i, c) in store.clusters().iter().enumerate() {
        // The directory's runs count each edge list; no need to read the lists.
        let edge_nodes: [u64; 4] = std::array::from_fn(|e| c.edge_nodes(e).unwrap_or(0));
        clusters.push(ClusterInfo {
            threshold: c.threshold,
            max_error: c.max_error,
            nodes: c.nodes(),
            index_depth: c.index_depth(),
            index_pages: layout.cluster_index_pages[i],
            edge_nodes,
        });
    }
    let state = store.state();
    let info = Info {
        format_version: format!("{}.{}", state.format_version.0, state.format_version.1),
        txn_id: state.txn_id,
        recovery_needed: state.recovery_needed,
        payload_slack: state.payload_slack,
        commit_slot: state.commit_slot,
        page_size: state.page_size,
        file_length: state.file_length,
        width: d.width(),
        height: d.height(),
        block_size: d.block_size(),
        levels: d.levels(),
        finest_level: d.finest_level(),
        padded_side: d.side(),
        padding_samples: d.padding_samples(),
        valid_samples: h.valid_samples,
        void_samples: h.void_samples,
        height_range: nodes
            .first()
            .filter(|_| h.valid_samples > 0)
            .map(|root| [root.min_height, root.max_height]),
        spacing_m: h.metadata.spacing_m,
        georeference: h
            .metadata
            .georeference
            .as_ref()
            .map(|g| GeoInfo::of(g, d.width(), d.height())),
        units: h.metadata.units.clone(),
        source_format: h.metadata.source_format.clone(),
        vertical_datum: h.metadata.vertical_datum,
        delta_min: h.delta_min,
        max_error: h.max_error,
        precision: h.precision.map(|p| p.step()),
        storage_error: h.storage_error(),
        thinned_by_area: h.thinned_by_area,
        thinned_grids: nodes.iter().filter(|n| n.grid_thin > 0).count() as u64,
        nodes: h.node_count,
        nodes_per_level: per_level,
        physical_blocks: h.block_count,
        clusters,
        sections: Sections::of(&layout),
    };
    if args.json {
        super::print_json(&info)?;
    } else {
        print_info(&args.file, &info);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_info(path: &std::path::Path, i: &Info) {
    println!(
        "{}: fmrh {} container, txn {}, {} bytes in {}-byte pages",
        path.display(),
        i.format_version,
        i.txn_id,
        i.file_length,
        i.page_size
    );
    if i.recovery_needed {
        println!("  a writer did not close it cleanly: its next writer recovers it (fmrh recover)");
    }
    println!(
        "  grid        {} x {} samples ({} valid, {} void), from {}",
        i.width, i.height, i.valid_samples, i.void_samples, i.source_format
    );
    match i.height_range {
        Some([lo, hi]) => println!(
            "  heights     {lo} .. {hi} {} above {}",
            i.units.as_deref().unwrap_or("(units unknown)"),
            datum_label(i.vertical_datum)
        ),
        None => println!("  heights     none (every sample is void)"),
    }
    match i.spacing_m {
        Some(s) => println!("  spacing     {} m x {} m", s[0], s[1]),
        None => println!("  spacing     unknown (scenes need --spacing)"),
    }
    if let Some(g) = &i.georeference {
        println!(
            "  georef      {} origin {:?} step {:?}",
            g.crs.as_deref().map_or("(no CRS)".into(), crs_label),
            g.origin,
            g.step
        );
        let b = g.bounds;
        println!(
            "  bounds      x {} .. {}, y {} .. {} (CRS units)",
            b[0], b[2], b[1], b[3]
        );
        if let Some([w, s, e, n]) = g.lon_lat_bounds {
            println!("  lon/lat     {w} .. {e} E, {s} .. {n} N");
        }
    }
    println!(
        "  blocks      {} a side, {} levels, {} physical blocks, padded to {}",
        i.block_size, i.levels, i.physical_blocks, i.padded_side
    );
    println!(
        "  nodes       {} (per level {:?})",
        i.nodes, i.nodes_per_level
    );
    println!("  max error   {} (delta_min {})", i.max_error, i.delta_min);
    match i.precision {
        Some(q) => println!(
            "  precision   {q}: heights within {} of the source, included in every error",
            i.storage_error
        ),
        None => println!("  precision   lossless"),
    }
    if i.thinned_by_area {
        println!(
            "  thinning    by area: {} of {} coarse grids keep every k-th column",
            i.thinned_grids,
            i.nodes - i.nodes_per_level.last().copied().unwrap_or(0)
        );
    }
    println!("  clusters    {}", i.clusters.len());
    println!("      threshold    max error      nodes  index pages (depth)");
    for c in &i.clusters {
        println!(
            "  {:>13.6} {:>12.6} {:>10} {:>8} ({})",
            c.threshold, c.max_error, c.nodes, c.index_pages, c.index_depth
        );
    }
    let s = &i.sections;
    let total = i.file_length.max(1) as f64;
    println!("  bytes per section");
    for (name, bytes) in [
        ("block payloads", s.block_payloads),
        ("grid payloads", s.grid_payloads),
        ("payload padding", s.payload_padding),
        ("node table", s.node_table),
        ("block table", s.block_table),
        ("cluster indexes", s.cluster_indexes),
        ("adjacency lists", s.adjacency_lists),
        ("cluster directory", s.cluster_directory),
        ("top of the tree", s.top),
        ("dataset header", s.dataset_header),
        ("commit slots", s.commit_slots),
        ("free list", s.free_list),
        ("free pages", s.free_pages),
        ("metadata bundle", s.metadata_bundle),
    ] {
        println!(
            "    {name:<18} {bytes:>12}  {:>6.2}%",
            100.0 * bytes as f64 / total
        );
    }
    if s.metadata_bundle > 0 {
        // 5.0 stores a frame per page, read as lookups reach them (format §6.7).
        let framed = i
            .format_version
            .split('.')
            .next()
            .and_then(|m| m.parse::<u16>().ok())
            .is_some_and(|m| m >= 5);
        println!(
            "  the dataset header, directory and tables are in the bundle: {} pages, \
             compressed, {}",
            s.metadata_bundle_pages,
            if framed {
                "each read when first needed"
            } else {
                "read whole on open"
            }
        );
    }
}

/// What heights above `datum` are said to be above, in `info`'s text.
fn datum_label(datum: VerticalDatum) -> &'static str {
    match datum {
        VerticalDatum::Egm96 => "the EGM96 geoid",
        VerticalDatum::Egm2008 => "the EGM2008 geoid",
        VerticalDatum::Ellipsoid => "the WGS 84 ellipsoid",
        VerticalDatum::Unknown => "an unknown datum (--vertical-datum at build says which)",
    }
}
