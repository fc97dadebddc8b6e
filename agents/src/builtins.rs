//! The built-in checkpoints, compiled into the binary from `config/checkpoints/` (the default robot's)
//! and `config/checkpoints/ROBOT/` (another robot's) so that `rally` finds them from any directory
//! (`rally eval kmac`, `rally eval kmac --model myochallenge`, the server's built-in agents).

/// Every file of `config/checkpoints/` as (name, JSON text): `NAME.json` is agent `NAME`. A test holds
/// this list to the directory.
pub const CHECKPOINTS: &[(&str, &str)] = &[
    (
        "dynsyn",
        include_str!("../../config/checkpoints/dynsyn.json"),
    ),
    ("kmac", include_str!("../../config/checkpoints/kmac.json")),
    (
        "kmac-rally",
        include_str!("../../config/checkpoints/kmac-rally.json"),
    ),
    (
        "muscle-pd",
        include_str!("../../config/checkpoints/muscle-pd.json"),
    ),
    (
        "muscle-ppo",
        include_str!("../../config/checkpoints/muscle-ppo.json"),
    ),
];

/// Every file of `config/checkpoints/myochallenge/`, MyoSuite's robot's, as [`CHECKPOINTS`] lists
/// the default robot's. A test holds this list to the directory.
pub const MYOCHALLENGE_CHECKPOINTS: &[(&str, &str)] = &[
    (
        "dynsyn",
        include_str!("../../config/checkpoints/myochallenge/dynsyn.json"),
    ),
    (
        "kmac",
        include_str!("../../config/checkpoints/myochallenge/kmac.json"),
    ),
    (
        "muscle-pd",
        include_str!("../../config/checkpoints/myochallenge/muscle-pd.json"),
    ),
    (
        "muscle-ppo",
        include_str!("../../config/checkpoints/myochallenge/muscle-ppo.json"),
    ),
];

/// The built-in checkpoints of robot `robot` ([`sim::config::robot_name`]).
pub fn of_robot(robot: &str) -> &'static [(&'static str, &'static str)] {
    match robot {
        sim::config::DEFAULT_ROBOT => CHECKPOINTS,
        "myochallenge" => MYOCHALLENGE_CHECKPOINTS,
        _ => &[],
    }
}

/// The default robot's built-in checkpoint called `name`, as JSON text.
pub fn checkpoint(name: &str) -> Option<&'static str> {
    checkpoint_of(sim::config::DEFAULT_ROBOT, name)
}

/// Robot `robot`'s built-in checkpoint called `name`, as JSON text.
pub fn checkpoint_of(robot: &str, name: &str) -> Option<&'static str> {
    of_robot(robot)
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}

/// The default robot's built-in checkpoints' names.
pub fn names() -> Vec<&'static str> {
    names_of(sim::config::DEFAULT_ROBOT)
}

/// Robot `robot`'s built-in checkpoints' names.
pub fn names_of(robot: &str) -> Vec<&'static str> {
    of_robot(robot).iter().map(|(n, _)| *n).collect()
}
