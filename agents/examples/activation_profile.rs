//! Where a checkpoint spends its activation in a single-serve episode: mean activation ‖a‖₁/n_a by
//! time relative to the first paddle contact (episodes without one are left out; `rally eval`
//! gives the split before and after it), how many muscles sit near full activation, and for K-MAC
//! how often each action's mean sits at a clip bound and how far its target is from the joint.
//! A diagnosis aid: `cargo run --release -p agents --example activation_profile -- CHECKPOINT
//! [episodes] [seed]`.
mod common;

use agents::player::Player;
use sim::events::ContactKind;
use sim::rng::Rng;
use sim::serve::ServeKind;

const BIN: f64 = 0.1;
const FIRST: i64 = -12;
const LAST: i64 = 12;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().expect("checkpoint file");
    let episodes: usize = common::arg(&args, 1, 200);
    let seed: u64 = common::arg(&args, 2, 4242);
    let bench = common::Bench::load(path);
    let (model, ck) = (bench.model.clone(), bench.checkpoint.clone());
    let mut env = bench.single();
    let mut player = bench.player();
    let muscles: Vec<usize> = model.muscles().map(|(i, _)| i).collect();
    let mut profile = Profile::new(muscles.len());
    let mut bounds = ActionBounds::new(&model, &ck.controller);
    for i in 0..episodes {
        let (serve_seed, agent_seed) = agents::seeds::episode_seeds(seed, i);
        env.reset(ServeKind::P2, &mut Rng::seeded(serve_seed), None);
        player.reseed(agent_seed);
        player.reset();
        let (trace, t_hit) = play(
            &mut env,
            &mut player,
            &model,
            &muscles,
            &mut profile,
            &mut bounds,
        );
        profile.add_episode(&trace, t_hit);
    }
    profile.print(path, episodes, seed, &model, &muscles);
    bounds.print(&model);
}

/// Plays one episode; returns its steps as (time, mean activation, muscles above 0.9) and the time
/// of its first paddle contact, if any. Adds each step's activations to `profile` and, for K-MAC,
/// its actions to `bounds`.
fn play(
    env: &mut sim::episode::SingleServe,
    player: &mut agents::checkpoint::CheckpointPlayer,
    model: &sim::model::Model,
    muscles: &[usize],
    profile: &mut Profile,
    bounds: &mut ActionBounds,
) -> (Vec<(f64, f64, f64)>, Option<f64>) {
    let na = muscles.len() as f64;
    let mut ctrl = vec![0.0; model.actuators.len()];
    let mut trace: Vec<(f64, f64, f64)> = Vec::new();
    let mut t_hit: Option<f64> = None;
    loop {
        if !common::act(player, env, &mut ctrl) {
            break;
        }
        bounds.add(model, player.last_mean(), &env.robot.state.qpos);
        let rep = env.step();
        let act = &env.robot.state.act;
        let l1 = muscles.iter().map(|&a| act[a]).sum::<f64>() / na;
        let s = muscles.iter().filter(|&&a| act[a] > 0.9).count() as f64;
        for (k, &a) in muscles.iter().enumerate() {
            profile.per_muscle[k] += act[a];
        }
        trace.push((env.world.time, l1, s));
        if t_hit.is_none()
            && rep
                .events
                .iter()
                .any(|e| matches!(e.kind, ContactKind::Paddle { .. }))
        {
            t_hit = Some(env.world.time);
        }
        if rep.done {
            break;
        }
    }
    (trace, t_hit)
}

/// Activation over the episodes: by time from the first contact (bins of `BIN` s), over all steps,
/// and per muscle.
struct Profile {
    sum: Vec<f64>,
    sat: Vec<f64>,
    cnt: Vec<usize>,
    all_l1: f64,
    all_steps: usize,
    hits: usize,
    per_muscle: Vec<f64>,
}

impl Profile {
    fn new(muscles: usize) -> Profile {
        let nb = (LAST - FIRST) as usize;
        Profile {
            sum: vec![0.0; nb],
            sat: vec![0.0; nb],
            cnt: vec![0; nb],
            all_l1: 0.0,
            all_steps: 0,
            hits: 0,
            per_muscle: vec![0.0; muscles],
        }
    }

