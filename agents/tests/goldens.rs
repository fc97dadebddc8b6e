//! Golden outputs (rust-analyzer's habit: the expected output is a file next to the test, refreshed
//! by one command): a served ball's flight, an episode of the scripted agent and a 10-rally match,
//! compared to the bit (floats round-trip exactly through the JSON). They pin `sim::SIM_VERSION`'s
//! meaning: a change that alters any of them must bump the version, and refreshing is refused while
//! the version is the one the goldens were written with.
//!
//! Refresh after bumping `SIM_VERSION`: `RALLY_UPDATE_GOLDENS=1 cargo test --workspace --test goldens`.

use std::path::PathBuf;
use std::sync::Arc;

use serde_json::{json, Value};
use sim::arena::MYOCHALLENGE;
use sim::rng::Rng;
use sim::serve::ServeKind;

const UPDATE: &str = "RALLY_UPDATE_GOLDENS";

fn goldens_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/goldens"))
}

/// Compares `output` with the golden `name`, or rewrites it under `RALLY_UPDATE_GOLDENS=1` when the
/// simulator's version differs from the one the golden was written with.
fn check(name: &str, output: Value) {
    let update = std::env::var_os(UPDATE).is_some();
    if let Err(e) = check_in(&goldens_dir(), name, output, sim::SIM_VERSION, update) {
        panic!("{e}");
    }
}

/// The rule, for any directory and version: equal output and version pass; changed output fails
/// unless the version changed too and `update` is set (then the golden is rewritten); an unchanged
/// output under a new version asks for the golden's refresh.
fn check_in(
    dir: &std::path::Path,
    name: &str,
    output: Value,
    version_now: &str,
    update: bool,
) -> Result<(), String> {
    let path = dir.join(format!("{name}.json"));
    let fresh = json!({"sim_version": version_now, "output": output});
    let golden: Option<Value> = std::fs::read_to_string(&path)
        .ok()
        .map(|t| serde_json::from_str(&t).expect("a golden is JSON"));
    let write = || {
        let text = serde_json::to_string_pretty(&fresh).unwrap() + "\n";
        std::fs::write(&path, text).unwrap();
        eprintln!("{name}: golden written for simulator {version_now}");
        Ok(())
    };
    let Some(golden) = golden else {
        if !update {
            return Err(format!(
                "{}: no golden; write it with {UPDATE}=1",
                path.display()
            ));
        }
        return write();
    };
    let version = golden["sim_version"].as_str().unwrap_or("?");
    if golden["output"] == fresh["output"] {
        if version == version_now {
            return Ok(());
        }
        if !update {
            return Err(format!(
                "{name}: SIM_VERSION is {version_now} but the golden (same output) says {version}: refresh with {UPDATE}=1"
            ));
        }
        return write();
    }
    if version == version_now {
        return Err(format!(
            "{name}: the simulator's output changed but SIM_VERSION is still {version}: a change \
             that alters a match must bump sim::SIM_VERSION, then refresh with {UPDATE}=1 \
             cargo test --workspace --test goldens"
        ));
    }
    if !update {
        return Err(format!(
            "{name}: the output changed with SIM_VERSION ({version} → {version_now}): refresh the golden with {UPDATE}=1"
        ));
    }
    write()
}

