//! The robots this server plays, each in an arena of its own: `default` (the shipped robot, always)
//! and `myochallenge` (MyoSuite's, when `rally model import myosuite` has written it to the data
//! directory). An agent plays one robot (its checkpoint's `model`); a match, tournament or SPRT is
//! between agents of one robot; leaderboards, ratings and continuous mode are per robot.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use sim::config::{ArenaConfig, DEFAULT_ROBOT};
use sim::model::Model;

/// MyoSuite's robot's name.
pub const MYOCHALLENGE: &str = "myochallenge";
/// Every robot a server may play besides the default one: their built-ins' names begin with
/// `ROBOT-`, which submissions may not take (before the robot is imported either).
pub const OTHER_ROBOTS: &[&str] = &[MYOCHALLENGE];
/// Where `rally model import myosuite` writes MyoSuite's robot, under the data directory.
pub const MYOCHALLENGE_FILE: &str = "models/myochallenge.xml";

/// One robot and the arena configuration (grip, P2's draws) it plays with.
#[derive(Clone)]
pub struct Arena {
    /// Its name ([`sim::config::robot_name`]).
    pub name: String,
    /// The robot.
    pub model: Arc<Model>,
    /// Its arena configuration.
    pub config: ArenaConfig,
}

/// The arenas of a server: the default robot's first.
#[derive(Clone)]
pub struct Arenas {
    list: Arc<Vec<Arena>>,
}

impl Arenas {
    /// The default robot's arena alone.
    pub fn default_only() -> Arenas {
        Arenas {
            list: Arc::new(vec![Arena {
                name: DEFAULT_ROBOT.into(),
                model: Arc::new(sim::config::default_model()),
                config: ArenaConfig::default(),
            }]),
        }
    }

    /// The default robot's arena and MyoSuite's when `data_dir` has it: a file that is there but
    /// does not load is an error (the server would otherwise silently drop that robot's agents); a
    /// missing one is logged with the command that imports it.
    pub fn load(data_dir: &Path) -> anyhow::Result<Arenas> {
        let mut list = Arc::unwrap_or_clone(Arenas::default_only().list);
        let path = myochallenge_path(data_dir);
        if path.exists() {
            list.push(myochallenge_arena(&path)?);
        } else {
            tracing::info!(
                file = %path.display(),
                "MyoSuite's MyoChallenge robot is not imported: its arena is closed (`rally model import myosuite` imports it; restart the server then)"
            );
        }
        let arenas = Arenas {
            list: Arc::new(list),
        };
        tracing::info!(robots = %arenas.names(), "the robots this process plays");
        Ok(arenas)
    }

    /// The arena of the robot called `name`.
    pub fn get(&self, name: &str) -> Option<&Arena> {
        self.list.iter().find(|a| a.name == name)
    }

    /// The default robot's arena.
    pub fn default_arena(&self) -> &Arena {
        &self.list[0]
    }

    /// Every arena, the default robot's first.
    pub fn iter(&self) -> impl Iterator<Item = &Arena> {
        self.list.iter()
    }

    /// The robots' names, as an error message lists them.
    pub fn names(&self) -> String {
        self.list
            .iter()
            .map(|a| a.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The arena of `name`, or why this server has none: the robots it plays, and for MyoSuite's,
    /// how to import it.
    pub fn require(&self, name: &str) -> Result<&Arena, String> {
        self.get(name).ok_or_else(|| {
            let hint = if name == MYOCHALLENGE {
                " (its operator imports it with `rally model import myosuite` and restarts it)"
            } else {
                ""
            };
            format!(
                "this server plays no robot '{name}'{hint}; it plays: {}",
                self.names()
            )
        })
    }
}

/// What a built-in agent of robot `robot` is called: `name` on the default robot, `ROBOT-name` on
/// any other (agent names are unique across robots: `scripted` and `myochallenge-scripted`).
pub fn builtin_name(robot: &str, name: &str) -> String {
    if robot == DEFAULT_ROBOT {
        name.to_string()
    } else {
        format!("{robot}-{name}")
    }
}

/// Why a submission may not take `name`: it is spelled as another robot's built-in (`ROBOT-…`,
/// in any case), whether that robot is imported yet or not.
pub fn reserved_name(name: &str) -> Option<String> {
    OTHER_ROBOTS.iter().find_map(|robot| {
        let prefix = format!("{robot}-");
        name.to_ascii_lowercase().starts_with(&prefix).then(|| {
            format!("names beginning with '{prefix}' are kept for the {robot} robot's built-ins")
        })
    })
}

/// Where MyoSuite's robot is imported, under `data_dir`.
pub fn myochallenge_path(data_dir: &Path) -> PathBuf {
    data_dir.join(MYOCHALLENGE_FILE)
}

/// MyoSuite's robot read from `path`, with MyoChallenge's arena configuration, checked to fit it.
pub fn myochallenge_arena(path: &Path) -> anyhow::Result<Arena> {
    let model = sim::mjcf::load(path, &|p| std::fs::read_to_string(p))
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let name = sim::config::robot_name(&model).to_string();
    if name != MYOCHALLENGE {
        anyhow::bail!(
            "{}: the robot is called '{name}', not '{MYOCHALLENGE}' (import it again with `rally model import myosuite`)",
            path.display()
        );
    }
    let model = Arc::new(model);
    let config = ArenaConfig::myochallenge();
    sim::robot::Robot::new(model.clone(), &config.grip, sim::Side::A)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(Arena {
        name,
        model,
        config,
    })
}