    /// Adds an episode's steps; those of an episode with a contact go to their bins too.
    fn add_episode(&mut self, trace: &[(f64, f64, f64)], t_hit: Option<f64>) {
        self.all_steps += trace.len();
        self.all_l1 += trace.iter().map(|t| t.1).sum::<f64>();
        let Some(th) = t_hit else { return };
        self.hits += 1;
        for &(t, l1, s) in trace {
            let b = ((t - th) / BIN).floor() as i64;
            if (FIRST..LAST).contains(&b) {
                let k = (b - FIRST) as usize;
                self.sum[k] += l1;
                self.sat[k] += s;
                self.cnt[k] += 1;
            }
        }
    }

    /// The summary line, the bins as CSV and the most active muscles.
    fn print(
        &self,
        path: &str,
        episodes: usize,
        seed: u64,
        model: &sim::model::Model,
        muscles: &[usize],
    ) {
        println!(
            "{path}: {episodes} episodes (seed {seed}), {} with contact; mean activation over all steps {:.3}; steps per episode {:.1}",
            self.hits,
            self.all_l1 / self.all_steps as f64,
            self.all_steps as f64 / episodes as f64
        );
        println!("t_from_contact_s,mean_activation,muscles_above_0.9,steps");
        for k in 0..self.cnt.len() {
            if self.cnt[k] > 0 {
                println!(
                    "{:+.1},{:.3},{:.1},{}",
                    (FIRST + k as i64) as f64 * BIN,
                    self.sum[k] / self.cnt[k] as f64,
                    self.sat[k] / self.cnt[k] as f64,
                    self.cnt[k]
                );
            }
        }
        let mut ranked: Vec<(usize, f64)> = self
            .per_muscle
            .iter()
            .enumerate()
            .map(|(k, &s)| (k, s / self.all_steps as f64))
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        let names: Vec<String> = ranked
            .iter()
            .take(12)
            .map(|&(k, m)| format!("{} {:.2}", model.actuators[muscles[k]].name, m))
            .collect();
        println!("most active muscles: {}", names.join(", "));
    }
}

/// Per action entry (K-MAC checkpoints only; none otherwise): steps whose mean action is at a clip
/// bound (|a| > 0.98), how far past ±1 it lies, and |target − position| in half-ranges of its span.
struct ActionBounds {
    space: agents::controller::ActionSpace,
    kmac: bool,
    clipped: Vec<f64>,
    gap: Vec<f64>,
    beyond: Vec<f64>,
    nsteps: f64,
}

impl ActionBounds {
    fn new(
        model: &sim::model::Model,
        controller: &agents::controller::ControllerSpec,
    ) -> ActionBounds {
        let space = agents::controller::ActionSpace::new(model);
        let kmac = matches!(controller, agents::controller::ControllerSpec::Kmac { .. });
        let nact = if kmac { space.joints.len() } else { 0 };
        ActionBounds {
            space,
            kmac,
            clipped: vec![0.0; nact],
            gap: vec![0.0; nact],
            beyond: vec![0.0; nact],
            nsteps: 0.0,
        }
    }

    /// Adds a step's mean action, taken at joint positions `qpos`.
    fn add(&mut self, model: &sim::model::Model, mean: &[f64], qpos: &[f64]) {
        if !self.kmac {
            return;
        }
        let space = &self.space;
        self.nsteps += 1.0;
        let targets = space.kmac_targets(model, mean);
        for (k, (&m, &z)) in mean.iter().zip(&targets).enumerate() {
            self.beyond[k] += (m.abs() - 1.0).max(0.0);
            if m.abs() > 0.98 {
                self.clipped[k] += 1.0;
            }
            let [lo, hi] = space.kmac_target_range(model, k);
            let q = qpos[model.joints[space.joints[k]].qpos_adr];
            self.gap[k] += (z - q).abs() / (0.5 * (hi - lo));
        }
    }

    fn print(&self, model: &sim::model::Model) {
        for k in 0..self.clipped.len() {
            println!(
                "action {:>14}: mean at a bound {:>5.1}% of steps, mean (|mean| - 1)+ {:.2}, |target - position| {:.2} half-ranges",
                model.joints[self.space.joints[k]].name,
                100.0 * self.clipped[k] / self.nsteps,
                self.beyond[k] / self.nsteps,
                self.gap[k] / self.nsteps
            );
        }
    }
}
