//! The arena configuration (`config/arena.toml`): the robot model each side plays with and the grip
//! constants. Parsing only: the caller reads files. The shipped file and model are compiled in as the
//! defaults, so a match is reproducible from the simulator's version alone.

use serde::Deserialize;

/// The shipped `config/arena.toml`.
pub const DEFAULT_ARENA_TOML: &str = include_str!("../../config/arena.toml");
/// The arena configuration for MyoSuite's MyoChallenge robot, `config/myochallenge.toml`.
pub const MYOCHALLENGE_ARENA_TOML: &str = include_str!("../../config/myochallenge.toml");
/// The shipped robot, `config/models/upper_body.xml`.
pub const DEFAULT_MODEL_XML: &str = include_str!("../../config/models/upper_body.xml");

/// The name that `--model`, checkpoints and the server give the shipped robot.
pub const DEFAULT_ROBOT: &str = "default";
/// The shipped robot's own name in its MJCF (`<mujoco model>`).
const DEFAULT_MJCF_NAME: &str = "muscle_rally_upper_body";

/// The name a robot goes by in checkpoints and in the server: [`DEFAULT_ROBOT`] for the shipped
/// robot, its MJCF name (`<mujoco model>`) for any other (`myochallenge` for MyoSuite's, as
/// `rally model import myosuite` writes it).
pub fn robot_name(model: &crate::model::Model) -> &str {
    if model.name == DEFAULT_MJCF_NAME {
        DEFAULT_ROBOT
    } else {
        &model.name
    }
}

/// The shipped robot, parsed: the one place [`DEFAULT_MODEL_XML`] is read (it is compiled in and
/// the tests load it, so it always parses).
pub fn default_model() -> crate::model::Model {
    crate::mjcf::parse_str(DEFAULT_MODEL_XML, "config/models/upper_body.xml")
        .expect("the shipped config/models/upper_body.xml is valid")
}

/// Grip constants (docs/design.md §5), as `[grip]` in `config/arena.toml` documents them.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripParams {
    /// Body that holds the paddle.
    pub hand_body: String,
    /// The paddle's body in the model, welded to the hand at its nominal pose.
    pub paddle_body: String,
    /// Muscles whose pull squeezes the handle.
    pub muscles: Vec<String>,
    /// Coulomb friction between hand and handle.
    pub friction: f64,
    /// Lever arm of the squeeze against twisting, m.
    pub lever_arm: f64,
    /// Distance from the nominal pose within which a slipping paddle can be regained, m.
    pub regain_distance: f64,
    /// Largest speed of the paddle relative to its nominal pose at which it can be regained, m/s.
    pub regain_speed: f64,
    /// Grip capacity needed to regain it, N.
    pub regain_force: f64,
    /// Distance from the nominal pose beyond which the paddle is dropped, m.
    pub drop_distance: f64,
    /// Activation of the grip muscles at the start of an episode or rally.
    pub initial_activation: f64,
}

/// Rally limits.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RallyParams {
    /// Legal returns after which a rally ends as CAPPED.
    pub cap: u32,
    /// Simulated seconds after which a rally ends as CAPPED.
    pub max_seconds: f64,
}

/// What MyoChallenge's P2 draws per episode besides the ball (MyoSuite's `paddle_mass_range` and
/// `ball_friction_range`), uniformly, from the episode's seed after the serve: `[p2]` in an arena's
/// configuration (the MyoChallenge robot's has it; the default robot's P2 draws the ball only).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct P2Draws {
    /// The paddle's mass, kg (its inertia scaled with it).
    pub paddle_mass: [f64; 2],
    /// The ball's sliding friction (the scene's is 1.0; MyoSuite draws the torsional and rolling
    /// coefficients too). Kept with the episode; see `SingleServe::ball_friction` for why it
    /// changes no contact law of ours.
    pub ball_friction: [f64; 2],
}

/// Everything in `config/arena.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArenaConfig {
    /// Robot model file, relative to the configuration file.
    pub model: String,
    /// Grip constants.
    pub grip: GripParams,
    /// Rally limits.
    pub rally: RallyParams,
    /// What P2 draws per episode besides the ball, if anything.
    #[serde(default)]
    pub p2: Option<P2Draws>,
}

impl ArenaConfig {
    /// Parses and checks a configuration; the error says which field is wrong.
    pub fn from_toml(text: &str) -> Result<ArenaConfig, String> {
        let c: ArenaConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        let g = &c.grip;
        let positive = [
            ("grip.friction", g.friction),
            ("grip.lever_arm", g.lever_arm),
            ("grip.regain_distance", g.regain_distance),
            ("grip.regain_speed", g.regain_speed),
            ("grip.drop_distance", g.drop_distance),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        if !(g.regain_force.is_finite() && g.regain_force >= 0.0) {
            return Err(format!(
                "grip.regain_force must be a number ≥ 0, got {}",
                g.regain_force
            ));
        }
        if g.regain_distance >= g.drop_distance {
            return Err("grip.regain_distance must be smaller than grip.drop_distance".into());
        }
        if !(0.0..=1.0).contains(&g.initial_activation) {
            return Err(format!(
                "grip.initial_activation must be in [0, 1], got {}",
                g.initial_activation
            ));
        }
        if c.rally.cap == 0 || !(c.rally.max_seconds.is_finite() && c.rally.max_seconds > 0.0) {
            return Err("rally.cap must be at least 1 and rally.max_seconds positive".into());
        }
        if g.muscles.is_empty() {
            return Err("grip.muscles must name at least one muscle".into());
        }
        if let Some(p2) = &c.p2 {
            for (name, [lo, hi]) in [
                ("p2.paddle_mass", p2.paddle_mass),
                ("p2.ball_friction", p2.ball_friction),
            ] {
                if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi) {
                    return Err(format!(
                        "{name} must be [low, high] with 0 < low <= high, got [{lo}, {hi}]"
                    ));
                }
            }
        }
        Ok(c)
    }
}

impl ArenaConfig {
    /// The configuration for MyoSuite's MyoChallenge robot (`config/myochallenge.toml`).
    pub fn myochallenge() -> ArenaConfig {
        ArenaConfig::from_toml(MYOCHALLENGE_ARENA_TOML)
            .expect("the shipped config/myochallenge.toml is valid")
    }
}

impl Default for ArenaConfig {
    fn default() -> Self {
        ArenaConfig::from_toml(DEFAULT_ARENA_TOML).expect("the shipped config/arena.toml is valid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_parses_and_bad_values_are_named() {
        let c = ArenaConfig::default();
        assert_eq!(c.grip.muscles, ["FDS", "FDP", "FPL"]);
        assert_eq!(ArenaConfig::myochallenge().grip.hand_body, "capitate_r");
        let bad = DEFAULT_ARENA_TOML.replace("drop_distance = 0.10", "drop_distance = -1");
        assert!(ArenaConfig::from_toml(&bad)
            .unwrap_err()
            .contains("grip.drop_distance"));
        let bad = DEFAULT_ARENA_TOML.replace("friction = 1.0", "friction = 1.0\nfrition = 2");
        assert!(ArenaConfig::from_toml(&bad)
            .unwrap_err()
            .contains("frition"));
    }
}
