//! Every checkpoint committed under `config/checkpoints/` loads and validates against the default
//! robot, carries its training provenance, and plays a few episodes; a checkpoint that no longer fits
//! the code fails here rather than where a user meets it.

use std::sync::Arc;

use agents::checkpoint::Checkpoint;

#[test]
fn committed_checkpoints_load_validate_and_play() {
    let m = Arc::new(
        sim::mjcf::parse_str(sim::config::DEFAULT_MODEL_XML, "upper_body.xml").expect("model"),
    );
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
            model: m.clone(),
            config: sim::config::ArenaConfig::default(),
            preset: sim::arena::MYOCHALLENGE,
            kind: sim::serve::ServeKind::P2,
            episodes: 4,
            seed: 99,
        };
        let spec = agents::player::PlayerSpec::Checkpoint(Arc::new(c));
        agents::eval::evaluate(&e, &spec, &|| {}).unwrap();
        seen += 1;
    }
    assert!(seen >= 1, "no committed checkpoint in {dir}");
}
