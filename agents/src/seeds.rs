//! The determinism primitive of evaluations and matches: every episode or rally `i` of a run seeded
//! `seed` gets its own serve seed and agent seed, unrelated to its neighbours', and [`par_indexed`]
//! plays such independent episodes on every core without letting the thread count change a result.

/// SplitMix64's increment, the golden ratio in 64 bits.
pub const SPLITMIX_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// SplitMix64's output function (Steele, Lea and Flood, 2014): a bijection of 64 bits whose outputs
/// for neighbouring inputs are unrelated. Every seed the project derives goes through it.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// One step of the SplitMix64 generator: advances `state` by [`SPLITMIX_GAMMA`] and returns the
/// mixed value.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(SPLITMIX_GAMMA);
    mix64(*state)
}

/// The serve seed and the agent seed of episode `i` of an evaluation with `seed`, mixed so that
/// neighbouring episodes get unrelated streams.
pub fn episode_seeds(seed: u64, i: usize) -> (u64, u64) {
    let base = mix64(seed ^ mix64(i as u64 + SPLITMIX_GAMMA));
    (base, mix64(base.wrapping_add(1)))
}

/// `play(state, i)` for every `i` in `0..n`, in parallel: one `state` per rayon worker (built by
/// `init`: an arena and its players, built once rather than per episode), the workers taking the
/// next index as they finish one. Results come back in index order. Each `play` must depend on `i`
/// alone (reseed the players from `i`'s seeds), so that results do not depend on which worker ran it.
pub fn par_indexed<S, T: Send>(
    n: usize,
    init: impl Fn() -> S + Sync,
    play: impl Fn(&mut S, usize) -> T + Sync,
) -> Vec<T> {
    use rayon::prelude::*;
    let workers = rayon::current_num_threads().clamp(1, n.max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<T>>> =
        (0..n).map(|_| std::sync::Mutex::new(None)).collect();
    (0..workers).into_par_iter().for_each(|_| {
        let mut state = init();
        loop {
            let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if i >= n {
                break;
            }
            let r = play(&mut state, i);
            *slots[i].lock().expect("no worker panics holding it") = Some(r);
        }
    });
    slots
        .into_iter()
        .map(|m| {
            m.into_inner()
                .expect("no worker panicked")
                .expect("every index played")
        })
        .collect()
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

    #[test]
    fn par_indexed_returns_every_index_in_order_on_any_pool() {
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let out = pool.install(|| par_indexed(50, || 0u64, |_, i| episode_seeds(9, i).0));
            let want: Vec<u64> = (0..50).map(|i| episode_seeds(9, i).0).collect();
            assert_eq!(out, want);
        }
    }
}

#[cfg(test)]
mod splitmix_tests {
    #[test]
    fn splitmix64_gives_the_reference_stream() {
        // The published SplitMix64 sequence from state 0.
        let mut state = 0;
        let got: Vec<u64> = (0..3).map(|_| super::splitmix64(&mut state)).collect();
        assert_eq!(
            got,
            [
                0xe220_a839_7b1d_cdaf,
                0x6e78_9e6a_a1b9_65f4,
                0x06c4_5d18_8009_454f
            ]
        );
    }
}