#[test]
fn the_golden_rule_refuses_a_changed_output_under_the_same_version() {
    let dir = std::env::temp_dir().join(format!("rally-goldens-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = |x: f64| json!({"x": x});
    assert!(
        check_in(&dir, "probe", out(1.0), "1.0", false).is_err(),
        "missing golden"
    );
    check_in(&dir, "probe", out(1.0), "1.0", true).unwrap();
    check_in(&dir, "probe", out(1.0), "1.0", false).unwrap();
    // The last bit of a float is a change.
    let nudged = f64::from_bits(1.0f64.to_bits() + 1);
    let e = check_in(&dir, "probe", out(nudged), "1.0", true).unwrap_err();
    assert!(e.contains("must bump"), "{e}");
    assert!(check_in(&dir, "probe", out(nudged), "1.1", false).is_err());
    check_in(&dir, "probe", out(nudged), "1.1", true).unwrap();
    check_in(&dir, "probe", out(nudged), "1.1", false).unwrap();
    // A bump without a change asks for the refresh too (the golden names its version).
    assert!(check_in(&dir, "probe", out(nudged), "1.2", false).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

fn v3(v: &nalgebra::Vector3<f64>) -> Value {
    json!([v.x, v.y, v.z])
}

#[test]
fn a_served_ball_flies_as_its_golden() {
    let bounce = sim::predict::BounceModel::for_table(&MYOCHALLENGE.table);
    let serve = sim::serve::generate(ServeKind::P2, &mut Rng::seeded(7), &bounce);
    let mut world = sim::BallWorld::new(MYOCHALLENGE, serve.ball);
    let (mut samples, mut contacts) = (Vec::new(), Vec::new());
    for step in 0..750 {
        let mut events = Vec::new();
        world.physics_step(&[], &mut events);
        contacts.extend(
            events
                .iter()
                .map(|e| json!({"kind": format!("{:?}", e.kind), "t": e.t, "pos": v3(&e.pos)})),
        );
        if step % 10 == 9 {
            let b = world.ball;
            samples.push(
                json!({"t": world.time, "pos": v3(&b.pos), "vel": v3(&b.vel), "spin": v3(&b.spin)}),
            );
        }
    }
    check(
        "served_ball",
        json!({"serve": "p2", "seed": 7, "samples": samples, "contacts": contacts}),
    );
}

#[test]
fn an_episode_of_the_scripted_agent_plays_as_its_golden() {
    let m = model();
    let mut env = sim::episode::SingleServe::new(
        m.clone(),
        &sim::config::ArenaConfig::default(),
        MYOCHALLENGE,
    )
    .unwrap();
    let spec = agents::factory::PlayerSpec::scripted("scripted").unwrap();
    let mut player = spec.build(&m, &MYOCHALLENGE, 0).unwrap();
    player.reseed(11);
    env.reset(ServeKind::P2, &mut Rng::seeded(3), None);
    player.reset();
    let mut ctrl = vec![0.0; m.actuators.len()];
    let mut frames = Vec::new();
    let mut step = 0;
    loop {
        ctrl.copy_from_slice(&env.robot.state.ctrl);
        player
            .act(&env.robot, &env.world.ball, env.world.time, &mut ctrl)
            .unwrap();
        env.robot.state.ctrl.copy_from_slice(&ctrl);
        let done = env.step().done;
        if step % 5 == 0 || done {
            frames.push(json!({
                "t": env.world.time,
                "ball": v3(&env.world.ball.pos),
                "paddle": v3(&env.robot.paddle.pose.pos),
                "qpos": env.robot.state.qpos,
                "act_sum": env.robot.state.act.iter().sum::<f64>(),
            }));
        }
        step += 1;
        if done {
            break;
        }
    }
    let end = env.referee.end().map(|e| e.reason.name());
    check(
        "scripted_episode",
        json!({"serve": "p2", "serve_seed": 3, "agent_seed": 11, "hit": env.hit, "success": env.success,
               "end": end, "steps": step, "frames": frames}),
    );
}

#[test]
fn a_ten_rally_match_plays_as_its_golden() {
    let spec = agents::matchrun::MatchSpec {
        model: model(),
        config: sim::config::ArenaConfig::default(),
        preset: MYOCHALLENGE,
        rallies: 10,
        seed: 1,
        replay: true,
    };
    let a = agents::factory::PlayerSpec::scripted("scripted").unwrap();
    let b = agents::factory::PlayerSpec::scripted("scripted-drive").unwrap();
    let (record, replay) = agents::matchrun::play_match(&spec, &a, &b, &mut |_| {}).unwrap();
    let mut record = serde_json::to_value(&record).unwrap();
    // The golden's own header says the version; the record's is the same by construction.
    record.as_object_mut().unwrap().remove("sim_version");
    // Replay frames: their count per rally and the last frame of each (the whole replay is ~0.5 MB).
    let ends: Vec<Value> = replay
        .iter()
        .map(|frames| json!({"frames": frames.len(), "last": frames.last()}))
        .collect();
    check("ten_rally_match", json!({"record": record, "replay": ends}));
}

/// MyoSuite's robot as `rally model import myosuite` wrote it (the file `RALLY_MYOCHALLENGE` names,
/// as `.ci/run` sets it; otherwise the test says why it did not run): the file's SHA-256, and ten
/// P2 serves each of the scripted agent and of the committed K-MAC checkpoint by its mean action,
/// whose summaries (mean effort and activation sum every step) show a change in any bit of any
/// step. The goldens above pin the default robot; this one pins the import (the pinned myosuite and
/// MuJoCo must write the same file on every machine) and the simulator on the 273-muscle robot,
/// from one machine to another.
#[test]
fn myosuite_robot_plays_as_its_golden() {
    use sha2::Digest;
    let Some(path) = std::env::var_os("RALLY_MYOCHALLENGE") else {
        eprintln!(
            "not run: set RALLY_MYOCHALLENGE to the file `rally model import myosuite` wrote"
        );
        return;
    };
    let bytes = std::fs::read(&path).unwrap();
    let digest: String = sha2::Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let golden = goldens_dir().join("myochallenge_serves.json");
    if std::env::var_os(UPDATE).is_none() {
        if let Ok(text) = std::fs::read_to_string(&golden) {
            let was: Value = serde_json::from_str(&text).expect("a golden is JSON");
            let was = was["output"]["model_sha256"]
                .as_str()
                .unwrap_or("?")
                .to_string();
            assert_eq!(
                digest, was,
                "the imported model differs from the one the golden was made with (left: this \
                 file's SHA-256): an import through --python with another MuJoCo or myosuite \
                 differs; with the releases the import pins, the file should be the same on every \
                 machine (.ci/run checks it does not depend on the BLAS kernel) — compare the two \
                 files"
            );
        }
    }
    let m = Arc::new(
        sim::mjcf::load(std::path::Path::new(&path), &|p| std::fs::read_to_string(p))
            .unwrap_or_else(|e| panic!("{e}")),
    );
    let e = agents::eval::Evaluation {
        lead_in: false,
        model: m.clone(),
        config: sim::config::ArenaConfig::myochallenge(),
        preset: MYOCHALLENGE,
        kind: ServeKind::P2,
        episodes: 10,
        seed: 5,
    };
    let scripted = agents::factory::PlayerSpec::scripted("scripted").unwrap();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/checkpoints/myochallenge/kmac.json"
    ))
    .unwrap();
    let kmac = agents::checkpoint::Checkpoint::from_json(&text, &m).unwrap();
    let kmac = agents::factory::PlayerSpec::Checkpoint(Arc::new(kmac)).mean_action();
    let play = |spec| serde_json::to_value(agents::eval::evaluate(&e, spec, &|| {}).unwrap());
    check(
        "myochallenge_serves",
        json!({"model_sha256": digest, "serve": "p2", "seed": 5,
               "scripted": play(&scripted).unwrap(), "kmac_mean_action": play(&kmac).unwrap()}),
    );
}
