//! Ball banks: balls recorded from rallies, served in a share of single-serve episodes.

use nalgebra::Vector3;
use serde::Deserialize;
use sim::ball::BallState;
use sim::rng::Rng;

type V3 = Vector3<f64>;

/// The file format of a ball bank.
pub const BANK_FORMAT: &str = "muscle-rally-balls";

/// Balls recorded from rallies (`rally match --returns`), each as its receiver met it, in the frame
/// of a ball struck by B towards A: a single-serve environment serves one of them, drawn uniformly,
/// in `fraction` of its episodes (ours: training on the balls a rally brings, not only on serves).
#[derive(Debug, Clone)]
pub struct BallBank {
    /// The balls.
    pub balls: std::sync::Arc<[BallState]>,
    /// Share of episodes served from the bank, in [0, 1].
    pub fraction: f64,
}

impl BallBank {
    /// One episode's ball: with probability `fraction` a bank ball, else `None` (serve as usual).
    /// Draws: one uniform, and one more for the index when the bank serves.
    pub fn draw(&self, rng: &mut Rng) -> Option<BallState> {
        if self.balls.is_empty() || rng.unit() >= self.fraction {
            return None;
        }
        let i = ((rng.unit() * self.balls.len() as f64) as usize).min(self.balls.len() - 1);
        Some(self.balls[i])
    }

    /// The bank file's JSON: `{"format", "version": 1, "frame", "source", "balls": [[x, y, z, vx,
    /// vy, vz, wx, wy, wz], …]}`.
    pub fn to_json(balls: &[BallState], source: serde_json::Value) -> serde_json::Value {
        let rows: Vec<Vec<f64>> = balls
            .iter()
            .map(|b| {
                b.pos
                    .iter()
                    .chain(b.vel.iter())
                    .chain(b.spin.iter())
                    .copied()
                    .collect()
            })
            .collect();
        serde_json::json!({
            "format": BANK_FORMAT,
            "version": 1,
            "frame": "struck by B (x < 0) towards A: world coordinates, m, m/s, rad/s",
            "source": source,
            "balls": rows,
        })
    }

    /// Reads a bank file's balls; the error says what is wrong and where.
    pub fn parse(text: &str) -> Result<Vec<BallState>, String> {
        #[derive(Deserialize)]
        struct File {
            format: String,
            version: u32,
            balls: Vec<Vec<f64>>,
        }
        let f: File = serde_json::from_str(text).map_err(|e| format!("not a ball bank: {e}"))?;
        if f.format != BANK_FORMAT || f.version != 1 {
            return Err(format!(
                "format {:?} version {}: expected {BANK_FORMAT:?} version 1",
                f.format, f.version
            ));
        }
        if f.balls.is_empty() {
            return Err("balls: empty".into());
        }
        f.balls
            .iter()
            .enumerate()
            .map(|(i, r)| {
                if r.len() != 9 || r.iter().any(|x| !x.is_finite()) {
                    return Err(format!("balls[{i}]: expected 9 finite numbers"));
                }
                if r[3] <= 0.0 {
                    return Err(format!("balls[{i}]: moves away from A (vx = {})", r[3]));
                }
                Ok(BallState {
                    pos: V3::new(r[0], r[1], r[2]),
                    vel: V3::new(r[3], r[4], r[5]),
                    spin: V3::new(r[6], r[7], r[8]),
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ball(vx: f64) -> BallState {
        BallState {
            pos: V3::new(-1.8, 0.1, 1.2),
            vel: V3::new(vx, 0.2, 1.0),
            spin: V3::new(0.0, -5.0, 0.0),
        }
    }

    #[test]
    fn a_bank_serves_its_share_of_episodes_and_only_its_balls() {
        let balls: Vec<BallState> = (0..5).map(|i| ball(5.0 + i as f64)).collect();
        let share = |fraction: f64| {
            let bank = BallBank {
                balls: balls.clone().into(),
                fraction,
            };
            let mut rng = Rng::seeded(3);
            let drawn: Vec<Option<BallState>> = (0..4000).map(|_| bank.draw(&mut rng)).collect();
            assert!(drawn.iter().flatten().all(|b| balls.contains(b)));
            drawn.iter().filter(|b| b.is_some()).count() as f64 / 4000.0
        };
        assert_eq!(share(0.0), 0.0);
        assert_eq!(share(1.0), 1.0);
        assert!((share(0.5) - 0.5).abs() < 0.03, "{}", share(0.5));
    }

    #[test]
    fn a_bank_file_round_trips_and_bad_ones_say_where() {
        let balls = vec![ball(6.0), ball(5.5)];
        let text = BallBank::to_json(&balls, serde_json::json!({"seed": 1})).to_string();
        assert_eq!(BallBank::parse(&text).unwrap(), balls);
        let bad = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
            edit(&mut v);
            BallBank::parse(&v.to_string()).unwrap_err()
        };
        assert!(bad(&|v| v["format"] = "x".into()).contains("expected"));
        assert!(bad(&|v| v["balls"] = serde_json::json!([])).contains("empty"));
        let short = bad(&|v| v["balls"][1] = serde_json::json!([1.0, 2.0]));
        assert!(short.contains("balls[1]"), "{short}");
        let away = bad(&|v| v["balls"][0][3] = (-6.0).into());
        assert!(away.contains("balls[0]") && away.contains("away"), "{away}");
        assert!(BallBank::parse("{")
            .unwrap_err()
            .contains("not a ball bank"));
    }
}
