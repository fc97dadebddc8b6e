//! `rally plan`: the physics-based planner's command for one ball (paper §IV-B), as JSON.

use clap::Args;
use nalgebra::Vector3;
use sim::arena::Side;
use sim::predict::BounceModel;
use sim::rng::Rng;

use super::{parse_preset, parse_vec3, CliError};

/// Arguments of `rally plan`.
#[derive(Args, Debug)]
#[command(
    after_help = "Output: {\"receiver\":\"a\",\"t_strike\":…,\"strike_pos\":[…],\"strike_vel\":[…],\"v_out\":[…],\"racket_vel\":[…],\"racket_quat\":[w,x,y,z]}\n\
                  t_strike is the time until the ball reaches the receiver's hitting plane (x = ±1.8), strike_vel its\n\
                  incoming velocity there; racket_quat turns the paddle frame's +z (the blade normal) onto the contact normal.\n\n\
                  Example:\n  rally plan --pos -1.2,-0.45,1.45 --vel 5.6,1.6,0.1 --seed 3"
)]
pub struct PlanArgs {
    /// Ball centre, m.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pos: Vector3<f64>,
    /// Ball velocity, m/s.
    #[arg(long, value_name = "VX,VY,VZ", value_parser = parse_vec3, allow_hyphen_values = true)]
    vel: Vector3<f64>,
    /// Outgoing velocity to plan for, m/s (default: drawn by the return sampler).
    #[arg(long, value_name = "VX,VY,VZ", value_parser = parse_vec3, allow_hyphen_values = true)]
    v_out: Option<Vector3<f64>>,
    /// Who strikes (default: the side the ball flies towards).
    #[arg(long, value_parser = ["a", "b"])]
    receiver: Option<String>,
    /// Seed of the return sampler.
    #[arg(long, default_value = "0", allow_hyphen_values = true)]
    seed: u64,
    /// Arena preset (its table decides the planner's bounce model).
    #[arg(long, default_value = "myochallenge", value_parser = parse_preset)]
    preset: sim::Preset,
}

/// Runs `rally plan`.
pub fn run(args: &PlanArgs) -> Result<(), CliError> {
    let receiver = args
        .receiver
        .as_deref()
        .map(|r| if r == "a" { Side::A } else { Side::B });
    let model = BounceModel::for_table(&args.preset.table);
    let plan = agents::planner::plan(
        &args.pos,
        &args.vel,
        receiver,
        args.v_out,
        &mut Rng::seeded(args.seed),
        &model,
    )
    .map_err(|e| CliError::Usage(format!("--pos/--vel: {e}")))?;
    let json = serde_json::to_string(&agents::planner::PlanJson::from(&plan))
        .map_err(anyhow::Error::from)?;
    println!("{json}");
    Ok(())
}
