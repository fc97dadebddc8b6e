//! Reachability of the strike plane: IK error over a grid of strike points with the blade facing the net.
use agents::ik::{BladeTarget, PaddleIk};
use nalgebra::Vector3;
use sim::config::DEFAULT_MODEL_XML;
fn main() {
    let xml = std::env::args()
        .nth(1)
        .map(|p| std::fs::read_to_string(p).unwrap())
        .unwrap_or(DEFAULT_MODEL_XML.to_string());
    let model = sim::mjcf::parse_str(&xml, "u.xml").unwrap();
    let paddle = model.body("paddle").unwrap();
    let grip = model.joint("grip").unwrap();
    let mut ik = PaddleIk::new(
        &model,
        paddle,
        sim::geometry::PaddleShape::from_model(&model, paddle)
            .unwrap()
            .blade
            .center,
        &[grip],
    );
    let mut ready = sim::episode::ready_pose(&model).unwrap();
    model.apply_couplings(&mut ready);
    let (mut worst, mut sum, mut n) = (0.0f64, 0.0, 0);
    for zi in 0..5 {
        let z = 0.95 + 0.12 * zi as f64;
        let mut row = String::new();
        for yi in 0..9 {
            let y = -0.9 + 0.25 * yi as f64;
            let t = BladeTarget {
                pos: Vector3::new(1.8, y, z),
                normal: Vector3::new(-1.0, 0.0, 0.1).normalize(),
            };
            let s = ik.solve_near(&model, &ready, Some(&ready), &t, 200);
            row += &format!("{:5.2}", s.position_error * 100.0 + s.normal_error * 10.0);
            worst = worst.max(s.position_error);
            sum += s.position_error;
            n += 1;
        }
        println!("z {z:.2}: {row}");
    }
    println!(
        "mean {:.3} m worst {:.3} m (cells: cm + 10*rad)",
        sum / n as f64,
        worst
    );
    for (y, z) in [(-0.66, 1.19), (0.5, 1.43)] {
        let t = BladeTarget {
            pos: Vector3::new(1.8, y, z),
            normal: Vector3::new(-1.0, 0.0, 0.1).normalize(),
        };
        for rest in [true, false] {
            let s = ik.solve_near(
                &model,
                &ready,
                if rest { Some(&ready) } else { None },
                &t,
                300,
            );
            let q: Vec<String> = model
                .joints
                .iter()
                .filter(|j| !model.is_dependent(model.joint(&j.name).unwrap()))
                .map(|j| format!("{}={:.2}", j.name, s.qpos[j.qpos_adr]))
                .collect();
            println!(
                "y {y} z {z} rest {rest}: err {:.3} m {:.2} rad: {}",
                s.position_error,
                s.normal_error,
                q.join(" ")
            );
        }
    }
}
#[allow(dead_code)]
fn _unused() {}
