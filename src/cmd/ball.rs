//! `rally ball`: simulate a free ball for a fixed duration and print one JSON object per control step.
//!
//! The ball flies with no paddle and does not stop at z = 0.3; with `--judge` a referee follows it as
//! the serve of a rally and a last line gives its verdict.

use std::io::{self, BufWriter, Write};

use clap::{ArgGroup, Args};
use nalgebra::Vector3;
use serde_json::{json, Value};
use sim::arena::{self, Side};
use sim::geometry::{Aabb, Feature};
use sim::predict::BounceModel;
use sim::rng::Rng;
use sim::rules::Referee;
use sim::serve::{self, ServeKind};
use sim::{BallState, BallWorld, ContactEvent, ContactKind, Preset};

use super::{parse_preset, parse_seconds, parse_vec3, CliError};

/// Arguments of `rally ball`.
#[derive(Args, Debug)]
#[command(
    group(ArgGroup::new("start").required(true).args(["pos", "serve"])),
    after_help = "Each line: {\"t\":0.37,\"pos\":[x,y,z],\"vel\":[vx,vy,vz],\"events\":[{\"kind\":\"table\",\"side\":\"a\",\"t\":0.3683,\"pos\":[x,y,z]}]}\n\
                  The first line is the state at t = 0; then one line per 10 ms control step. `events` lists the contacts that\n\
                  began since the previous line: kind table, net, floor or paddle; side \"a\" (x > 0) or \"b\" (x < 0) by where it\n\
                  happened, null for the net; t and pos at first contact. Table events also give `face`: top, edge or side.\n\n\
                  Examples:\n  rally ball --serve p2 --seed 7\n  rally ball --pos -1.2,-0.45,1.45 --vel 5.6,1.6,0.1 --duration 1 --judge"
)]
pub struct BallArgs {
    /// Initial ball centre, m (world frame: x along the table, net at x = 0; z up).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, requires = "vel", conflicts_with_all = ["serve", "seed"], allow_hyphen_values = true)]
    pos: Option<Vector3<f64>>,
    /// Initial ball velocity, m/s.
    #[arg(long, value_name = "VX,VY,VZ", value_parser = parse_vec3, requires = "pos", allow_hyphen_values = true)]
    vel: Option<Vector3<f64>>,
    /// Initial ball spin (angular velocity), rad/s.
    #[arg(long, value_name = "WX,WY,WZ", value_parser = parse_vec3, requires = "pos", allow_hyphen_values = true)]
    spin: Option<Vector3<f64>>,
    /// Generate the ball from a serve: MyoChallenge p0/p1/p2 (to side A), the paper's rally serve
    /// (from B) or stroke (a robot's return from B: the rally serve with a stroke's error).
    #[arg(long, value_parser = ["p0", "p1", "p2", "rally", "stroke"], requires = "seed")]
    serve: Option<String>,
    /// Seed of the serve generator (ChaCha8; identical on every platform).
    #[arg(long, allow_hyphen_values = true)]
    seed: Option<u64>,
    /// Arena preset: contact laws and air model.
    #[arg(long, default_value = "myochallenge", value_parser = parse_preset)]
    preset: Preset,
    /// Simulated time, s.
    #[arg(long, default_value = "3", value_parser = parse_seconds, allow_hyphen_values = true)]
    duration: f64,
    /// Judge the ball as a rally's serve and print a last line with the referee's verdict.
    #[arg(long)]
    judge: bool,
}

/// The ball at t = 0 and the side it is served from.
fn initial_ball(args: &BallArgs) -> Result<(BallState, Side), CliError> {
    if let (Some(kind), Some(seed)) = (&args.serve, args.seed) {
        let kind = ServeKind::parse(kind)
            .ok_or_else(|| CliError::Usage(format!("--serve: unknown serve '{kind}'")))?;
        let model = BounceModel::for_table(&args.preset.table);
        let serve = serve::generate(kind, &mut Rng::seeded(seed), &model);
        return Ok((serve.ball, serve.server));
    }
    let (Some(pos), Some(vel)) = (args.pos, args.vel) else {
        return Err(CliError::Usage(
            "give --pos and --vel, or --serve and --seed".into(),
        ));
    };
    check_clear_of_solids(&pos)?;
    let mut ball = BallState::new(pos, vel);
    if let Some(spin) = args.spin {
        ball.spin = spin;
    }
    // The server is the side the ball flies away from.
    let server = if vel.x >= 0.0 { Side::B } else { Side::A };
    Ok((ball, server))
}

