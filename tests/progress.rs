//! Progress is reported honestly: every phase the library starts it finishes, phases do not
//! nest, and the units a phase advances add up to exactly the total it announced. Checked for
//! the model build (levels), the writer (payload bytes), `verify --full` (payload bytes,
//! blocks assembled, levels re-measured) and window reads (blocks).

use std::sync::Mutex;

use fmrh::heightfield::Heightfield;
use fmrh::model::{BuildOptions, Model};
use fmrh::progress::{Progress, Unit};
use fmrh::store::{verify_with_progress, FileSource, VerifyMode, WriteOptions};

/// A phase heard: `(name, total, unit, advanced, finished)`.
type Phase = (String, u64, Unit, u64, bool);

/// Records phases.
#[derive(Default)]
struct Recorder(Mutex<Vec<Phase>>);

impl Progress for Recorder {
    fn start(&self, phase: &str, total: u64, unit: Unit) {
        let mut p = self.0.lock().unwrap();
        if let Some(last) = p.last() {
            assert!(last.4, "{phase} started inside {}", last.0);
        }
        p.push((phase.to_owned(), total, unit, 0, false));
    }
    fn advance(&self, n: u64) {
        let mut p = self.0.lock().unwrap();
        let last = p.last_mut().expect("advance outside a phase");
        assert!(!last.4, "advance after {} finished", last.0);
        last.3 += n;
    }
    fn finish(&self) {
        let mut p = self.0.lock().unwrap();
        let last = p.last_mut().expect("finish outside a phase");
        last.4 = true;
    }
}

impl Recorder {
    /// The phases, each checked complete.
    fn phases(&self) -> Vec<(String, u64, Unit)> {
        self.0
            .lock()
            .unwrap()
            .iter()
            .map(|(name, total, unit, advanced, finished)| {
                assert!(finished, "{name} never finished");
                assert_eq!(advanced, total, "{name}: advanced {advanced} of {total}");
                (name.clone(), *total, *unit)
            })
            .collect()
    }
}

fn field() -> Heightfield {
    Heightfield::from_fn(300, 200, |x, y| {
        ((x * 7 + y * 3) % 41) as f32 + (x as f32).sqrt()
    })
    .unwrap()
}

#[test]
fn every_phase_finishes_and_adds_up() {
    let options = BuildOptions {
        block_size: 33,
        ..BuildOptions::default()
    };
    let rec = Recorder::default();
    let model = Model::build_with_progress(field(), &options, &rec).unwrap();
    let phases = rec.phases();
    assert_eq!(
        phases,
        vec![(
            "measuring levels".to_string(),
            u64::from(model.domain().levels()),
            Unit::Steps
        )]
    );

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.fmrh");
    let rec = std::sync::Arc::new(Recorder::default());
    let write = WriteOptions {
        progress: rec.clone(),
        ..WriteOptions::default()
    };
    let metadata = fmrh::heightfield::Metadata::default();
    fmrh::store::write_file(&model, &metadata, &path, &write, false).unwrap();
    let phases = rec.phases();
    assert_eq!(phases.len(), 1);
    assert_eq!(
        (phases[0].0.as_str(), phases[0].2),
        ("coding and writing payloads", Unit::Bytes)
    );
    assert!(phases[0].1 > 0);

    let rec = Recorder::default();
    let file = std::fs::File::open(&path).unwrap();
    let report = verify_with_progress(
        FileSource::new(file, &path).unwrap(),
        VerifyMode::Full,
        &rec,
    )
    .unwrap();
    assert!(report.valid, "{report:?}");
    let names: Vec<String> = rec.phases().into_iter().map(|p| p.0).collect();
    assert_eq!(
        names,
        ["checking payloads", "assembling blocks", "measuring levels"]
    );

    let store = fmrh::store::Store::open(&path).unwrap();
    let rec = Recorder::default();
    let window = fmrh::model::SampleRect {
        col0: 10,
        row0: 40,
        col1: 150,
        row1: 90,
    };
    let hf = store.read_window_with_progress(window, &rec).unwrap();
    assert_eq!(hf, store.read_window(window).unwrap());
    // Columns 10..=150 meet blocks 0..=4 (32 cells each), rows 40..=90 blocks 1..=2.
    assert_eq!(
        rec.phases(),
        vec![("assembling blocks".to_string(), 10, Unit::Steps)]
    );
}
