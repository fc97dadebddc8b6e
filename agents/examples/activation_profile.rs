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
    let na = muscles.len() as f64;
    let nb = (LAST - FIRST) as usize;
    let (mut sum, mut sat, mut cnt) = (vec![0.0; nb], vec![0.0; nb], vec![0usize; nb]);
    let (mut all_l1, mut all_steps, mut hits) = (0.0, 0usize, 0);
    let mut per_muscle = vec![0.0; muscles.len()];
    // Per action entry (K-MAC checkpoints only): steps whose mean action is at a clip bound
    // (|a| > 0.98), how far past ±1 it lies, and |target − position| in half-ranges of its span.
    let space = agents::controller::ActionSpace::new(&model);
    let kmac = matches!(
        ck.controller,
        agents::controller::ControllerSpec::Kmac { .. }
    );
    let nact = if kmac { space.joints.len() } else { 0 };
    let (mut clipped, mut gap, mut nsteps) = (vec![0.0; nact], vec![0.0; nact], 0.0);
    let mut beyond = vec![0.0; nact];
    for i in 0..episodes {
        let (serve_seed, agent_seed) = agents::seeds::episode_seeds(seed, i);
        env.reset(ServeKind::P2, &mut Rng::seeded(serve_seed), None);
        player.reseed(agent_seed);
        player.reset();
        let mut ctrl = vec![0.0; model.actuators.len()];
        let mut trace: Vec<(f64, f64, f64)> = Vec::new();
        let mut t_hit: Option<f64> = None;
        loop {
            if !common::act(&mut player, &mut env, &mut ctrl) {
                break;
            }
            if kmac {
                nsteps += 1.0;
                let mean = player.last_mean();
                let targets = space.kmac_targets(&model, mean);
                for (k, (&m, &z)) in mean.iter().zip(&targets).enumerate() {
                    beyond[k] += (m.abs() - 1.0).max(0.0);
                    if m.abs() > 0.98 {
                        clipped[k] += 1.0;
                    }
                    let [lo, hi] = space.kmac_target_range(&model, k);
                    let q = env.robot.state.qpos[model.joints[space.joints[k]].qpos_adr];
                    gap[k] += (z - q).abs() / (0.5 * (hi - lo));
                }
            }
            let rep = env.step();
            let act = &env.robot.state.act;
            let l1 = muscles.iter().map(|&a| act[a]).sum::<f64>() / na;
            let s = muscles.iter().filter(|&&a| act[a] > 0.9).count() as f64;
            for (k, &a) in muscles.iter().enumerate() {
                per_muscle[k] += act[a];
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
        all_steps += trace.len();
        all_l1 += trace.iter().map(|t| t.1).sum::<f64>();
        let Some(th) = t_hit else { continue };
        hits += 1;
        for &(t, l1, s) in &trace {
            let b = ((t - th) / BIN).floor() as i64;
            if (FIRST..LAST).contains(&b) {
                let k = (b - FIRST) as usize;
                sum[k] += l1;
                sat[k] += s;
                cnt[k] += 1;
            }
        }
    }
    println!(
        "{path}: {episodes} episodes (seed {seed}), {hits} with contact; mean activation over all steps {:.3}; steps per episode {:.1}",
        all_l1 / all_steps as f64,
        all_steps as f64 / episodes as f64
    );
    println!("t_from_contact_s,mean_activation,muscles_above_0.9,steps");
    for k in 0..nb {
        if cnt[k] > 0 {
            println!(
                "{:+.1},{:.3},{:.1},{}",
                (FIRST + k as i64) as f64 * BIN,
                sum[k] / cnt[k] as f64,
                sat[k] / cnt[k] as f64,
                cnt[k]
            );
        }
    }
    let mut ranked: Vec<(usize, f64)> = per_muscle
        .iter()
        .enumerate()
        .map(|(k, &s)| (k, s / all_steps as f64))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    let names: Vec<String> = ranked
        .iter()
        .take(12)
        .map(|&(k, m)| format!("{} {:.2}", model.actuators[muscles[k]].name, m))
        .collect();
    println!("most active muscles: {}", names.join(", "));
    for k in 0..nact {
        println!(
            "action {:>14}: mean at a bound {:>5.1}% of steps, mean (|mean| - 1)+ {:.2}, |target - position| {:.2} half-ranges",
            model.joints[space.joints[k]].name,
            100.0 * clipped[k] / nsteps,
            beyond[k] / nsteps,
            gap[k] / nsteps
        );
    }
}
