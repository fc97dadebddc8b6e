//! Admission: a checkpoint's text validated against the model and qualified on P2 serves, in one
//! call whose every outcome is a value, never a panic — what the server runs for a submission
//! (inside a child process under CPU-time and memory limits: `rally checkpoint admit`) and, in
//! process, for its built-in checkpoints.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::checkpoint::Checkpoint;
use crate::eval::{evaluate, EvalReport, Evaluation};
use crate::factory::PlayerSpec;

/// What an admission found. The child process prints it as one JSON line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum Admission {
    /// Valid, and it played its qualification episodes (the thresholds are the caller's to apply).
    Qualified {
        /// The qualification's figures.
        report: Box<EvalReport>,
    },
    /// Not a valid checkpoint of this model: the field and what is wrong with it.
    Invalid {
        /// Why.
        error: String,
    },
    /// Valid, but its qualification could not be played (its network failed on an observation).
    Failed {
        /// Why.
        error: String,
    },
    /// It asked for more memory than the process may have (under the limit `rally checkpoint
    /// admit` sets, the allocator's refusal).
    OverMemory {
        /// What failed to allocate.
        error: String,
    },
}

/// Validates `text` as a checkpoint of `eval.model`, then plays `eval`'s episodes with it. A panic
/// inside (a network the reader accepted but cannot run, an allocation the memory limit refused) is
/// caught and becomes an outcome.
pub fn admit(text: &str, eval: &Evaluation) -> Admission {
    let checkpoint = match guarded(|| Checkpoint::from_json(text, &eval.model)) {
        Ok(Ok(c)) => c,
        // The reader reports a panic of tract's as the network's field being wrong.
        Ok(Err(e)) if out_of_memory(&e.to_string()) => {
            return Admission::OverMemory {
                error: e.to_string(),
            }
        }
        Ok(Err(e)) => {
            return Admission::Invalid {
                error: e.to_string(),
            }
        }
        Err(p) => return p.outcome(|error| Admission::Invalid { error }),
    };
    let spec = PlayerSpec::Checkpoint(Arc::new(checkpoint));
    match guarded(|| evaluate(eval, &spec, &|| {})) {
        Ok(Ok(report)) => Admission::Qualified {
            report: Box::new(report),
        },
        Ok(Err(error)) if out_of_memory(&error) => Admission::OverMemory { error },
        Ok(Err(error)) => Admission::Failed { error },
        Err(p) => p.outcome(|error| Admission::Failed { error }),
    }
}

/// Whether a failure's message says an allocation was refused: tract asserts "failed to allocate"
/// when it gets no memory for a tensor; a collection asked to grow past what can be addressed
/// panics with "capacity overflow". (Other allocations abort the process: "memory allocation of N
/// bytes failed", which the server reads from the child's standard error.)
fn out_of_memory(message: &str) -> bool {
    message.contains("failed to allocate") || message.contains("capacity overflow")
}

/// A caught panic's message.
struct Panicked(String);

impl Panicked {
    /// The outcome of a panic: out of memory when an allocation was refused, else `other`.
    fn outcome(self, other: impl FnOnce(String) -> Admission) -> Admission {
        if out_of_memory(&self.0) {
            Admission::OverMemory { error: self.0 }
        } else {
            other(format!("the network panicked: {}", self.0))
        }
    }
}

fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, Panicked> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        Panicked(
            p.downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "(no message)".into()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn qualification(episodes: usize) -> Evaluation {
        Evaluation {
            lead_in: false,
            model: Arc::new(sim::config::default_model()),
            config: sim::config::ArenaConfig::default(),
            preset: sim::arena::MYOCHALLENGE,
            kind: sim::serve::ServeKind::P2,
            episodes,
            seed: 0,
        }
    }

    #[test]
    fn a_trained_checkpoint_qualifies_and_junk_is_named() {
        let eval = qualification(4);
        let kmac = crate::builtins::checkpoint("kmac").expect("built in");
        match admit(kmac, &eval) {
            Admission::Qualified { report } => {
                assert_eq!(report.episodes, 4);
                assert!(report.hit_rate.value > 0.0, "{report:?}");
            }
            other => panic!("{other:?}"),
        }
        match admit("{\"name\": 3}", &eval) {
            Admission::Invalid { error } => assert!(error.contains("expected a string"), "{error}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_panic_becomes_an_outcome() {
        let p = Panicked("failed to allocate Layout { size: 4000000000 }".into());
        let fail = |error| Admission::Failed { error };
        assert!(matches!(p.outcome(fail), Admission::OverMemory { .. }));
        let p = Panicked("index out of bounds".into());
        match p.outcome(fail) {
            Admission::Failed { error } => assert!(error.contains("index out of bounds")),
            other => panic!("{other:?}"),
        }
        assert!(guarded(|| panic!("boom")).is_err());
    }
}
