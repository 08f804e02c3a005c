//! Transactions as a state machine (proptest-state-machine): random sequences of begin,
//! replace (fitting or not, with or without voids), commit, abort, crash with damage (also
//! during recovery), injected I/O failures, clean reopen, and snapshots taken and dropped,
//! each step checked against an in-memory model by the driver in `common/txn_driver.rs`:
//! the latest snapshot holds the committed samples, older snapshots keep theirs, a crash or
//! failure leaves the old or the new state in a file that verifies, and the stored model
//! equals a fresh build of the stored samples. Shrinking gives the shortest failing
//! sequence. Also: replacement equals rebuild as a plain property over random replacement
//! sequences on random terrains.

mod common;

use common::txn_driver::{Driver, Op};
use proptest::prelude::*;
use proptest_state_machine::{prop_state_machine, ReferenceStateMachine, StateMachineTest};

/// What the generator needs to know: whether a transaction is open, and whether it holds a
/// replacement (a commit to crash or fail needs something to write).
#[derive(Clone, Debug, Default)]
struct Shape {
    in_txn: bool,
    replaced: bool,
}

struct Reference;

const W: u32 = 41;
const H: u32 = 30;

/// Mostly patches that fit, some that overhang the data.
fn replace() -> impl Strategy<Value = Op> {
    let place = prop_oneof![
        4 => (0u16..(W as u16 - 12), 0u16..(H as u16 - 10), 1u8..12, 1u8..10),
        1 => (0u16..(W as u16 + 4), 0u16..(H as u16 + 4), 1u8..40, 1u8..30),
    ];
    (place, any::<u32>(), any::<bool>()).prop_map(|((col0, row0, width, height), seed, voids)| {
        Op::Replace {
            col0,
            row0,
            width,
            height,
            seed,
            voids,
        }
    })
}

impl ReferenceStateMachine for Reference {
    type State = Shape;
    type Transition = Op;

    fn init_state() -> BoxedStrategy<Shape> {
        Just(Shape::default()).boxed()
    }

    fn transitions(state: &Shape) -> BoxedStrategy<Op> {
        let crash = (
            0u16..80,
            any::<u64>(),
            proptest::option::weighted(0.3, (0u8..4, any::<u64>())),
        )
            .prop_map(|(after, damage, recovery)| Op::Crash {
                after,
                damage,
                recovery,
            });
        let fail = (any::<u8>(), any::<u8>(), any::<bool>())
            .prop_map(|(kind, nth, sticky)| Op::Fail { kind, nth, sticky });
        if state.in_txn && state.replaced {
            prop_oneof![
                4 => replace(),
                3 => Just(Op::Commit),
                1 => Just(Op::Abort),
                3 => crash,
                3 => fail,
                1 => Just(Op::Snapshot),
            ]
            .boxed()
        } else if state.in_txn {
            prop_oneof![
                6 => replace(),
                1 => Just(Op::Commit),
                1 => Just(Op::Abort),
                1 => Just(Op::Snapshot),
            ]
            .boxed()
        } else {
            prop_oneof![
                5 => Just(Op::Begin),
                1 => Just(Op::Reopen),
                1 => crash,
                2 => Just(Op::Snapshot),
                1 => any::<u8>().prop_map(Op::DropSnapshot),
            ]
            .boxed()
        }
    }

    fn apply(mut state: Shape, op: &Op) -> Shape {
        match op {
            Op::Begin => state.in_txn = true,
            Op::Replace { .. } => state.replaced = true,
            Op::Commit | Op::Abort | Op::Crash { .. } | Op::Fail { .. } | Op::Reopen => {
                state.in_txn = false;
                state.replaced = false;
            }
            _ => {}
        }
        state
    }
}

struct Transactions;

impl StateMachineTest for Transactions {
    type SystemUnderTest = Driver;
    type Reference = Reference;

    fn init_test(_: &Shape) -> Driver {
        Driver::new(W, H, 9)
    }

    fn apply(mut driver: Driver, _: &Shape, op: Op) -> Driver {
        driver.step(&op);
        driver
    }

    fn check_invariants(driver: &Driver, shape: &Shape) {
        assert_eq!(driver.in_txn(), shape.in_txn);
    }

    fn teardown(driver: Driver, _: Shape) {
        driver.check_full();
        eprintln!(
            "case: {} commits, {} crashes, {} I/O failures",
            driver.commits, driver.crashes, driver.failures
        );
    }
}

prop_state_machine! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        max_shrink_iters: 2000,
        .. ProptestConfig::default()
    })]
    #[test]
    fn transactions_match_the_model(sequential 1..60 => Transactions);
}

/// One replacement: a patch of some character and void rate, placed by fractions of the data.
fn edit() -> impl Strategy<Value = (f64, f64, f64, f64, common::fields::Character, f64, u64)> {
    (
        0.0..1.0f64,
        0.0..1.0f64,
        0.0..=1.0f64,
        0.0..=1.0f64,
        common::fields::character(),
        prop_oneof![Just(0.0), Just(0.1), Just(1.0)],
        any::<u64>(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// After any sequence of replacements (several per transaction, any terrain, voids
    /// anywhere, the whole dataset at once), the stored model equals a fresh build of the
    /// stored samples with the stored thresholds.
    #[test]
    fn replacement_equals_rebuild(
        field in common::fields::any_field(60),
        block in prop_oneof![Just(9u32), Just(17)],
        edits in proptest::collection::vec(edit(), 1..7),
        per_txn in 1usize..4,
    ) {
        use common::txn::{build_bytes, described, paste, samples_digest, digest_samples};
        use fmrh::model::Thresholds;
        use fmrh::store::io::SimDisk;
        use fmrh::store::Container;
        use fmrh::store::Store;

        let bytes = build_bytes(&field, block, &Thresholds::Ladder);
        let thresholds = common::txn::thresholds(&Store::from_bytes(bytes.clone()).unwrap());
        let (container, _) = Container::open_io(SimDisk::new(bytes)).unwrap();
        let (w, h) = (u64::from(field.width()), u64::from(field.height()));
        let mut expected = field.clone();
        for txn in edits.chunks(per_txn) {
            let mut writer = container.begin_write().unwrap();
            for &(fx, fy, fw, fh, character, voids, seed) in txn {
                let col0 = (fx * w as f64) as u64;
                let row0 = (fy * h as f64) as u64;
                let pw = (((w - col0) as f64 * fw) as u64).max(1);
                let ph = (((h - row0) as f64 * fh) as u64).max(1);
                let patch = common::fields::make(pw as u32, ph as u32, character, voids, seed);
                writer.replace_region(col0, row0, &patch).unwrap();
                expected = paste(&expected, col0, row0, &patch);
            }
            writer.commit().unwrap();
        }
        let now = container.read().unwrap();
        prop_assert_eq!(samples_digest(&now), digest_samples(expected.samples()));
        let fresh = build_bytes(&expected, block, &Thresholds::Explicit(thresholds));
        prop_assert!(described(&now) == described(&Store::from_bytes(fresh).unwrap()));
    }
}
