//! ONNX as the second checkpoint format: a PyTorch-style MLP exported to ONNX (fixture written by
//! `tools/make_onnx_policy.py`) runs through tract and matches numpy's outputs; mismatched or broken
//! models are refused naming the `onnx` field.

use std::sync::Arc;

use agents::checkpoint::{Activation, Checkpoint, ObservationSpec, OnnxPolicy, FORMAT, VERSION};
use agents::controller::{ControllerSpec, PdGains};
use agents::observation::ObsBlock;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

fn onnx_checkpoint(blocks: Vec<ObsBlock>, n: usize, bytes: &[u8]) -> Checkpoint {
    Checkpoint {
        format: FORMAT.into(),
        version: VERSION,
        name: "onnx-fixture".into(),
        model: "default".into(),
        controller: ControllerSpec::Kmac {
            gains: PdGains { kp: 40.0, kd: 3.0 },
            activation_clamp: None,
            activation_noise: None,
            clamp_coupled: false,
        },
        observation: ObservationSpec {
            blocks,
            mean: vec![0.0; n],
            std: vec![1.0; n],
            replan: Default::default(),
        },
        policy: None,
        onnx: Some(OnnxPolicy::from_bytes(bytes)),
        policy_std: None,
        action_noise: None,
        grip_floor: None,
        training: None,
        expected_activation_noise: false,
    }
}

#[test]
fn an_onnx_policy_matches_numpy_and_plays() {
    let m = model();
    let bytes = include_bytes!("fixtures/policy.onnx");
    let ck = onnx_checkpoint(ObsBlock::ALL.to_vec(), 206, bytes);
    ck.validate(&m).unwrap_or_else(|e| panic!("{e}"));
    let text = serde_json::to_string(&ck).unwrap();
    let ck = Checkpoint::from_json(&text, &m).unwrap();
    let net = ck.network().unwrap();
    // The plan the validation built is the one every player gets (and a clone's players too).
    let plan = |n: &agents::checkpoint::Network| match n {
        agents::checkpoint::Network::Onnx(plan, _) => plan.clone(),
        other => panic!("not ONNX: {other:?}"),
    };
    let again = ck.clone().network().unwrap();
    assert!(Arc::ptr_eq(&plan(&net), &plan(&again)));
    let expected: serde_json::Value =
        serde_json::from_str(include_str!("fixtures/policy_expected.json")).unwrap();
    let rows = |k: &str| -> Vec<Vec<f64>> {
        expected[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                r.as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            })
            .collect()
    };
    let mut worst: f64 = 0.0;
    for (x, y) in rows("inputs").iter().zip(rows("outputs")) {
        let out = net.forward(x).unwrap();
        assert_eq!(out.len(), 13);
        for (a, b) in out.iter().zip(&y) {
            worst = worst.max((a - b).abs() / b.abs().max(1.0));
        }
    }
    assert!(worst < 1e-5, "tract vs numpy: {worst}");
    let e = agents::eval::Evaluation {
        lead_in: false,
        model: m.clone(),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes: 2,
        seed: 1,
    };
    let r = agents::eval::evaluate(
        &e,
        &agents::factory::PlayerSpec::Checkpoint(Arc::new(ck)),
        &|| {},
    )
    .unwrap();
    assert_eq!(r.episodes, 2);
}

#[test]
fn mismatched_or_broken_onnx_models_are_refused() {
    let m = model();
    let bytes = include_bytes!("fixtures/policy.onnx");
    // The model takes 206 entries; an observation without the planner's command has 195.
    let blocks: Vec<ObsBlock> = ObsBlock::ALL
        .iter()
        .copied()
        .filter(|b| *b != ObsBlock::Command)
        .collect();
    let e = onnx_checkpoint(blocks, 195, bytes)
        .validate(&m)
        .unwrap_err();
    assert!(e.field.starts_with("onnx"), "{e}");
    let e = onnx_checkpoint(ObsBlock::ALL.to_vec(), 206, b"not an onnx file")
        .validate(&m)
        .unwrap_err();
    assert!(e.field.starts_with("onnx"), "{e}");
    let mut c = onnx_checkpoint(ObsBlock::ALL.to_vec(), 206, bytes);
    c.onnx = Some(OnnxPolicy::from_base64("@@@".into()));
    assert!(c.validate(&m).unwrap_err().message.contains("base64"));
    // A Direct controller wants 77 actions, the network gives 13.
    let mut c = onnx_checkpoint(ObsBlock::ALL.to_vec(), 206, bytes);
    c.controller = ControllerSpec::Direct;
    assert!(c.validate(&m).unwrap_err().message.contains("13 actions"));
}

