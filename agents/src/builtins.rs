//! The built-in checkpoints, compiled into the binary from `config/checkpoints/` so that `rally` finds
//! them from any directory (`rally eval kmac`, the server's built-in agents).

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

/// The built-in checkpoint called `name`, as JSON text.
pub fn checkpoint(name: &str) -> Option<&'static str> {
    CHECKPOINTS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}

/// The built-in checkpoints' names.
pub fn names() -> Vec<&'static str> {
    CHECKPOINTS.iter().map(|(n, _)| *n).collect()
}
