//! DynSyn: synergy groups derived from the dynamics (random joint-velocity drive, muscle-length
//! correlations, k-medoids) and the per-group values with per-muscle weights.

use nalgebra::DVector;
use serde::{Deserialize, Serialize};
use sim::model::Model;

use super::*;

/// DynSyn's synergy groups: which group each muscle belongs to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Synergies {
    /// Group index of each muscle (in `ActionSpace::muscles` order).
    pub group_of: Vec<usize>,
    /// Number of groups.
    pub groups: usize,
}

impl Synergies {
    /// DynSyn controls: muscle `i` gets `clip(group_value[g(i)] · weight[i], 0, 1)`, the weights being
    /// the policy's state-dependent per-muscle outputs (1 = the group's value as is).
    pub fn controls(
        &self,
        space: &ActionSpace,
        group_values: &[f64],
        weights: &[f64],
        pelvis: &[f64],
        ctrl: &mut [f64],
    ) {
        for (k, &a) in space.muscles.iter().enumerate() {
            let g = self.group_of[k];
            ctrl[a] = (group_values[g] * weights[k]).clamp(0.0, 1.0);
        }
        for ((_, s), &t) in space.servo_joints().zip(pelvis) {
            ctrl[s] = t;
        }
    }

    /// DynSyn's grouping from the dynamics (He et al. 2024): drive the joints at random velocities with
    /// zero muscle action, record every muscle's length, correlate the length signals over windows, and
    /// cluster the muscles by k-medoids on `1 − |correlation|`. Deterministic in `seed`.
    pub fn derive(model: &Model, groups: usize, seed: u64) -> Synergies {
        let space = ActionSpace::new(model);
        let m = space.muscles.len();
        let groups = groups.clamp(1, m.max(1));
        let mut rng = sim::rng::Rng::seeded(seed);
        let mut geometry = MuscleGeometry::new(model);
        let mut q = model.qpos0.clone();
        model.apply_couplings(&mut q);
        // Random joint-velocity drive: every 0.1 s a new velocity within the joint ranges' scale.
        let steps = 600;
        let h = sim::arena::CONTROL_DT;
        let mut samples = vec![Vec::with_capacity(steps); m];
        let mut vel = vec![0.0; space.joints.len()];
        for k in 0..steps {
            if k % 10 == 0 {
                for v in vel.iter_mut() {
                    *v = rng.uniform(-1.5, 1.5);
                }
            }
            for (i, &j) in space.joints.iter().enumerate() {
                let joint = &model.joints[j];
                let adr = joint.qpos_adr;
                let mut x = q[adr] + vel[i] * h;
                if let Some([lo, hi]) = joint.range {
                    if x < lo || x > hi {
                        vel[i] = -vel[i];
                        x = x.clamp(lo, hi);
                    }
                }
                q[adr] = x;
            }
            model.apply_couplings(&mut q);
            geometry.update(model, &q);
            for (i, &a) in space.muscles.iter().enumerate() {
                samples[i].push(geometry.length(model, a, &q));
            }
        }
        // Correlation of length changes over windows of 100 samples, averaged.
        let window = 100;
        let mut distance = vec![vec![0.0; m]; m];
        let windows = steps / window;
        for w in 0..windows {
            let seg: Vec<DVector<f64>> = samples
                .iter()
                .map(|s| {
                    let x = DVector::from_iterator(
                        window - 1,
                        (w * window..(w + 1) * window - 1).map(|t| s[t + 1] - s[t]),
                    );
                    let mean = x.mean();
                    let c = x.add_scalar(-mean);
                    let n = c.norm();
                    if n > 1e-15 {
                        c / n
                    } else {
                        c
                    }
                })
                .collect();
            for i in 0..m {
                for j in 0..m {
                    distance[i][j] += (1.0 - seg[i].dot(&seg[j]).abs()) / windows as f64;
                }
            }
        }
        Synergies {
            group_of: k_medoids(&distance, groups),
            groups,
        }
    }
}

/// k-medoids (PAM-style swaps from a greedy start) on a distance matrix; returns each item's cluster.
fn k_medoids(distance: &[Vec<f64>], k: usize) -> Vec<usize> {
    let n = distance.len();
    // Greedy start: the most central item, then repeatedly the item farthest from the chosen ones.
    let mut medoids = vec![(0..n)
        .min_by(|&a, &b| {
            distance[a]
                .iter()
                .sum::<f64>()
                .total_cmp(&distance[b].iter().sum::<f64>())
        })
        .unwrap_or(0)];
    while medoids.len() < k {
        let next = (0..n)
            .filter(|i| !medoids.contains(i))
            .max_by(|&a, &b| {
                let da = medoids
                    .iter()
                    .map(|&m| distance[a][m])
                    .fold(f64::INFINITY, f64::min);
                let db = medoids
                    .iter()
                    .map(|&m| distance[b][m])
                    .fold(f64::INFINITY, f64::min);
                da.total_cmp(&db)
            })
            .expect("k ≤ n");
        medoids.push(next);
    }
    let cost = |med: &[usize]| -> f64 {
        (0..n)
            .map(|i| {
                med.iter()
                    .map(|&m| distance[i][m])
                    .fold(f64::INFINITY, f64::min)
            })
            .sum()
    };
    let mut best = cost(&medoids);
    loop {
        let mut improved = false;
        for slot in 0..medoids.len() {
            for cand in 0..n {
                if medoids.contains(&cand) {
                    continue;
                }
                let old = medoids[slot];
                medoids[slot] = cand;
                let c = cost(&medoids);
                if c + 1e-12 < best {
                    best = c;
                    improved = true;
                } else {
                    medoids[slot] = old;
                }
            }
        }
        if !improved {
            break;
        }
    }
    (0..n)
        .map(|i| {
            (0..medoids.len())
                .min_by(|&a, &b| distance[i][medoids[a]].total_cmp(&distance[i][medoids[b]]))
                .expect("k ≥ 1")
        })
        .collect()
}
