//! The batch plan (`rally batch PLAN.toml`) on any text: requests or a usage error, never a panic,
//! a hang or unbounded memory. It compiles the CLI's plan module itself, which depends on serde,
//! serde_json and toml only.
#![no_main]

use std::collections::HashMap;

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../../src/cmd/batch/plan.rs"]
mod plan;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = plan::parse(text) {
        let names: HashMap<String, i64> =
            [("scripted".to_string(), 1), ("kmac".to_string(), 2)].into();
        let _ = plan::jobs(&p, &names, &[1, 2, 3]);
    }
});
