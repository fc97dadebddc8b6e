//! The match runner (docs/design.md §7–8): two players, `n` rallies with alternating servers in the dual arena,
//! each rally's length, server, end and failing side, every hitting-plane crossing, the trajectory
//! drift statistics, and a replay at 50 Hz. A match is a deterministic function of (simulator version,
//! preset, players, seed): same inputs, same bytes.

mod drift;

pub use drift::*;

use std::ops::ControlFlow;
use std::sync::Arc;

use serde::Serialize;
use sim::arena::{Preset, Side};
use sim::ball::BallState;
use sim::config::ArenaConfig;
use sim::episode::{Crossing, Rally, StepReport};
use sim::model::Model;
use sim::rng::Rng;

use crate::factory::PlayerSpec;
use crate::player::Player;
use crate::seeds::episode_seeds;

/// Replay frames per second (every second control step).
pub const REPLAY_HZ: usize = 50;

/// A match to play.
#[derive(Debug, Clone)]
pub struct MatchSpec {
    /// The robot model both sides use.
    pub model: Arc<Model>,
    /// Arena constants (grip, rally cap).
    pub config: ArenaConfig,
    /// Contact laws.
    pub preset: Preset,
    /// Rallies to play; A serves the even ones, B the odd ones.
    pub rallies: u32,
    /// Match seed.
    pub seed: u64,
    /// Record replay frames.
    pub replay: bool,
}

/// One crossing as recorded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CrossingRecord {
    /// Side receiving the ball ("a" or "b").
    pub receiver: &'static str,
    /// 0 for the serve, k for the k-th return.
    pub exchange: u32,
    /// Receiver-frame lateral position, m.
    pub y_r: f64,
    /// Height, m.
    pub z: f64,
    /// Inside the serve box.
    pub in_box: bool,
    /// Extrapolated (the receiver hit the ball before the plane).
    pub extrapolated: bool,
}

impl From<&Crossing> for CrossingRecord {
    fn from(c: &Crossing) -> Self {
        CrossingRecord {
            receiver: c.receiver.name(),
            exchange: c.exchange,
            y_r: c.y_r,
            z: c.z,
            in_box: c.in_box,
            extrapolated: c.extrapolated,
        }
    }
}

/// One rally.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RallyRecord {
    /// 0-based index in the match.
    pub index: u32,
    /// Who served.
    pub server: &'static str,
    /// Legal returns.
    pub length: u32,
    /// How it ended (a failure's name or CAPPED).
    pub end: &'static str,
    /// Who failed (null when capped).
    pub failing_side: Option<&'static str>,
    /// Simulated duration, s.
    pub duration: f64,
    /// Every incoming ball's crossing of its receiver's plane.
    pub crossings: Vec<CrossingRecord>,
}

/// A replay frame: ball, both paddles (position and quaternion w, x, y, z), both robots' qpos and
/// activations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Frame {
    /// Time in the rally, s.
    pub t: f64,
    /// Ball centre.
    pub ball: [f64; 3],
    /// Paddle A: position then quaternion.
    pub paddle_a: [f64; 7],
    /// Paddle B.
    pub paddle_b: [f64; 7],
    /// Robot A's joint positions.
    pub qpos_a: Vec<f64>,
    /// Robot B's joint positions.
    pub qpos_b: Vec<f64>,
    /// Robot A's actuator activations (muscles; 0 for servos), for colouring its muscles.
    pub act_a: Vec<f64>,
    /// Robot B's activations.
    pub act_b: Vec<f64>,
}

