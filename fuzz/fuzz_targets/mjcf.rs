//! The MJCF loader on any text: a model or an error, never a panic, a hang or unbounded memory.
//! Every `<include file=…>` resolves to the input itself, so include cycles are exercised too.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = sim::mjcf::parse_str(text, "fuzz.xml");
    let _ = sim::mjcf::load(Path::new("fuzz.xml"), &|_: &Path| Ok(text.to_string()));
});