/// The reader's refusal of fixture `file`, a model the checkpoint_onnx fuzz target found.
fn refused(file: &str) -> agents::checkpoint::CheckpointError {
    let path = format!("{}/tests/fixtures/{file}", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(path).unwrap();
    let m = model();
    let blocks = agents::observation::ObsBlock::ALL.to_vec();
    let n = agents::observation::Observer::new(&m, blocks.clone(), 0).size();
    let text = serde_json::to_string(&onnx_checkpoint(blocks, n, &bytes)).unwrap();
    let e = Checkpoint::from_json(&text, &m).unwrap_err();
    assert_eq!(e.field, "onnx.model_base64", "{e}");
    e
}

#[test]
fn an_onnx_graph_whose_output_names_nothing_is_refused_not_a_panic() {
    // Found by the checkpoint_onnx fuzz target in CI: tract-onnx 0.23 panicked ("no entry found for
    // key") on a graph output that no input, initializer or node produces.
    let e = refused("onnx_output_names_nothing.onnx");
    assert!(
        e.message
            .contains("is no input, initializer or node's output"),
        "{e}"
    );
}

/// The process's peak resident memory, bytes (Linux).
fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
}

#[test]
fn an_onnx_graph_that_would_allocate_too_much_is_refused_before_it_does() {
    // `tools/make_onnx_policy.py`: 374 bytes whose ConstantOfShape makes 250 000 000 floats (10^9
    // bytes) when the graph is optimised or run.
    let before = peak_rss();
    let e = refused("policy_big_constant.onnx");
    assert!(
        e.message
            .contains("node 'ConstantOfShape' would make a tensor of 1000000000 bytes"),
        "{e}"
    );
    if let (Some(before), Some(after)) = (before, peak_rss()) {
        let grew = after.saturating_sub(before);
        assert!(grew < 256 << 20, "the refusal took {grew} bytes");
    }
}

#[test]
fn an_onnx_model_without_an_input_is_refused_not_a_panic() {
    // Found by the checkpoint_onnx fuzz target once the case above was refused: tract-core 0.23
    // indexed the inputs of a model that has none.
    let e = refused("onnx_no_input.onnx");
    assert!(e.message.contains("it takes 0 inputs, not one"), "{e}");
}

#[test]
fn an_onnx_policy_whose_shapes_depend_on_its_input_is_refused() {
    // `tools/make_onnx_policy.py`: 13 zeros for the zero observation, two more entries per negative
    // observation entry (NonZero). Its width, and what it allocates, would change in play: refused
    // when it is read, whatever it answers the zero observation.
    let m = model();
    let bytes = include_bytes!("fixtures/policy_variable_width.onnx");
    let ck = onnx_checkpoint(ObsBlock::ALL.to_vec(), 206, bytes);
    let e = ck.validate(&m).unwrap_err();
    assert!(
        e.message.contains("known only from the input's values"),
        "{e}"
    );
}

#[test]
fn a_network_whose_output_is_not_finite_in_play_forfeits_instead_of_panicking() {
    // Finite for the zero observation validation tries, infinite for the observations of play: the
    // player's check at every call turns it into an invalid action (the episode's end), never a
    // panic.
    let m = model();
    let kmac = ControllerSpec::Kmac {
        gains: PdGains { kp: 10.0, kd: 1.0 },
        activation_clamp: None,
        activation_noise: None,
        clamp_coupled: false,
    };
    let mut ck = Checkpoint::template(&m, "overflow", kmac, &[8], Activation::Relu);
    for layer in &mut ck.policy.as_mut().unwrap().layers {
        for row in &mut layer.weights {
            row.iter_mut().for_each(|w| *w = 1e300);
        }
    }
    ck.validate(&m).unwrap_or_else(|e| panic!("{e}"));
    let e = agents::eval::Evaluation {
        lead_in: false,
        model: m.clone(),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes: 3,
        seed: 1,
    };
    let r = agents::eval::evaluate(
        &e,
        &agents::factory::PlayerSpec::Checkpoint(Arc::new(ck)),
        &|| {},
    )
    .unwrap();
    assert_eq!(r.ends, [("INVALID_ACTION".to_string(), 3)]);
}
