//! `ppo::tune_candle_threads` (its own test binary: it sets an environment variable, which is only
//! sound while no other thread runs, and a test binary runs its tests on threads).

/// Training read `/proc/cpuinfo` before every matrix product (candle re-derives its thread count
/// unless `RAYON_NUM_THREADS` is set): the fix must keep candle's count and rayon's pool as they
/// were and leave candle an answer it need not look up. One test, as the variables are the process's.
#[test]
fn candle_no_longer_reads_cpuinfo_before_every_product_nor_spins_long() {
    const SPIN: &str = "CANDLE_BARRIER_POOL_SPIN_LIMIT";
    std::env::remove_var("RAYON_NUM_THREADS");
    std::env::remove_var(SPIN);
    let candle_before = candle_core::utils::get_num_threads();
    let logical = std::thread::available_parallelism().map_or(1, |n| n.get());
    agents::ppo::tune_candle_threads();
    assert_eq!(
        std::env::var("RAYON_NUM_THREADS").ok(),
        Some(candle_before.to_string()),
        "candle's count is fixed in the variable it reads first"
    );
    assert_eq!(candle_core::utils::get_num_threads(), candle_before);
    assert_eq!(
        rayon::current_num_threads(),
        logical,
        "the global pool keeps every logical CPU"
    );
    // A second call (or a user's own setting) changes nothing.
    agents::ppo::tune_candle_threads();
    assert_eq!(candle_core::utils::get_num_threads(), candle_before);

    // candle's element-wise workers spin 25 000 times after each operation unless told otherwise:
    // told 200, unless the user set their own value.
    assert_eq!(std::env::var(SPIN).ok().as_deref(), Some("200"));
    std::env::set_var(SPIN, "7");
    agents::ppo::tune_candle_threads();
    assert_eq!(std::env::var(SPIN).ok().as_deref(), Some("7"));
}