/// A ball that starts inside the table, the net or the floor would be thrown out by the contact
/// forces: refuse it.
fn check_clear_of_solids(pos: &Vector3<f64>) -> Result<(), CliError> {
    let r = arena::BALL_RADIUS;
    let solids = [("table", Aabb::table()), ("net", Aabb::net())];
    for (name, solid) in solids {
        let gap = solid.proximity(pos).distance - r;
        if gap < 0.0 {
            return Err(CliError::Usage(format!(
                "--pos: the ball (radius {r} m) would start {:.1} mm inside the {name}",
                -gap * 1000.0
            )));
        }
    }
    if pos.z - r < arena::FLOOR_Z {
        return Err(CliError::Usage(format!(
            "--pos: the ball would start below the floor (z must be at least {r} m)"
        )));
    }
    Ok(())
}

fn vec_json(v: &Vector3<f64>) -> Value {
    json!([v.x, v.y, v.z])
}

/// One contact event as printed.
pub fn event_json(e: &ContactEvent) -> Value {
    let mut obj = json!({
        "kind": e.kind.name(),
        "side": e.side().map(Side::name),
        "t": e.t,
        "pos": vec_json(&e.pos),
    });
    match e.kind {
        ContactKind::Table { feature } => {
            obj["face"] = json!(match feature {
                Feature::Top => "top",
                Feature::Edge => "edge",
                Feature::Side => "side",
            });
        }
        ContactKind::Paddle { owner } => obj["owner"] = json!(owner.name()),
        ContactKind::Net | ContactKind::Floor => {}
    }
    obj
}

fn state_line(t: f64, ball: &BallState, events: &[ContactEvent]) -> Value {
    json!({
        "t": t,
        "pos": vec_json(&ball.pos),
        "vel": vec_json(&ball.vel),
        "events": events.iter().map(event_json).collect::<Vec<_>>(),
    })
}

/// Runs `rally ball`.
pub fn run(args: &BallArgs) -> Result<(), CliError> {
    let (ball, server) = initial_ball(args)?;
    let mut world = BallWorld::new(args.preset, ball);
    let mut referee = Referee::new(server);
    let steps = (args.duration / arena::CONTROL_DT).round() as u64;
    let stdout = io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let result = (|| -> io::Result<()> {
        writeln!(out, "{}", state_line(0.0, &world.ball, &[]))?;
        let mut events = Vec::new();
        for k in 1..=steps {
            events.clear();
            world.control_step(&mut [], &mut events);
            for e in &events {
                referee.on_contact(e);
            }
            referee.on_ball_height(world.time, world.ball.pos.z);
            // Control-step times printed exactly (k / 100), not as the sum of 2 ms steps.
            let t = k as f64 / (1.0 / arena::CONTROL_DT).round();
            writeln!(out, "{}", state_line(t, &world.ball, &events))?;
        }
        if args.judge {
            writeln!(out, "{}", verdict_json(&referee))?;
        }
        out.flush()
    })();
    match result {
        // A closed pipe (`rally ball | head`) is the reader's choice, not a failure.
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

fn verdict_json(referee: &Referee) -> Value {
    let end = referee.end();
    json!({
        "verdict": {
            "server": referee.server().name(),
            "rally_length": referee.rally_length(),
            "end": end.map(|e| e.reason.name()),
            "failing_side": end.and_then(|e| e.failing_side).map(Side::name),
            "t": end.map(|e| e.t),
        }
    })
}
