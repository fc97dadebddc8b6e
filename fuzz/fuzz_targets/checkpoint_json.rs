//! The checkpoint reader on any text (what `POST /api/v1/agents` and `rally eval FILE` read): a
//! checkpoint or an error naming the field, never a panic, a hang or unbounded memory. A checkpoint
//! that loads must also build its network and act once.
#![no_main]

use agents::checkpoint::Checkpoint;
use libfuzzer_sys::fuzz_target;
use muscle_rally_fuzz::model;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(c) = Checkpoint::from_json(text, model()) {
        let net = c
            .network()
            .expect("a checkpoint that loads builds its network");
        let _ = net.forward(&vec![0.0; c.observation.mean.len()]);
    }
});
