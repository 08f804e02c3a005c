//! Heightfields made in code: random ones of several characters for property tests, and the
//! named hard cases. All deterministic from a seed.

#![allow(dead_code)]

use fmrh::Heightfield;
use proptest::prelude::*;

/// splitmix64: a tiny deterministic generator, so a failing case is reproduced by its seed.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The characters of random terrain the property tests draw from.
#[derive(Clone, Copy, Debug)]
pub enum Character {
    /// Small integers: ties everywhere, many zero errors.
    SmallIntegers,
    /// Uniform noise.
    Noise,
    /// Smooth sine hills with a little noise.
    Hills,
    /// A vertical cliff at a random column.
    Cliff,
    /// Flat with a few spikes.
    Spikes,
    /// Constant.
    Flat,
}

pub fn character() -> impl Strategy<Value = Character> {
    prop_oneof![
        Just(Character::SmallIntegers),
        Just(Character::Noise),
        Just(Character::Hills),
        Just(Character::Cliff),
        Just(Character::Spikes),
        Just(Character::Flat),
    ]
}

/// A `w × h` field of `character`, with roughly `void_rate` of its samples void.
pub fn make(w: u32, h: u32, character: Character, void_rate: f64, seed: u64) -> Heightfield {
    let mut rng = Rng::new(seed);
    let (fx, fy, phase) = (rng.unit() * 0.5, rng.unit() * 0.5, rng.unit() * 6.0);
    let cliff_at = (rng.unit() * f64::from(w)) as u32;
    Heightfield::from_fn(w, h, |x, y| {
        let v = match character {
            Character::SmallIntegers => (rng.next_u64() % 4) as f32,
            Character::Noise => (rng.unit() * 100.0) as f32,
            Character::Hills => {
                (100.0 * (f64::from(x) * fx + phase).sin() * (f64::from(y) * fy).cos() + rng.unit())
                    as f32
            }
            Character::Cliff => {
                if x < cliff_at {
                    10.0
                } else {
                    500.0
                }
            }
            Character::Spikes => {
                if rng.next_u64().is_multiple_of(97) {
                    1000.0
                } else {
                    0.0
                }
            }
            Character::Flat => 42.0,
        };
        if rng.unit() < void_rate {
            f32::NAN
        } else {
            v
        }
    })
    .expect("generated fields are valid")
}

/// A random field for property tests: size, character, voids and seed all drawn.
pub fn any_field(max_side: u32) -> impl Strategy<Value = Heightfield> {
    (
        1..=max_side,
        1..=max_side,
        character(),
        prop_oneof![Just(0.0), Just(0.03), Just(0.3), Just(0.97)],
        any::<u64>(),
    )
        .prop_map(|(w, h, c, voids, seed)| make(w, h, c, voids, seed))
}