/// Everything a match produced.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MatchRecord {
    /// Player A's name.
    pub a: String,
    /// Player B's name.
    pub b: String,
    /// Match seed.
    pub seed: u64,
    /// Arena preset.
    pub preset: &'static str,
    /// Simulator version.
    pub sim_version: &'static str,
    /// Rallies.
    pub rallies: Vec<RallyRecord>,
    /// Points won by A and by B (a rally is a point for the side that did not fail; CAPPED is none).
    pub points: [u32; 2],
    /// Mean rally length (the cooperative score).
    pub mean_rally_length: f64,
    /// Longest rally.
    pub max_rally_length: u32,
    /// Drift statistics of every crossing in the match.
    pub drift: DriftStats,
    /// Drift of the returns each player produced (crossings at the opponent's plane, exchange ≥ 1, plus
    /// all serves as the reference): [A, B].
    pub drift_by_player: [DriftStats; 2],
}

/// Replay frames of each rally, at [`REPLAY_HZ`].
pub type Replay = Vec<Vec<Frame>>;

fn frame(rally: &Rally, t0: f64) -> Frame {
    let pose = |r: &sim::robot::Robot| {
        let p = r.ball_paddle();
        let q = p.pose.rot.quaternion();
        [p.pose.pos.x, p.pose.pos.y, p.pose.pos.z, q.w, q.i, q.j, q.k]
    };
    let b = rally.arena.world.ball.pos;
    Frame {
        t: rally.arena.world.time - t0,
        ball: [b.x, b.y, b.z],
        paddle_a: pose(&rally.arena.robots[0]),
        paddle_b: pose(&rally.arena.robots[1]),
        qpos_a: rally.arena.robots[0].state.qpos.clone(),
        qpos_b: rally.arena.robots[1].state.qpos.clone(),
        act_a: rally.arena.robots[0].state.act.clone(),
        act_b: rally.arena.robots[1].state.act.clone(),
    }
}

/// Plays a match between `a` (side A) and `b` (side B); `progress(k)` is called after rally k.
pub fn play_match(
    spec: &MatchSpec,
    a: &PlayerSpec,
    b: &PlayerSpec,
    progress: &mut dyn FnMut(u32),
) -> Result<(MatchRecord, Replay), String> {
    let players = [
        a.build(&spec.model, &spec.preset, 0)?,
        b.build(&spec.model, &spec.preset, 0)?,
    ];
    play_match_with(spec, players, [a.name(), b.name()], &mut |e| {
        if let MatchEvent::Rally { rally, .. } = e {
            progress(rally)
        }
        ControlFlow::Continue(())
    })
}

/// What [`play_match_with`] tells its caller while a match is played, e.g. to show it live.
#[derive(Debug, Clone, Copy)]
pub enum MatchEvent<'a> {
    /// Rally `rally` recorded a replay frame (at [`REPLAY_HZ`]; only when the spec keeps frames).
    Frame {
        /// The rally's index.
        rally: u32,
        /// The frame, as it goes into the replay.
        frame: &'a Frame,
    },
    /// Rally `rally` is over: its record and all its frames (empty unless the spec keeps frames).
    Rally {
        /// The rally's index.
        rally: u32,
        /// Its record.
        record: &'a RallyRecord,
        /// Its replay frames, the same the `Frame` events gave one by one.
        frames: &'a [Frame],
    },
}

