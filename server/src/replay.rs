//! Replay frames as the pages draw them: each stored frame (ball, paddles, joint positions,
//! activations) gains both robots' body poses, computed from its joint positions with `sim`'s
//! kinematics, so that no page computes physics.

use serde_json::{json, Value};

/// Adds each frame's body poses (world frame, `[x, y, z, qw, qx, qy, qz]` per body, rounded to
/// 0.1 mm and 1e-5) for robots A and B, computed from the frame's joint positions with the
/// simulator's kinematics and placed by each side's frame.
pub fn with_body_poses(model: &sim::model::Model, frames: &str) -> Result<String, String> {
    let mut frames: Vec<Value> = serde_json::from_str(frames).map_err(|e| e.to_string())?;
    let mut kin = sim::kinematics::Kinematics::new(model);
    let round = |x: f64, k: f64| (x * k).round() / k;
    for f in frames.iter_mut() {
        for (key, out, side) in [
            ("qpos_a", "bodies_a", sim::arena::Side::A),
            ("qpos_b", "bodies_b", sim::arena::Side::B),
        ] {
            let Some(qpos) = f[key].as_array() else {
                continue;
            };
            let qpos: Vec<f64> = qpos.iter().filter_map(Value::as_f64).collect();
            if qpos.len() != model.nq {
                continue;
            }
            kin.update(model, &qpos);
            let frame = sim::robot::SideFrame::new(side);
            let poses: Vec<Value> = (0..model.bodies.len())
                .map(|b| {
                    let p = frame.point_to_world(&kin.xpos[b]);
                    let r = frame.rotation_to_world(&kin.xquat[b]);
                    json!([
                        round(p.x, 1e4),
                        round(p.y, 1e4),
                        round(p.z, 1e4),
                        round(r.w, 1e5),
                        round(r.i, 1e5),
                        round(r.j, 1e5),
                        round(r.k, 1e5)
                    ])
                })
                .collect();
            f[out] = Value::Array(poses);
        }
    }
    serde_json::to_string(&frames).map_err(|e| e.to_string())
}
