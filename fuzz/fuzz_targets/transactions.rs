//! Fuzz target: random sequences of begin / replace / commit / abort / crash with damage
//! (also during recovery) / injected I/O failure / reopen / snapshots on a simulated disk,
//! checked step by step against an in-memory model by the same driver the proptest state
//! machine uses (`tests/common/txn_driver.rs`, included by path). Any violated property
//! (a state neither old nor new after a crash, a file that fails `verify --full`, a model
//! unequal to a fresh build, a snapshot that changed) panics.
//!
//! cargo fuzz run --sanitizer none transactions

#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../tests/common/txn_driver.rs"]
mod txn_driver;

use txn_driver::{Driver, Op};

/// Reads the ops: one selector byte each, then the bytes that op needs (zero when the input
/// runs out).
fn decode(data: &[u8]) -> Vec<Op> {
    let mut bytes = data.iter().copied();
    let mut next = move || bytes.next();
    let mut ops = Vec::new();
    while let Some(selector) = next() {
        let mut byte = || next().unwrap_or(0);
        let op = match selector % 10 {
            0 | 1 => Op::Begin,
            2..=4 => Op::Replace {
                col0: u16::from(byte()),
                row0: u16::from(byte()),
                width: byte() % 48,
                height: byte() % 40,
                seed: u32::from_le_bytes([byte(), byte(), byte(), byte()]),
                voids: byte() % 4 == 0,
            },
            5 => Op::Commit,
            6 => Op::Abort,
            7 => Op::Crash {
                after: u16::from(byte()),
                damage: u64::from(byte()) | u64::from(byte()) << 8,
                recovery: match byte() {
                    r if r % 3 == 0 => Some((r % 5, u64::from(byte()))),
                    _ => None,
                },
            },
            8 => Op::Fail {
                kind: byte(),
                nth: byte(),
                sticky: byte() % 2 == 0,
            },
            _ => match byte() % 3 {
                0 => Op::Reopen,
                1 => Op::Snapshot,
                _ => Op::DropSnapshot(byte()),
            },
        };
        ops.push(op);
        if ops.len() >= 64 {
            break;
        }
    }
    ops
}

fuzz_target!(|data: &[u8]| {
    let ops = decode(data);
    let mut driver = Driver::new(41, 30, 9);
    for op in &ops {
        driver.step(op);
    }
    driver.check_full();
});
