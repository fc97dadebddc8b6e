//! Every checkpoint committed under `config/checkpoints/` loads and validates against the default
//! robot, carries its training provenance, and plays a few episodes; a checkpoint that no longer fits
//! the code fails here rather than where a user meets it.

use std::sync::Arc;

use agents::checkpoint::Checkpoint;

#[test]
fn committed_checkpoints_load_validate_and_play() {
    let m = Arc::new(sim::config::default_model());
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/checkpoints");
    let mut seen = 0;
    for entry in std::fs::read_dir(dir).expect("config/checkpoints exists") {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "json") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.len() <= 8 << 20, "{}: over 8 MiB", path.display());
        let c =
            Checkpoint::from_json(&text, &m).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let t = c
            .training
            .as_ref()
            .unwrap_or_else(|| panic!("{}: no training provenance", path.display()));
        assert!(t.env_steps > 0 && !t.command.is_empty() && !t.git_commit.is_empty());
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        assert_eq!(c.name, stem, "{}: its name is its file's", path.display());
        let e = agents::eval::Evaluation {
            lead_in: false,
            model: m.clone(),
            config: sim::config::ArenaConfig::default(),
            preset: sim::arena::MYOCHALLENGE,
            kind: sim::serve::ServeKind::P2,
            episodes: 4,
            seed: 99,
        };
        let spec = agents::factory::PlayerSpec::Checkpoint(Arc::new(c));
        agents::eval::evaluate(&e, &spec, &|| {}).unwrap();
        seen += 1;
    }
    assert!(seen >= 1, "no committed checkpoint in {dir}");
}

#[test]
fn a_rally_match_between_committed_checkpoints_is_bit_identical_per_seed() {
    let m = Arc::new(sim::config::default_model());
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/checkpoints");
    let load = |name: &str| -> Option<agents::factory::PlayerSpec> {
        let text = std::fs::read_to_string(format!("{dir}/{name}.json")).ok()?;
        let c = Checkpoint::from_json(&text, &m).expect("a committed checkpoint loads");
        Some(agents::factory::PlayerSpec::Checkpoint(Arc::new(c)))
    };
    // The rally-trained agent if it is committed, against the single-serve one.
    let a = load("kmac-rally")
        .or_else(|| load("kmac"))
        .expect("kmac is committed");
    let b = load("kmac").unwrap();
    let spec = |seed| agents::matchrun::MatchSpec {
        model: m.clone(),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        rallies: 4,
        seed,
        replay: true,
    };
    let play = |seed| agents::matchrun::play_match(&spec(seed), &a, &b, &mut |_| {}).unwrap();
    let (r1, p1) = play(31);
    let (r2, p2) = play(31);
    assert_eq!(r1, r2);
    assert_eq!(p1, p2);
    assert!(p1.iter().all(|frames| frames.len() > 10));
    let (r3, _) = play(32);
    assert_ne!(r1.rallies, r3.rallies, "another seed, another match");
}

#[test]
fn the_binary_carries_every_committed_checkpoint_as_committed() {
    // `agents::builtins` is how `rally` finds a built-in from any directory: it must list every file
    // of config/checkpoints/ (and of config/checkpoints/myochallenge/), each with the file's text.
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/checkpoints");
    carried(root, agents::builtins::CHECKPOINTS);
    carried(
        &format!("{root}/myochallenge"),
        agents::builtins::MYOCHALLENGE_CHECKPOINTS,
    );
    for (name, text) in agents::builtins::MYOCHALLENGE_CHECKPOINTS {
        let model: serde_json::Value = serde_json::from_str(text).unwrap();
        assert_eq!(model["model"], "myochallenge", "{name} names its robot");
        assert_eq!(
            agents::builtins::checkpoint_of("myochallenge", name),
            Some(*text)
        );
    }
}

fn carried(dir: &str, list: &[(&str, &str)]) {
    let mut on_disk: Vec<(String, String)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .map(|p| {
            let name = p.file_stem().unwrap().to_string_lossy().to_string();
            (name, std::fs::read_to_string(&p).unwrap())
        })
        .collect();
    on_disk.sort();
    let embedded: Vec<(String, String)> = list
        .iter()
        .map(|(n, t)| (n.to_string(), t.to_string()))
        .collect();
    assert_eq!(
        embedded.iter().map(|(n, _)| n).collect::<Vec<_>>(),
        on_disk.iter().map(|(n, _)| n).collect::<Vec<_>>(),
        "agents/src/builtins.rs lists {dir} (sorted)"
    );
    for ((name, a), (_, b)) in embedded.iter().zip(&on_disk) {
        assert!(a == b, "{name}: the embedded copy differs from the file");
    }
}
