//! Empirical observation normalisation as rsl_rl's `EmpiricalNormalization`: a running mean and
//! (population) variance over every observation seen in training, merged batch by batch with Chan's
//! parallel formula, and `(x − mean) / (std + ε)` with ε = 1e-2. A checkpoint stores `mean` and
//! `std + ε`, so a player normalises with `(x − mean) / std` and needs nothing else.

use serde::{Deserialize, Serialize};

/// rsl_rl's ε, added to the standard deviation.
pub const EPSILON: f64 = 1e-2;

/// Running mean and variance of vectors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunningNormalizer {
    /// Per-entry mean.
    pub mean: Vec<f64>,
    /// Per-entry population variance.
    pub var: Vec<f64>,
    /// Vectors seen.
    pub count: u64,
}

impl RunningNormalizer {
    /// A normaliser of `dim`-vectors that has seen nothing (mean 0, variance 1).
    pub fn new(dim: usize) -> RunningNormalizer {
        RunningNormalizer {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 0,
        }
    }

    /// Merges a batch of `rows` vectors (row-major, `rows·dim` entries).
    pub fn update(&mut self, batch: &[f64]) {
        let dim = self.mean.len();
        if dim == 0 || batch.is_empty() {
            return;
        }
        let rows = batch.len() / dim;
        let n = rows as f64;
        for k in 0..dim {
            let col = || (0..rows).map(|r| batch[r * dim + k]);
            let mean_x = col().sum::<f64>() / n;
            let var_x = col().map(|x| (x - mean_x).powi(2)).sum::<f64>() / n;
            if self.count == 0 {
                self.mean[k] = mean_x;
                self.var[k] = var_x;
                continue;
            }
            let rate = n / (self.count as f64 + n);
            let delta = mean_x - self.mean[k];
            self.mean[k] += rate * delta;
            self.var[k] += rate * (var_x - self.var[k] + (1.0 - rate) * delta * delta);
        }
        self.count += rows as u64;
    }

    /// The divisor a player uses: `std + ε`.
    pub fn scale(&self) -> Vec<f64> {
        self.var
            .iter()
            .map(|v| v.max(0.0).sqrt() + EPSILON)
            .collect()
    }

    /// Normalises one vector `x` in place.
    pub fn apply(&self, x: &mut [f64]) {
        for ((v, m), var) in x.iter_mut().zip(&self.mean).zip(&self.var) {
            *v = (*v - m) / (var.max(0.0).sqrt() + EPSILON);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_merge_to_the_whole_data_mean_and_variance() {
        // 2-vectors in three uneven batches; the merged statistics equal those of all rows at once.
        let rows: Vec<[f64; 2]> = (0..23)
            .map(|i| [(i as f64 * 0.7).sin() * 3.0 + 1.0, (i * i) as f64 * 0.01])
            .collect();
        let flat = |r: &[[f64; 2]]| r.iter().flatten().copied().collect::<Vec<f64>>();
        let mut n = RunningNormalizer::new(2);
        n.update(&flat(&rows[..5]));
        n.update(&flat(&rows[5..6]));
        n.update(&flat(&rows[6..]));
        for k in 0..2 {
            let m = rows.iter().map(|r| r[k]).sum::<f64>() / 23.0;
            let v = rows.iter().map(|r| (r[k] - m).powi(2)).sum::<f64>() / 23.0;
            assert!((n.mean[k] - m).abs() < 1e-12, "{} vs {m}", n.mean[k]);
            assert!((n.var[k] - v).abs() < 1e-12, "{} vs {v}", n.var[k]);
        }
        assert_eq!(n.count, 23);
    }

    #[test]
    fn applies_mean_and_std_plus_epsilon() {
        let mut n = RunningNormalizer::new(1);
        n.update(&[1.0, 3.0]); // mean 2, population variance 1
        let mut x = [4.0];
        n.apply(&mut x);
        assert!((x[0] - 2.0 / (1.0 + EPSILON)).abs() < 1e-12);
        assert_eq!(n.scale(), vec![1.0 + EPSILON]);
    }
}
