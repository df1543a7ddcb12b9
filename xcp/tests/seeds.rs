//! The seed generator against the standard's own answer (NIST CAVP, HMAC_DRBG with SHA-256)
//! and against the attack that broke its predecessor: two consecutive seeds of the old
//! xorshift64* generator gave away its whole state and every later seed; the same attack finds
//! nothing in HMAC_DRBG's seeds.

use aer_xcp::seeds::SeedGenerator;

fn hex(text: &str) -> Vec<u8> {
    (0..text.len())
        .step_by(2)
        .map(|at| u8::from_str_radix(&text[at..at + 2], 16).expect("hex"))
        .collect()
}

/// CAVP's HMAC_DRBG.rsp, [SHA-256], no prediction resistance, no reseed, no personalization
/// and no additional input, COUNT = 0: instantiate, generate 1024 bits twice, the second is
/// ReturnedBits.
#[test]
fn the_generator_returns_nists_bits() {
    let entropy = hex("ca851911349384bffe89de1cbdc46e6831e44d34a4fb935ee285dd14b71a7488");
    let nonce = hex("659ba96c601dc69fc902940805ec0ca8");
    let expected = hex(concat!(
        "e528e9abf2dece54d47c7e75e5fe302149f817ea9fb4bee6f4199697d04d5b89",
        "d54fbb978a15b5c443c9ec21036d2460b6f73ebad0dc2aba6e624abf07745bc1",
        "07694bb7547bb0995f70de25d6b29e2d3011bb19d27676c07162c8b5ccde0668",
        "961df86803482cb37ed6d5c0bb8d50cf1f50d476aa0458bdaba806f48be9dcb8",
    ));
    // The nonce is part of the instantiation's seed material, after the entropy.
    let mut generator = SeedGenerator::new(&[entropy, nonce].concat(), &[]);
    let mut bits = [0u8; 128];
    generator.fill(&mut bits, &[]);
    generator.fill(&mut bits, &[]);
    assert_eq!(bits.to_vec(), expected);
}

/// xorshift64* as `SeedKey` drew seeds before: the low 48 bits of each output.
struct Xorshift(u64);

const MULTIPLIER: u64 = 0x2545_F491_4F6C_DD1D;
const LOW_48: u64 = (1 << 48) - 1;

impl Xorshift {
    fn step(state: u64) -> u64 {
        let mut x = state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        x
    }

    fn seed(&mut self) -> u64 {
        self.0 = Self::step(self.0);
        self.0.wrapping_mul(MULTIPLIER) & LOW_48
    }
}

/// The inverse of an odd number modulo 2^64 (Newton's iteration).
fn inverse(odd: u64) -> u64 {
    let mut inverse = odd;
    for _ in 0..6 {
        inverse = inverse.wrapping_mul(2u64.wrapping_sub(odd.wrapping_mul(inverse)));
    }
    inverse
}

/// The attack: a seed gives the low 48 bits of the state (the multiplier is odd); the 2^16
/// candidates for the rest are tried against the second seed, and a surviving state predicts
/// the third. `None` if no state explains both seeds.
fn predict_third(first: u64, second: u64) -> Option<u64> {
    let low = first.wrapping_mul(inverse(MULTIPLIER)) & LOW_48;
    (0..1u64 << 16)
        .map(|high| (high << 48) | low)
        .find(|&state| Xorshift::step(state).wrapping_mul(MULTIPLIER) & LOW_48 == second)
        .map(|state| {
            let next = Xorshift::step(Xorshift::step(state));
            next.wrapping_mul(MULTIPLIER) & LOW_48
        })
}

fn seed_as_u64(seed: [u8; 6]) -> u64 {
    let mut bytes = [0u8; 8];
    bytes[..6].copy_from_slice(&seed);
    u64::from_le_bytes(bytes)
}

#[test]
fn two_seeds_gave_the_old_generator_away_and_give_nothing_now() {
    // The old generator: the attack predicts the third seed from the first two.
    let mut old = Xorshift(0x1234_5678_9ABC_DEF1);
    let (first, second, third) = (old.seed(), old.seed(), old.seed());
    assert_eq!(predict_third(first, second), Some(third));

    // HMAC_DRBG: no xorshift state explains two of its seeds, so nothing is predicted.
    let mut generator = SeedGenerator::new(&[0x5A; 32], b"CCM 0123456789abcdef");
    let mut seeds = [[0u8; 6]; 3];
    for (at_us, seed) in seeds.iter_mut().enumerate() {
        generator.fill(seed, &(at_us as u32).to_le_bytes());
    }
    let [first, second, third] = seeds.map(seed_as_u64);
    let predicted = predict_third(first, second);
    assert!(
        predicted.is_none_or(|guess| guess != third),
        "{predicted:?}"
    );
}

/// 20,000 seeds from one instantiation: none repeats, and every byte value turns up about
/// equally often (a chi-square statistic far below what a skewed generator gives).
#[test]
fn seeds_do_not_repeat_and_spread_evenly() {
    let mut generator = SeedGenerator::new(&[0xC3; 32], b"CCM");
    let mut seen = std::collections::HashSet::new();
    let mut counts = [0u32; 256];
    for at_us in 0..20_000u32 {
        let mut seed = [0u8; 6];
        generator.fill(&mut seed, &at_us.to_le_bytes());
        assert!(seen.insert(seed), "seed {at_us} repeats");
        for byte in seed {
            counts[usize::from(byte)] += 1;
        }
    }
    let expected = 20_000.0 * 6.0 / 256.0;
    let chi_square: f64 = counts
        .iter()
        .map(|&count| (f64::from(count) - expected).powi(2) / expected)
        .sum();
    // 255 degrees of freedom: mean 255, standard deviation 22.6; 400 is more than 6 of them.
    assert!(chi_square < 400.0, "chi-square {chi_square:.1}");
}
