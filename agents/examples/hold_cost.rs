//! What K-MAC spends holding the ready pose still: targets = the ready pose, with and without the
//! gravity lead (`controller::gravity_offset`), for 1 s of a P2 episode (the ball ignored), at a few
//! gains; prints the mean activation and the pose drift every 0.1 s. A diagnosis aid:
//! `cargo run --release -p agents --example hold_cost`.
use agents::controller::{gravity_offset, Kmac, PdGains};
use sim::episode::SingleServe;
use sim::rng::Rng;
use sim::serve::ServeKind;
use std::sync::Arc;

fn main() {
    let model = Arc::new(sim::config::default_model());
    let config = sim::config::ArenaConfig::default();
    let mut env = SingleServe::new(model.clone(), &config, sim::arena::MYOCHALLENGE).unwrap();
    let muscles: Vec<usize> = model.muscles().map(|(i, _)| i).collect();
    let na = muscles.len() as f64;
    for &(kp, kd) in &[(10.0, 1.0), (10.0, 0.0), (30.0, 1.0)] {
        for lead in [false, true] {
            let gains = PdGains { kp, kd };
            let mut kmac = Kmac::new(&model, gains);
            let mut ready = sim::episode::ready_pose(&model).unwrap();
            model.apply_couplings(&mut ready);
            let mut targets: Vec<f64> = kmac
                .space
                .joints
                .iter()
                .map(|&j| ready[model.joints[j].qpos_adr])
                .collect();
            if lead {
                let mut data = sim::dynamics::Data::new(&model);
                let grip: Vec<usize> = model.joint("grip").into_iter().collect();
                let off = gravity_offset(&model, &mut data, &kmac.space, &gains, &ready, &grip);
                for (t, o) in targets.iter_mut().zip(off) {
                    *t += o;
                }
            }
            env.reset(ServeKind::P2, &mut Rng::seeded(1), None);
            let mut ctrl = vec![0.0; model.actuators.len()];
            let mut prof = Vec::new();
            for step in 0..100 {
                ctrl.copy_from_slice(&env.robot.state.ctrl);
                kmac.controls(
                    &model,
                    &env.robot.state,
                    &targets,
                    sim::arena::CONTROL_DT,
                    &mut ctrl,
                );
                agents::controller::apply_grip_floor(&env.robot, 0.1, &mut ctrl);
                env.robot.state.ctrl.copy_from_slice(&ctrl);
                let _ = env.step();
                let act = &env.robot.state.act;
                if step % 10 == 9 {
                    let l1 = muscles.iter().map(|&a| act[a]).sum::<f64>() / na;
                    let drift: f64 = kmac
                        .space
                        .joints
                        .iter()
                        .map(|&j| {
                            (env.robot.state.qpos[model.joints[j].qpos_adr]
                                - ready[model.joints[j].qpos_adr])
                                .powi(2)
                        })
                        .sum::<f64>()
                        .sqrt();
                    prof.push(format!("{l1:.3}/{drift:.2}"));
                }
            }
            println!(
                "kp {kp} kd {kd} lead {lead}: activation/drift(rad) every 0.1 s: {}",
                prof.join(" ")
            );
        }
    }
}
