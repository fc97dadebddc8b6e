//! The determinism primitive of evaluations and matches: every episode or rally `i` of a run seeded
//! `seed` gets its own serve seed and agent seed, unrelated to its neighbours'.

/// The serve seed and the agent seed of episode `i` of an evaluation with `seed` (SplitMix64-style
/// mixing, so neighbouring episodes get unrelated streams).
pub fn episode_seeds(seed: u64, i: usize) -> (u64, u64) {
    let mix = |mut z: u64| {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let base = mix(seed ^ mix(i as u64 + 0x9e37_79b9_7f4a_7c15));
    (base, mix(base.wrapping_add(1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episode_seeds_differ_and_repeat() {
        assert_eq!(episode_seeds(7, 3), episode_seeds(7, 3));
        assert_ne!(episode_seeds(7, 3), episode_seeds(7, 4));
        assert_ne!(episode_seeds(7, 3), episode_seeds(8, 3));
    }
}
