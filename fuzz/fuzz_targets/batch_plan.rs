//! The batch plan (`rally batch PLAN.toml`) on any text: requests or a usage error, never a panic,
//! a hang or unbounded memory. It compiles the CLI's plan module itself, which depends on serde,
//! serde_json and toml only.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../../src/cmd/batch/plan.rs"]
mod plan;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = plan::parse(text) {
        let roster = plan::Roster {
            names: [("scripted".to_string(), 1), ("kmac".to_string(), 2)].into(),
            ids: vec![1, 2, 3],
            others: vec![(4, "myochallenge-kmac".into(), "myochallenge".into())],
        };
        let _ = plan::jobs(&p, &roster);
    }
});
