//! The ONNX side of the checkpoint reader: any bytes as the embedded `.onnx` file of an otherwise
//! valid checkpoint (every observation block, a K-MAC controller). A model or an error naming
//! `onnx`, never a panic, a hang or unbounded memory. The corpus starts from the ONNX test fixture.
#![no_main]

use agents::checkpoint::{Checkpoint, ObservationSpec, OnnxPolicy, FORMAT, VERSION};
use agents::controller::{ControllerSpec, PdGains};
use agents::observation::{ObsBlock, Observer};
use libfuzzer_sys::fuzz_target;
use muscle_rally_fuzz::model;

fuzz_target!(|data: &[u8]| {
    // The checkpoint reader contains tract's panics (catch_unwind: a model tract panics on is
    // refused). libfuzzer-sys's hook aborts on every panic, even a caught one, so it is replaced by
    // a silent one: a panic the reader does not contain still reaches libfuzzer-sys's own
    // catch_unwind, which aborts, and is a crash.
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let m = model();
    let n = Observer::new(m, ObsBlock::ALL.to_vec(), 0).size();
    let c = Checkpoint {
        format: FORMAT.into(),
        version: VERSION,
        name: "fuzz".into(),
        model: "default".into(),
        controller: ControllerSpec::Kmac {
            gains: PdGains { kp: 10.0, kd: 1.0 },
            activation_clamp: None,
            activation_noise: None,
            clamp_coupled: false,
        },
        observation: ObservationSpec {
            blocks: ObsBlock::ALL.to_vec(),
            mean: vec![0.0; n],
            std: vec![1.0; n],
            replan: Default::default(),
        },
        policy: None,
        onnx: Some(OnnxPolicy::from_bytes(data)),
        policy_std: None,
        action_noise: None,
        grip_floor: None,
        training: None,
        expected_activation_noise: false,
    };
    let text = serde_json::to_string(&c).unwrap();
    if let Ok(c) = Checkpoint::from_json(&text, m) {
        let net = c
            .network()
            .expect("a checkpoint that loads builds its network");
        let _ = net.forward(&vec![0.0; n]);
    }
});