/// [`play_match`] with players already built (named for the record); `on_event` hears of every
/// replay frame as it is recorded and of every rally as it ends. A `Break` from it stops the match
/// at the end of the rally being played (its worker is free for the next match): an error that
/// says after how many rallies.
pub fn play_match_with(
    spec: &MatchSpec,
    mut players: [Box<dyn Player>; 2],
    names: [String; 2],
    on_event: &mut dyn FnMut(MatchEvent<'_>) -> ControlFlow<()>,
) -> Result<(MatchRecord, Replay), String> {
    let mut rally = Rally::new(spec.model.clone(), &spec.config, spec.preset)?;
    let mut records = Vec::new();
    let mut replay: Replay = Vec::new();
    let mut points = [0u32; 2];
    for k in 0..spec.rallies {
        let mut stop = false;
        let (record, frames, loser) = play_rally(
            &mut rally,
            &mut players,
            spec,
            k,
            &mut |frame| stop |= on_event(MatchEvent::Frame { rally: k, frame }).is_break(),
            &mut |_, _| {},
        );
        if let Some(loser) = loser {
            points[match loser {
                Side::A => 1,
                Side::B => 0,
            }] += 1;
        }
        stop |= on_event(MatchEvent::Rally {
            rally: k,
            record: &record,
            frames: &frames,
        })
        .is_break();
        if stop {
            return Err(format!(
                "stopped after {} of {} rallies",
                k + 1,
                spec.rallies
            ));
        }
        records.push(record);
        replay.push(frames);
    }
    let all: Vec<CrossingRecord> = records
        .iter()
        .flat_map(|r| r.crossings.iter().copied())
        .collect();
    // Player X's returns arrive at the other side's plane; the serves (exchange 0) are the reference.
    let by = |hitter: Side| -> DriftStats {
        let receiver = hitter.other().name();
        let mine: Vec<CrossingRecord> = all
            .iter()
            .copied()
            .filter(|c| c.exchange == 0 || c.receiver == receiver)
            .collect();
        drift_stats(&mine)
    };
    let lengths: Vec<u32> = records.iter().map(|r| r.length).collect();
    let [name_a, name_b] = names;
    let record = MatchRecord {
        a: name_a,
        b: name_b,
        seed: spec.seed,
        preset: spec.preset.name,
        sim_version: sim::SIM_VERSION,
        mean_rally_length: if lengths.is_empty() {
            0.0
        } else {
            lengths.iter().sum::<u32>() as f64 / lengths.len() as f64
        },
        max_rally_length: lengths.iter().copied().max().unwrap_or(0),
        points,
        drift: drift_stats(&all),
        drift_by_player: [by(Side::A), by(Side::B)],
        rallies: records,
    };
    Ok((record, replay))
}

/// The rally records of the match `spec` describes between `a` (side A) and `b`, without replay
/// frames, played in parallel: one arena and one pair of players per rayon worker, each taking the
/// next rally index. Rallies are independent, so record k equals rally k of [`play_match`] whatever
/// the number of threads (a test checks it); no drift statistics, no points (training's
/// validation uses it).
pub fn play_rallies(
    spec: &MatchSpec,
    a: &PlayerSpec,
    b: &PlayerSpec,
) -> Result<Vec<RallyRecord>, String> {
    par_rallies(spec, a, b, |rally, players, spec, k| {
        play_rally(rally, players, spec, k, &mut |_| {}, &mut |_, _| {}).0
    })
}

/// Every legal return of the match `spec` describes between `a` and `b`, as its receiver met it: the
/// ball [`crate::env::TASK_DELAY_STEPS`] control steps after the stroke's first paddle contact (where
/// training judges a stroke), turned into the frame of a ball struck by B towards A (a half turn
/// about the vertical for A's returns), in rally order. Only returns that landed on the other half
/// count. Played like [`play_rallies`]; a ball bank for training on the balls a rally brings
/// (`[bank]` in a training configuration, `rally match --returns`).
pub fn record_returns(
    spec: &MatchSpec,
    a: &PlayerSpec,
    b: &PlayerSpec,
) -> Result<Vec<BallState>, String> {
    let per_rally = par_rallies(spec, a, b, |rally, players, spec, k| {
        let mut tracker = ReturnTracker::default();
        play_rally(rally, players, spec, k, &mut |_| {}, &mut |r, report| {
            tracker.step(r, report)
        });
        tracker.returns
    })?;
    Ok(per_rally.into_iter().flatten().collect())
}

/// `play(rally, players, spec, k)` for every rally k of the match, without replay frames, in
/// parallel (one arena and pair of players per rayon worker), results in rally order.
fn par_rallies<T: Send>(
    spec: &MatchSpec,
    a: &PlayerSpec,
    b: &PlayerSpec,
    play: impl Fn(&mut Rally, &mut [Box<dyn Player>; 2], &MatchSpec, u32) -> T + Sync,
) -> Result<Vec<T>, String> {
    let build = || -> Result<([Box<dyn Player>; 2], Rally), String> {
        Ok((
            [
                a.build(&spec.model, &spec.preset, 0)?,
                b.build(&spec.model, &spec.preset, 0)?,
            ],
            Rally::new(spec.model.clone(), &spec.config, spec.preset)?,
        ))
    };
    // Fail early, once, on anything wrong with the players or the arena.
    build()?;
    let spec = MatchSpec {
        replay: false,
        ..spec.clone()
    };
    Ok(crate::seeds::par_indexed(
        spec.rallies as usize,
        || build().expect("checked above"),
        |(players, rally), k| play(rally, players, &spec, k as u32),
    ))
}

/// Follows one rally for [`record_returns`].
#[derive(Default)]
struct ReturnTracker {
    /// The side whose stroke is in flight and the control steps since its first contact.
    stroke: Option<(Side, usize)>,
    /// That stroke's ball, once taken, waiting for the referee's verdict.
    pending: Option<(Side, BallState)>,
    returns: Vec<BallState>,
}

impl ReturnTracker {
    fn step(&mut self, rally: &Rally, report: &StepReport) {
        for e in &report.events {
            if let sim::ContactKind::Paddle { owner } = e.kind {
                if self.stroke.is_none_or(|(s, _)| s != owner) {
                    self.stroke = Some((owner, 0));
                    self.pending = None;
                }
            }
        }
        if let Some((side, n)) = self.stroke.as_mut() {
            *n += 1;
            if *n == crate::env::TASK_DELAY_STEPS {
                self.pending = Some((*side, rally.arena.world.ball));
            }
        }
        for call in &report.calls {
            if let sim::rules::Call::LegalReturn { hitter, .. } = call {
                if let Some((side, ball)) = self.pending.take() {
                    if side == *hitter {
                        self.returns.push(struck_by_b(side, ball));
                    }
                }
            }
        }
    }
}

/// `ball`, struck by `hitter`, in the frame where B struck it (a half turn about z for A).
fn struck_by_b(hitter: Side, ball: BallState) -> BallState {
    match hitter {
        Side::B => ball,
        Side::A => {
            let turn = |v: nalgebra::Vector3<f64>| nalgebra::Vector3::new(-v.x, -v.y, v.z);
            BallState {
                pos: turn(ball.pos),
                vel: turn(ball.vel),
                spin: turn(ball.spin),
            }
        }
    }
}

/// Plays rally `k` of a match on `rally` (reset first: every rally starts from the ready pose with its
/// own serve and agent seeds, so it depends on nothing but the match seed and `k`); its record, its
/// replay frames (empty unless `spec.replay`; each also given to `on_frame` as it is recorded) and
/// the side that failed.
fn play_rally(
    rally: &mut Rally,
    players: &mut [Box<dyn Player>; 2],
    spec: &MatchSpec,
    k: u32,
    on_frame: &mut dyn FnMut(&Frame),
    on_step: &mut dyn FnMut(&Rally, &StepReport),
) -> (RallyRecord, Vec<Frame>, Option<Side>) {
    let mut ctrl = vec![0.0; spec.model.actuators.len()];
    let server = if k.is_multiple_of(2) {
        Side::A
    } else {
        Side::B
    };
    let (serve_seed, agent_seed) = episode_seeds(spec.seed, k as usize);
    rally.reset(server, &mut Rng::seeded(serve_seed), None);
    let t0 = rally.arena.world.time;
    for (i, p) in players.iter_mut().enumerate() {
        p.reset();
        p.reseed(agent_seed.wrapping_add(i as u64));
    }
    let mut frames = Vec::new();
    let every = (1.0 / (sim::arena::CONTROL_DT * REPLAY_HZ as f64))
        .round()
        .max(1.0) as usize;
    let mut step = 0usize;
    loop {
        if spec.replay && step.is_multiple_of(every) {
            frames.push(frame(rally, t0));
            on_frame(frames.last().expect("just pushed"));
        }
        let mut invalid = None;
        for (i, side) in [Side::A, Side::B].into_iter().enumerate() {
            let robot = &rally.arena.robots[i];
            ctrl.copy_from_slice(&robot.state.ctrl);
            let ball = rally.arena.world.ball;
            let ok = players[i]
                .act(robot, &ball, rally.arena.world.time, &mut ctrl)
                .is_ok()
                && ctrl.iter().all(|c| c.is_finite());
            if ok {
                rally.arena.robots[i].state.ctrl.copy_from_slice(&ctrl);
            } else if invalid.is_none() {
                invalid = Some(side);
            }
        }
        if let Some(side) = invalid {
            rally.invalid_action(side);
            break;
        }
        step += 1;
        let report = rally.step();
        on_step(rally, &report);
        if report.done {
            break;
        }
    }
    if spec.replay {
        frames.push(frame(rally, t0));
        on_frame(frames.last().expect("just pushed"));
    }
    let end = rally.referee.end().expect("a finished rally has an end");
    let record = RallyRecord {
        index: k,
        server: server.name(),
        length: rally.referee.rally_length(),
        end: end.reason.name(),
        failing_side: end.failing_side.map(Side::name),
        duration: rally.arena.world.time - t0,
        crossings: rally.crossings.iter().map(CrossingRecord::from).collect(),
    };
    (record, frames, end.failing_side)
}

/// Re-plays rally `k` of the match `spec` describes, alone and with replay frames: the same record
/// and frames, bit for bit, as rally `k` of [`play_match`] with `spec.replay` set.
pub fn replay_rally(
    spec: &MatchSpec,
    a: &PlayerSpec,
    b: &PlayerSpec,
    k: u32,
) -> Result<(RallyRecord, Vec<Frame>), String> {
    if k >= spec.rallies {
        return Err(format!(
            "the match has rallies 0 to {}",
            spec.rallies.saturating_sub(1)
        ));
    }
    let mut players = [
        a.build(&spec.model, &spec.preset, 0)?,
        b.build(&spec.model, &spec.preset, 0)?,
    ];
    let mut rally = Rally::new(spec.model.clone(), &spec.config, spec.preset)?;
    let spec = MatchSpec {
        replay: true,
        ..spec.clone()
    };
    let (record, frames, _) = play_rally(
        &mut rally,
        &mut players,
        &spec,
        k,
        &mut |_| {},
        &mut |_, _| {},
    );
    Ok((record, frames))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn energy_distance_is_zero_for_equal_samples_and_grows_with_a_shift() {
        let x = [[0.0, 1.2], [0.3, 1.25], [-0.2, 1.15]];
        assert!(energy_distance(&x, &x).unwrap().abs() < 1e-12);
        let shifted: Vec<[f64; 2]> = x.iter().map(|p| [p[0] + 0.5, p[1]]).collect();
        let far: Vec<[f64; 2]> = x.iter().map(|p| [p[0] + 1.5, p[1]]).collect();
        let (d1, d2) = (
            energy_distance(&x, &shifted).unwrap(),
            energy_distance(&x, &far).unwrap(),
        );
        assert!(d1 > 0.0 && d2 > d1);
        assert!(energy_distance(&x, &[]).is_none());
    }

    #[test]
    fn drift_slope_follows_a_growing_offset() {
        let mut c = Vec::new();
        for k in 0..4u32 {
            for i in 0..5 {
                c.push(CrossingRecord {
                    receiver: "a",
                    exchange: k,
                    y_r: 0.1 * i as f64 + 0.2 * k as f64,
                    z: 1.2,
                    in_box: true,
                    extrapolated: false,
                });
            }
        }
        let s = drift_stats(&c);
        assert_eq!(s.by_exchange.len(), 4);
        assert!((s.by_exchange[0].mean[0] - 0.2).abs() < 1e-12);
        assert!(s.drift_slope.unwrap() > 0.0);
        assert_eq!(s.in_box_fraction, 1.0);
    }
}
