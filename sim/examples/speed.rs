//! Times the robot's physics step (used while optimising; `rally bench robot` is the benchmark).
use sim::dynamics::{step, Data, State};
use std::path::Path;
use std::time::Instant;
fn main() {
    let model = sim::mjcf::load(Path::new("config/models/upper_body.xml"), &|p| {
        std::fs::read_to_string(p)
    })
    .unwrap();
    let mut data = Data::new(&model);
    let mut state = State::new(&model);
    state.set_qpos(&model, &model.keyframes[0].qpos.clone());
    for c in state.ctrl.iter_mut() {
        *c = 0.1;
    }
    let n: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(20000);
    let t = Instant::now();
    for _ in 0..n {
        step(&model, &mut data, &mut state);
    }
    let dt = t.elapsed().as_secs_f64();
    println!(
        "{:.0} steps/s ({:.1} us/step)",
        n as f64 / dt,
        dt / n as f64 * 1e6
    );
}
