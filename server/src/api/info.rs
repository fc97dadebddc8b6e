//! What the server tells about itself and its world: health, metrics, the leaderboard, the OpenAPI
//! document, and the arena's and the robot's geometry for the pages to draw.

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};

use super::{robot_of, ApiResult, Typed};
use crate::db;
use crate::ratings;
use crate::state::AppState;

pub(super) async fn healthz(State(s): State<AppState>) -> ApiResult<Json<wire::Health>> {
    db::ping(&s.pool).await?;
    Ok(Json(wire::Health {
        status: "ok".into(),
        sim_version: sim::SIM_VERSION.into(),
        qualification: Some(wire::QualificationRule {
            episodes: s.settings.qualification_episodes,
            min_hit_rate: s.settings.qualification_min_hit_rate,
            max_dropped: s.settings.qualification_max_dropped,
        }),
        models: s.arenas.iter().map(|a| a.name.clone()).collect(),
    }))
}

/// `GET /arena?model=`: the arena's geometry as the simulator has it (table, net, floor, hitting
/// planes, serve box, ball, the robot's paddle), so that pages draw what the simulator simulates.
pub(super) async fn arena(
    State(s): State<AppState>,
    Typed(q): Typed<wire::ModelQuery>,
) -> super::ApiResult<Json<Value>> {
    use sim::arena as a;
    let robot = robot_of(&s, &q)?;
    let paddle = robot
        .model
        .body(&robot.config.grip.paddle_body)
        .and_then(|b| sim::geometry::PaddleShape::from_model(&robot.model, b).ok())
        .unwrap_or_else(sim::geometry::PaddleShape::standard);
    let cyl = |c: &sim::geometry::Cylinder| {
        let axis = ["x", "y", "z"][c.axis];
        json!({"center": [c.center.x, c.center.y, c.center.z], "axis": axis,
               "radius": c.radius, "half_length": c.half_length})
    };
    Ok(Json(json!({
        "sim_version": sim::SIM_VERSION,
        "model": robot.name,
        "table": {"x": [-a::TABLE_HALF_LENGTH, a::TABLE_HALF_LENGTH], "y": [a::TABLE_Y_MIN, a::TABLE_Y_MAX],
                  "center_y": a::TABLE_CENTER_Y, "top_z": a::TABLE_TOP_Z},
        "net": {"center": a::NET_CENTER, "half_size": a::NET_HALF_SIZE, "top_z": a::NET_TOP_Z},
        "floor_z": a::FLOOR_Z,
        "strike_plane_x": a::STRIKE_PLANE_X,
        "serve_box": {"z": [a::SERVE_BOX_Z.0, a::SERVE_BOX_Z.1], "half_width": a::SERVE_BOX_HALF_WIDTH},
        "ball_radius": a::BALL_RADIUS,
        "paddle": {"blade": cyl(&paddle.blade), "handle": cyl(&paddle.handle)},
    })))
}

/// `GET /model?model=`: what a page needs to draw the robots — bodies (name, parent; `paddle` is drawn from
/// the frames' paddle pose instead), every geom in its body's frame (kind, size, pos, quat w x y z),
/// the sites and every muscle's path through them (the actuator index that colours it).
pub(super) async fn robot_model(
    State(s): State<AppState>,
    Typed(q): Typed<wire::ModelQuery>,
) -> ApiResult<Json<Value>> {
    let robot = robot_of(&s, &q)?;
    let m = &robot.model;
    let q = |q: &nalgebra::UnitQuaternion<f64>| json!([q.w, q.i, q.j, q.k]);
    let v = |p: &nalgebra::Vector3<f64>| json!([p.x, p.y, p.z]);
    let kind = |k: sim::model::GeomKind| match k {
        sim::model::GeomKind::Sphere => "sphere",
        sim::model::GeomKind::Capsule => "capsule",
        sim::model::GeomKind::Cylinder => "cylinder",
        sim::model::GeomKind::Box => "box",
        sim::model::GeomKind::Ellipsoid => "ellipsoid",
        sim::model::GeomKind::Plane => "plane",
    };
    let muscles: Vec<Value> = m
        .muscles()
        .filter_map(|(a, act)| match act.transmission {
            sim::model::Transmission::Tendon(t) => {
                Some(json!({"name": act.name, "actuator": a, "sites": m.tendons[t].sites().collect::<Vec<_>>()}))
            }
            _ => None,
        })
        .collect();
    Ok(Json(json!({
        "name": m.name,
        "robot": robot.name,
        "paddle_body": m.body(&robot.config.grip.paddle_body),
        "bodies": m.bodies.iter().map(|b| json!({"name": b.name, "parent": b.parent})).collect::<Vec<_>>(),
        "geoms": m.geoms.iter().map(|g| json!({"body": g.body, "name": g.name, "kind": kind(g.kind),
            "size": g.size, "pos": v(&g.pos), "quat": q(&g.quat)})).collect::<Vec<_>>(),
        "sites": m.sites.iter().map(|st| json!({"body": st.body, "pos": v(&st.pos)})).collect::<Vec<_>>(),
        "muscles": muscles,
    })))
}

