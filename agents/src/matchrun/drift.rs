//! Trajectory drift: the moments of where returns cross the hitting plane, and the energy distance
//! between two sets of crossings.

use serde::Serialize;

use super::CrossingRecord;

/// Mean and covariance of `(y_r, z)` samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Moments {
    /// Samples.
    pub n: usize,
    /// Mean `(y_r, z)`.
    pub mean: [f64; 2],
    /// Covariance `[[yy, yz], [yz, zz]]` (zero below two samples).
    pub cov: [[f64; 2]; 2],
}

/// Trajectory drift statistics (docs/design.md §7).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DriftStats {
    /// Crossings counted.
    pub crossings: usize,
    /// Fraction of them inside the serve box.
    pub in_box_fraction: f64,
    /// Moments per exchange index (0 = serves).
    pub by_exchange: Vec<Moments>,
    /// Energy distance between the serves' crossings and the returns' crossings (null without both).
    pub energy_distance: Option<f64>,
    /// Least-squares slope of the energy distance between the serves and exchange k, over k ≥ 1 (null
    /// with fewer than two exchange indices that have returns).
    pub drift_slope: Option<f64>,
}

fn moments(points: &[[f64; 2]]) -> Moments {
    let n = points.len();
    if n == 0 {
        return Moments {
            n,
            mean: [0.0; 2],
            cov: [[0.0; 2]; 2],
        };
    }
    let mean = [
        points.iter().map(|p| p[0]).sum::<f64>() / n as f64,
        points.iter().map(|p| p[1]).sum::<f64>() / n as f64,
    ];
    let mut cov = [[0.0; 2]; 2];
    if n > 1 {
        for p in points {
            let d = [p[0] - mean[0], p[1] - mean[1]];
            for i in 0..2 {
                for j in 0..2 {
                    cov[i][j] += d[i] * d[j] / (n - 1) as f64;
                }
            }
        }
    }
    Moments { n, mean, cov }
}

/// Energy distance `2·E|X − Y| − E|X − X'| − E|Y − Y'|` between two samples (Székely's statistic).
pub fn energy_distance(x: &[[f64; 2]], y: &[[f64; 2]]) -> Option<f64> {
    if x.is_empty() || y.is_empty() {
        return None;
    }
    let dist = |a: &[f64; 2], b: &[f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let mean_between = |a: &[[f64; 2]], b: &[[f64; 2]]| {
        a.iter()
            .flat_map(|p| b.iter().map(move |q| dist(p, q)))
            .sum::<f64>()
            / (a.len() * b.len()) as f64
    };
    Some(2.0 * mean_between(x, y) - mean_between(x, x) - mean_between(y, y))
}

/// Drift statistics of a set of crossings.
pub fn drift_stats(crossings: &[CrossingRecord]) -> DriftStats {
    let max_ex = crossings.iter().map(|c| c.exchange).max().unwrap_or(0);
    let at = |k: u32| -> Vec<[f64; 2]> {
        crossings
            .iter()
            .filter(|c| c.exchange == k)
            .map(|c| [c.y_r, c.z])
            .collect()
    };
    let serves = at(0);
    let returns: Vec<[f64; 2]> = crossings
        .iter()
        .filter(|c| c.exchange > 0)
        .map(|c| [c.y_r, c.z])
        .collect();
    let by_exchange: Vec<Moments> = (0..=max_ex).map(|k| moments(&at(k))).collect();
    let per_k: Vec<(f64, f64)> = (1..=max_ex)
        .filter_map(|k| energy_distance(&serves, &at(k)).map(|e| (k as f64, e)))
        .collect();
    let drift_slope = (per_k.len() >= 2).then(|| {
        let n = per_k.len() as f64;
        let (mx, my) = (
            per_k.iter().map(|p| p.0).sum::<f64>() / n,
            per_k.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let sxx: f64 = per_k.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let sxy: f64 = per_k.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        sxy / sxx
    });
    DriftStats {
        crossings: crossings.len(),
        in_box_fraction: if crossings.is_empty() {
            0.0
        } else {
            crossings.iter().filter(|c| c.in_box).count() as f64 / crossings.len() as f64
        },
        by_exchange,
        energy_distance: energy_distance(&serves, &returns),
        drift_slope,
    }
}
