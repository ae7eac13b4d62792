//! Seeded generators derived from (scenario seed, purpose, indices): every random draw of a run is fixed by
//! the scenario, and a draw for one point never depends on how many others came before it or on threads.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What a generator is for; each purpose gets its own independent stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    Perturbation = 1,
    Mounting = 2,
    Layout = 3,
    Target = 4,
    Measurement = 5,
    Split = 6,
    /// The study's campaigns: one seed per (region, layout, size, repetition), and its test sets.
    Study = 7,
    /// The measurement of the `k`-th point of a campaign's sequence, when the history of the arm matters.
    Sequence = 8,
}

/// A generator for `purpose` and up to three indices (region, attempt, point, …). The key holds the seed,
/// the purpose and the first two indices verbatim and the stream number the third, so distinct inputs can
/// never share a stream.
pub fn derive(seed: u64, purpose: Stream, indices: &[u64]) -> ChaCha8Rng {
    assert!(indices.len() <= 3, "at most three indices");
    let at = |k: usize| indices.get(k).copied().unwrap_or(0);
    let mut key = [0u8; 32];
    for (slot, word) in key
        .chunks_exact_mut(8)
        .zip([seed, purpose as u64, at(0), at(1)])
    {
        slot.copy_from_slice(&word.to_le_bytes());
    }
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(at(2));
    rng
}
