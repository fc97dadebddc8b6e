//! The workers' players, kept: an agent's checkpoint is parsed, validated and its network built
//! (an ONNX graph optimised) once per process, not once per match, and shared by every worker.
//!
//! Keyed by the spec's SHA-256 ([`crate::db::spec_hash`]): two specs share an entry only if they are
//! the same text. Bounded by `player_cache` entries, the least recently used leaving first; 0 turns
//! it off (every match builds its own, as `rally bench server` measures against).

use std::num::NonZeroUsize;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use agents::factory::PlayerSpec;

use crate::db;

/// The cache of built players' recipes.
pub struct PlayerCache {
    entries: Option<Mutex<lru::LruCache<String, PlayerSpec>>>,
    loads: AtomicUsize,
    /// Matches set up, and their setup times summed (µs): from the claim to the first frame.
    setups: AtomicU64,
    setup_us: AtomicU64,
}

impl PlayerCache {
    /// A cache of at most `capacity` agents (0: none kept).
    pub fn new(capacity: usize) -> PlayerCache {
        PlayerCache {
            entries: NonZeroUsize::new(capacity).map(|n| Mutex::new(lru::LruCache::new(n))),
            loads: AtomicUsize::new(0),
            setups: AtomicU64::new(0),
            setup_us: AtomicU64::new(0),
        }
    }

    /// The recipe of an agent of `kind` whose spec is `spec`: the kept one, or built (blocking: a
    /// checkpoint is parsed and validated, its network built) and kept.
    pub fn get(
        &self,
        model: &sim::model::Model,
        kind: db::AgentKind,
        spec: &str,
    ) -> Result<PlayerSpec, String> {
        let key = match kind {
            // A scripted agent's recipe is its name: nothing to keep.
            db::AgentKind::Scripted => return build(model, kind, spec),
            db::AgentKind::Checkpoint => db::spec_hash(spec),
        };
        if let Some(found) = self.lookup(kind, &key) {
            return Ok(found);
        }
        // Built outside the lock: another worker may build the same one meanwhile (both are the
        // same checkpoint; the second one stored replaces the first).
        let built = build(model, kind, spec)?;
        self.loads.fetch_add(1, Ordering::Relaxed);
        if let Some(entries) = &self.entries {
            if let Ok(mut e) = entries.lock() {
                e.put(key, built.clone());
            }
        }
        Ok(built)
    }

    /// The kept recipe of the agent of `kind` whose spec's hash is `hash`, if it is kept (a
    /// scripted agent's never is: its recipe is its name).
    pub fn lookup(&self, kind: db::AgentKind, hash: &str) -> Option<PlayerSpec> {
        match kind {
            db::AgentKind::Scripted => None,
            db::AgentKind::Checkpoint => self.entries.as_ref()?.lock().ok()?.get(hash).cloned(),
        }
    }

    /// Checkpoints this process has parsed and built for matches and replays so far.
    pub fn loads(&self) -> usize {
        self.loads.load(Ordering::Relaxed)
    }

    /// Records a match's setup: the time from its claim to its first frame (the agents' specs
    /// read, their players got from here, the arena built).
    pub fn record_setup(&self, took: std::time::Duration) {
        self.setups.fetch_add(1, Ordering::Relaxed);
        self.setup_us
            .fetch_add(took.as_micros() as u64, Ordering::Relaxed);
    }

    /// Matches set up so far in this process, and their setup times summed, s.
    pub fn setups(&self) -> (u64, f64) {
        (
            self.setups.load(Ordering::Relaxed),
            self.setup_us.load(Ordering::Relaxed) as f64 * 1e-6,
        )
    }
}

/// A stored agent's recipe, built from its spec.
fn build(model: &sim::model::Model, kind: db::AgentKind, spec: &str) -> Result<PlayerSpec, String> {
    match kind {
        db::AgentKind::Scripted => {
            PlayerSpec::scripted(spec).ok_or_else(|| format!("unknown scripted agent '{spec}'"))
        }
        db::AgentKind::Checkpoint => {
            let c = agents::checkpoint::Checkpoint::from_json(spec, model)
                .map_err(|e| e.to_string())?;
            // The network now, once, rather than by each player (the ONNX plan is kept in it).
            c.network().map_err(|e| e.to_string())?;
            Ok(PlayerSpec::Checkpoint(Arc::new(c)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> sim::model::Model {
        sim::config::default_model()
    }

    fn template(name: &str) -> String {
        let m = model();
        let c = agents::checkpoint::Checkpoint::template(
            &m,
            name,
            agents::controller::ControllerSpec::Direct,
            &[8],
            agents::checkpoint::Activation::Tanh,
        );
        serde_json::to_string(&c).unwrap()
    }

    #[test]
    fn a_checkpoint_is_built_once_and_the_least_recent_leaves_first() {
        let m = model();
        let cache = PlayerCache::new(2);
        let (one, two, three) = (template("one"), template("two"), template("three"));
        let kind = db::AgentKind::Checkpoint;
        let first = cache.get(&m, kind, &one).unwrap();
        let again = cache.get(&m, kind, &one).unwrap();
        let same = |a: &PlayerSpec, b: &PlayerSpec| match (a, b) {
            (PlayerSpec::Checkpoint(a), PlayerSpec::Checkpoint(b)) => Arc::ptr_eq(a, b),
            _ => false,
        };
        assert!(same(&first, &again));
        assert_eq!(cache.loads(), 1);
        cache.get(&m, kind, &two).unwrap();
        cache.get(&m, kind, &one).unwrap();
        cache.get(&m, kind, &three).unwrap(); // `two` is the least recently used: it leaves
        assert_eq!(cache.loads(), 3);
        cache.get(&m, kind, &one).unwrap();
        assert_eq!(cache.loads(), 3);
        cache.get(&m, kind, &two).unwrap();
        assert_eq!(cache.loads(), 4);
        // Scripted agents are not checkpoints: nothing loaded or kept.
        cache.get(&m, db::AgentKind::Scripted, "scripted").unwrap();
        assert_eq!(cache.loads(), 4);
        // A bad spec is an error, and nothing is kept of it.
        assert!(cache.get(&m, kind, "{}").is_err());
        assert_eq!(cache.loads(), 4);
    }

    #[test]
    fn without_a_capacity_every_call_builds() {
        let m = model();
        let cache = PlayerCache::new(0);
        let one = template("one");
        for _ in 0..3 {
            cache.get(&m, db::AgentKind::Checkpoint, &one).unwrap();
        }
        assert_eq!(cache.loads(), 3);
    }
}
