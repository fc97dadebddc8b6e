//! A batch plan (`rally batch PLAN.toml`): what it may say, and the requests it turns into.
//!
//! Parsing and checking only: no I/O, nothing but serde and toml, so that the fuzz target
//! `fuzz/fuzz_targets/batch_plan.rs` compiles this very file (`#[path]`) without the CLI. The jobs
//! are plain data; `rally batch` turns them into the server's request types (the `wire` crate).

use std::collections::HashMap;

use serde::Deserialize;

/// The most matches one plan may submit (entries times their repeats): a plan is typed by a person,
/// and a typo such as `repeat = 10000` on many entries must not build millions of requests.
pub const MAX_MATCHES: usize = 100_000;

/// Reads a plan from its TOML text.
pub fn parse(text: &str) -> Result<Plan, String> {
    toml::from_str(text).map_err(|e| e.to_string())
}

/// An agent in a plan: its name or its id.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum AgentRef {
    Id(i64),
    Name(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// The robot whose agents the plan names (`default`, `myochallenge`): agents meet only agents
    /// of their own robot.
    #[serde(default = "default_model")]
    model: String,
    #[serde(default = "default_rallies")]
    rallies: u32,
    #[serde(default = "default_seed")]
    seed: u64,
    #[serde(default, rename = "match")]
    matches: Vec<PlanMatch>,
    #[serde(default, rename = "tournament")]
    tournaments: Vec<PlanTournament>,
    #[serde(default, rename = "sprt")]
    sprts: Vec<PlanSprt>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlanSprt {
    a: AgentRef,
    b: AgentRef,
    elo0: Option<f64>,
    elo1: Option<f64>,
    alpha: Option<f64>,
    beta: Option<f64>,
    rallies_per_match: Option<u32>,
    max_matches: Option<u32>,
    seed: Option<u64>,
}

fn default_model() -> String {
    "default".into()
}

impl Plan {
    /// The robot the plan plays.
    pub fn model(&self) -> &str {
        &self.model
    }
}

/// The server's agents as a plan sees them: those of the plan's robot by name and by id, and the
/// other robots' (id, name, robot), so that naming one says which robot it plays.
#[derive(Debug, Default)]
pub struct Roster {
    /// The plan's robot's agents by name.
    pub names: HashMap<String, i64>,
    /// Their ids.
    pub ids: Vec<i64>,
    /// Every other robot's agents: (id, name, robot).
    pub others: Vec<(i64, String, String)>,
}

fn default_rallies() -> u32 {
    20
}
fn default_seed() -> u64 {
    1
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlanMatch {
    a: AgentRef,
    b: AgentRef,
    rallies: Option<u32>,
    seed: Option<u64>,
    #[serde(default = "one")]
    repeat: u32,
}

fn one() -> u32 {
    1
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlanTournament {
    kind: String,
    agents: Vec<AgentRef>,
    rallies_per_match: Option<u32>,
    #[serde(default = "one")]
    rounds: u32,
    seed: Option<u64>,
}

/// What the plan asks for, with agents resolved to ids.
pub enum Job {
    Match {
        a: i64,
        b: i64,
        rallies: u32,
        seed: u64,
    },
    Tournament {
        /// `round_robin` or `gauntlet` (checked).
        kind: String,
        agents: Vec<i64>,
        rallies_per_match: u32,
        rounds: u32,
        seed: u64,
        label: String,
    },
    Sprt {
        a: i64,
        b: i64,
        /// H0, H1, alpha, beta where the plan gives them (the server's defaults otherwise).
        elo0: Option<f64>,
        elo1: Option<f64>,
        alpha: Option<f64>,
        beta: Option<f64>,
        rallies_per_match: u32,
        max_matches: Option<u32>,
        seed: u64,
        label: String,
    },
}

/// Turns the plan into requests, resolving agent names against the server's agents of the plan's
/// robot; a usage error for anything wrong (an agent of another robot included), before anything
/// is submitted.
pub fn jobs(plan: &Plan, roster: &Roster) -> Result<Vec<Job>, String> {
    let (agents, ids) = (&roster.names, &roster.ids);
    let elsewhere = |at: &str, found: Option<&(i64, String, String)>| {
        found.map(|(id, name, robot)| {
            format!(
                "{at}: agent {id} ('{name}') plays the {robot} robot, not this plan's {} (its `model`)",
                plan.model
            )
        })
    };
    let resolve = |r: &AgentRef, at: &str| -> Result<i64, String> {
        match r {
            AgentRef::Id(id) if ids.contains(id) => Ok(*id),
            AgentRef::Id(id) => Err(elsewhere(at, roster.others.iter().find(|o| o.0 == *id))
                .unwrap_or_else(|| format!("{at}: the server has no agent with id {id}"))),
            AgentRef::Name(n) if !agents.contains_key(n) => {
                if let Some(e) = elsewhere(at, roster.others.iter().find(|o| &o.1 == n)) {
                    return Err(e);
                }
                let mut known: Vec<&str> = agents.keys().map(String::as_str).collect();
                known.sort();
                Err(format!(
                    "{at}: the server has no agent named '{n}' (it has: {})",
                    known.join(", ")
                ))
            }
            AgentRef::Name(n) => agents.get(n).copied().ok_or_else(|| {
                let mut known: Vec<&str> = agents.keys().map(String::as_str).collect();
                known.sort();
                format!(
                    "{at}: the server has no agent named '{n}' (it has: {})",
                    known.join(", ")
                )
            }),
        }
    };
    let mut out = Vec::new();
    let mut k = 0u64;
    for (i, m) in plan.matches.iter().enumerate() {
        let at = format!("match {}", i + 1);
        let (a, b) = (resolve(&m.a, &at)?, resolve(&m.b, &at)?);
        let rallies = m.rallies.unwrap_or(plan.rallies);
        if rallies == 0 {
            return Err(format!("{at}: rallies must be at least 1"));
        }
        if m.repeat == 0 || m.repeat > 10_000 {
            return Err(format!("{at}: repeat must be between 1 and 10000"));
        }
        if out.len() + m.repeat as usize > MAX_MATCHES {
            return Err(format!(
                "{at}: the plan asks for more than {MAX_MATCHES} matches; split it into several plans"
            ));
        }
        let seed = m.seed.unwrap_or(plan.seed.wrapping_add(k));
        for r in 0..m.repeat {
            let (x, y) = if r % 2 == 0 { (a, b) } else { (b, a) };
            out.push(Job::Match {
                a: x,
                b: y,
                rallies,
                seed: seed.wrapping_add(r as u64) & (i64::MAX as u64),
            });
        }
        k += 1;
    }
    for (i, t) in plan.tournaments.iter().enumerate() {
        let at = format!("tournament {}", i + 1);
        // The API's words, spelled here too: this module builds alone in the fuzz target.
        if t.kind != "round_robin" && t.kind != "gauntlet" {
            return Err(format!(
                "{at}: kind must be round_robin or gauntlet, not '{}'",
                t.kind
            ));
        }
        let agents: Vec<i64> = t
            .agents
            .iter()
            .map(|r| resolve(r, &at))
            .collect::<Result<_, _>>()?;
        let seed = t.seed.unwrap_or(plan.seed.wrapping_add(k)) & (i64::MAX as u64);
        out.push(Job::Tournament {
            label: format!("{}, {} agents", t.kind, agents.len()),
            kind: t.kind.clone(),
            agents,
            rallies_per_match: t.rallies_per_match.unwrap_or(plan.rallies),
            rounds: t.rounds,
            seed,
        });
        k += 1;
    }
    for (i, t) in plan.sprts.iter().enumerate() {
        let at = format!("sprt {}", i + 1);
        let (a, b) = (resolve(&t.a, &at)?, resolve(&t.b, &at)?);
        if a == b {
            return Err(format!("{at}: an SPRT needs two different agents"));
        }
        let name = |id: i64| {
            agents
                .iter()
                .find(|(_, v)| **v == id)
                .map_or(format!("#{id}"), |(n, _)| n.clone())
        };
        out.push(Job::Sprt {
            a,
            b,
            elo0: t.elo0,
            elo1: t.elo1,
            alpha: t.alpha,
            beta: t.beta,
            rallies_per_match: t.rallies_per_match.unwrap_or(plan.rallies),
            max_matches: t.max_matches,
            seed: t.seed.unwrap_or(plan.seed.wrapping_add(k)) & (i64::MAX as u64),
            label: format!("{} vs {}", name(a), name(b)),
        });
        k += 1;
    }
    if out.is_empty() {
        return Err("the plan has no [[match]], [[tournament]] or [[sprt]] entry".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(text: &str) -> Plan {
        parse(text).expect("a valid plan")
    }

    #[test]
    fn repeats_swap_sides_and_count_seeds() {
        let p = plan(
            "rallies = 5\nseed = 10\n[[match]]\na = \"x\"\nb = 2\nrepeat = 3\n[[match]]\na = 2\nb = \"x\"\nseed = 99\n[[tournament]]\nkind = \"gauntlet\"\nagents = [\"x\", 2]\n",
        );
        let roster = Roster {
            names: [("x".to_string(), 1)].into(),
            ids: vec![1, 2],
            ..Roster::default()
        };
        let jobs = jobs(&p, &roster).unwrap();
        let m: Vec<(i64, i64, u32, u64)> = jobs
            .iter()
            .filter_map(|j| match j {
                Job::Match {
                    a,
                    b,
                    rallies,
                    seed,
                } => Some((*a, *b, *rallies, *seed)),
                _ => None,
            })
            .collect();
        assert_eq!(
            m,
            vec![(1, 2, 5, 10), (2, 1, 5, 11), (1, 2, 5, 12), (2, 1, 5, 99)]
        );
        let Job::Tournament {
            agents,
            seed,
            rallies_per_match,
            ..
        } = &jobs[4]
        else {
            panic!("a tournament last")
        };
        assert_eq!(agents, &[1, 2]);
        assert_eq!(*seed, 12, "the third entry: seed + 2");
        assert_eq!(*rallies_per_match, 5);
    }

    #[test]
    fn a_plan_of_too_many_matches_is_refused_before_it_is_built() {
        let entry = "[[match]]\na = 1\nb = 1\nrepeat = 10000\n";
        let roster = Roster {
            ids: vec![1],
            ..Roster::default()
        };
        let ok = plan(&entry.repeat(MAX_MATCHES / 10_000));
        assert_eq!(jobs(&ok, &roster).unwrap().len(), MAX_MATCHES);
        let over = plan(&entry.repeat(MAX_MATCHES / 10_000 + 1));
        let e = jobs(&over, &roster).err().unwrap();
        assert!(e.contains("more than 100000 matches"), "{e}");
    }

    #[test]
    fn bad_plans_are_refused_before_anything_is_sent() {
        let names = Roster {
            names: [("x".to_string(), 1)].into(),
            ids: vec![1],
            others: vec![(5, "mc".to_string(), "myochallenge".to_string())],
        };
        let unknown = plan("[[match]]\na = \"x\"\nb = \"nobody\"\n");
        let e = jobs(&unknown, &names).err().unwrap();
        assert!(
            e.contains("no agent named 'nobody'") && e.contains("it has: x"),
            "{e}"
        );
        assert!(jobs(&plan("[[match]]\na = 1\nb = 7\n"), &names).is_err());
        // Another robot's agent, by name or id: said so, with its robot.
        for other in ["\"mc\"", "5"] {
            let e = jobs(&plan(&format!("[[match]]\na = 1\nb = {other}\n")), &names)
                .err()
                .unwrap();
            assert!(
                e.contains("agent 5 ('mc') plays the myochallenge robot, not this plan's default"),
                "{e}"
            );
        }
        assert!(jobs(&plan("rallies = 3\n"), &names).is_err(), "empty plan");
        let kind = plan("[[tournament]]\nkind = \"swiss\"\nagents = [1, 1]\n");
        assert!(jobs(&kind, &names).err().unwrap().contains("swiss"));
        assert!(
            toml::from_str::<Plan>("[[match]]\na = 1\nb = 2\nrally = 3\n").is_err(),
            "unknown key"
        );
    }
}
