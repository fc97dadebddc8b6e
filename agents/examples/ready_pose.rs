//! Solves the ready posture the model's "ready" keyframe should hold: the blade behind the hitting
//! plane at the middle of where P2 serves cross it (see sim/examples/p2_crossings.rs), facing the net.
use agents::ik::{BladeTarget, PaddleIk};
use nalgebra::Vector3;
fn main() {
    let model = sim::config::default_model();
    let grip = model.joint("grip").unwrap();
    let mut ik = PaddleIk::new(
        &model,
        model.body("paddle").unwrap(),
        sim::geometry::PaddleShape::from_model(&model, model.body("paddle").unwrap())
            .unwrap()
            .blade
            .center,
        &[grip],
    );
    let mut q = sim::episode::ready_pose(&model).unwrap();
    model.apply_couplings(&mut q);
    let t = BladeTarget {
        pos: Vector3::new(1.95, 0.05, 1.22),
        normal: Vector3::new(-1.0, 0.0, 0.1).normalize(),
    };
    let s = ik.solve_near(&model, &q, Some(&q), &t, 300);
    let vals: Vec<String> = model
        .joints
        .iter()
        .map(|j| format!("{:.3}", s.qpos[j.qpos_adr]))
        .collect();
    println!(
        "error {:.4} m {:.3} rad\nqpos {}",
        s.position_error,
        s.normal_error,
        vals.join(" ")
    );
}