/// `GET /leaderboard?model=`: robot `model`'s leaderboard (none: the default robot's).
pub(super) async fn leaderboard(
    State(s): State<AppState>,
    Typed(q): Typed<wire::ModelQuery>,
) -> ApiResult<Json<ratings::Leaderboard>> {
    let robot = robot_of(&s, &q)?;
    Ok(Json(
        (*crate::board::current_board(&s, &robot.name).await?).clone(),
    ))
}

pub(super) async fn metrics(State(s): State<AppState>) -> ApiResult<Response> {
    let by_status: Vec<(String, i64)> = db::matches_by_status(&s.pool).await?;
    let (agents_n, rallies_n): (i64, i64) = db::agent_and_rally_counts(&s.pool).await?;
    let mut out = String::new();
    out.push_str("# HELP rally_matches Matches by status.\n# TYPE rally_matches gauge\n");
    for st in ["queued", "running", "done", "failed", "cancelled"] {
        let n = by_status.iter().find(|(k, _)| k == st).map_or(0, |x| x.1);
        out.push_str(&format!("rally_matches{{status=\"{st}\"}} {n}\n"));
    }
    out.push_str(&format!("# HELP rally_agents Registered agents.\n# TYPE rally_agents gauge\nrally_agents {agents_n}\n"));
    out.push_str(&format!("# HELP rally_rallies_total Rallies stored.\n# TYPE rally_rallies_total counter\nrally_rallies_total {rallies_n}\n"));
    let tallies = db::contest_tallies(&s.pool).await?;
    out.push_str("# HELP rally_sprts SPRTs by status.\n# TYPE rally_sprts gauge\n");
    for st in [
        "running",
        "accepted_h1",
        "accepted_h0",
        "inconclusive",
        "failed",
        "cancelled",
    ] {
        let key = format!("sprt_{st}");
        let n = tallies.iter().find(|(k, _)| *k == key).map_or(0, |x| x.1);
        out.push_str(&format!("rally_sprts{{status=\"{st}\"}} {n}\n"));
    }
    let t = tallies
        .iter()
        .find(|(k, _)| k == "tournaments")
        .map_or(0, |x| x.1);
    out.push_str(&format!("# HELP rally_tournaments Tournaments created.\n# TYPE rally_tournaments counter\nrally_tournaments {t}\n"));
    out.push_str(&format!(
        "# HELP rally_workers Match workers.\n# TYPE rally_workers gauge\nrally_workers {}\n",
        s.settings.workers
    ));
    let (setups, setup_s) = s.players.setups();
    out.push_str(&format!(
        "# HELP rally_match_setup_seconds From a match's claim to its first frame, in this process.\n# TYPE rally_match_setup_seconds summary\nrally_match_setup_seconds_sum {setup_s}\nrally_match_setup_seconds_count {setups}\n"
    ));
    out.push_str(&format!(
        "# HELP rally_player_loads_total Checkpoints parsed and built for matches and replays in this process.\n# TYPE rally_player_loads_total counter\nrally_player_loads_total {}\n",
        s.players.loads()
    ));
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out).into_response())
}

pub(super) async fn openapi() -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        crate::page::OPENAPI,
    )
        .into_response()
}
