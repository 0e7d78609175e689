//! The error metrics every method is compared with (docs/design.md, "Error metric"):
//! area-weighted relative RMS over vertices per channel, and the maximum relative error.

use crate::error::{Error, Result};

/// How far an estimate is from the truth, per colour channel.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorStats {
    /// sqrt(sum w (e - t)^2 / sum w t^2) per channel.
    pub rel_rms: [f64; 3],
    /// max |e - t| / |t| per channel over the vertices whose truth is at least
    /// `MAX_FLOOR` of that channel's largest value (dark vertices would divide by ~0).
    pub rel_max: [f64; 3],
}

/// Vertices darker than this fraction of the channel's maximum are left out of `rel_max`.
pub const MAX_FLOOR: f64 = 1e-3;

impl ErrorStats {
    /// The worst channel's relative RMS.
    pub fn worst_rms(&self) -> f64 {
        self.rel_rms.iter().cloned().fold(0.0, f64::max)
    }
}

/// Compares `estimate` with `truth`, weighting vertex i by `weights[i]` (its area).
/// Errors: lengths that differ, a non-finite value in `estimate` or `truth` (naming the row),
/// a negative or non-finite weight, weights that are all zero (nothing is compared).
/// A channel whose truth is 0 at every vertex has no scale to be relative to: both figures
/// are then 0 where the estimate is 0 there too, and infinite where it is not.
pub fn relative_error(
    estimate: &[[f32; 3]],
    truth: &[[f32; 3]],
    weights: &[f32],
) -> Result<ErrorStats> {
    if estimate.len() != truth.len() || truth.len() != weights.len() {
        return Err(Error::InvalidArgument(format!(
            "estimate ({}), truth ({}) and weights ({}) must have the same length",
            estimate.len(),
            truth.len(),
            weights.len()
        )));
    }
    for (name, rows) in [("estimate", estimate), ("truth", truth)] {
        if let Some(i) = rows.iter().position(|r| !r.iter().all(|x| x.is_finite())) {
            return Err(Error::InvalidArgument(format!(
                "{name} row {i} holds {:?}: every value compared must be finite",
                rows[i]
            )));
        }
    }
    if let Some(i) = weights.iter().position(|w| !w.is_finite() || *w < 0.0) {
        return Err(Error::InvalidArgument(format!(
            "weights[{i}] = {}: weights must be finite and >= 0",
            weights[i]
        )));
    }
    if !weights.iter().any(|w| *w > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "weights are all zero ({} vertices): nothing would be compared; give positive \
             weights (vertex areas) to the vertices that count",
            weights.len()
        )));
    }
    let mut stats = ErrorStats::default();
    for c in 0..3 {
        let peak = truth
            .iter()
            .map(|t| f64::from(t[c]).abs())
            .fold(0.0, f64::max);
        let (mut num, mut den, mut worst) = (0.0, 0.0, 0.0f64);
        for ((e, t), w) in estimate.iter().zip(truth).zip(weights) {
            let (e, t, w) = (f64::from(e[c]), f64::from(t[c]), f64::from(*w));
            num += w * (e - t) * (e - t);
            den += w * t * t;
            if t.abs() >= MAX_FLOOR * peak && t != 0.0 {
                worst = worst.max((e - t).abs() / t.abs());
            }
        }
        stats.rel_rms[c] = if den > 0.0 {
            (num / den).sqrt()
        } else if num > 0.0 {
            f64::INFINITY
        } else {
            0.0
        };
        // An all-zero truth: the maximum is as undefined as the RMS; the same answer.
        stats.rel_max[c] = if peak > 0.0 {
            worst
        } else if estimate.iter().any(|e| e[c] != 0.0) {
            f64::INFINITY
        } else {
            0.0
        };
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_ten_percent_bias_reads_as_ten_percent() {
        let t = vec![[1.0, 2.0, 4.0]; 5];
        let e: Vec<[f32; 3]> = t.iter().map(|v| v.map(|x| x * 1.1)).collect();
        let s = relative_error(&e, &t, &[1.0; 5]).unwrap();
        for c in 0..3 {
            assert!((s.rel_rms[c] - 0.1).abs() < 1e-6);
            assert!((s.rel_max[c] - 0.1).abs() < 1e-6);
        }
    }

    #[test]
    fn weights_decide_which_vertex_counts() {
        let t = vec![[1.0; 3], [1.0; 3]];
        let e = vec![[1.0; 3], [2.0; 3]];
        let s = relative_error(&e, &t, &[1.0, 0.0]).unwrap();
        assert_eq!(s.rel_rms, [0.0; 3]);
        let s = relative_error(&e, &t, &[1.0, 3.0]).unwrap();
        assert!((s.rel_rms[0] - (3.0f64 / 4.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn an_all_zero_truth_is_exact_or_infinitely_wrong() {
        let t = vec![[0.0, 1.0, 0.0]; 3];
        let s = relative_error(&t, &t, &[1.0; 3]).unwrap();
        assert_eq!((s.rel_rms, s.rel_max), ([0.0; 3], [0.0; 3]));
        let e = vec![[1e-9, 1.0, 0.0]; 3];
        let s = relative_error(&e, &t, &[1.0; 3]).unwrap();
        assert_eq!(s.rel_rms, [f64::INFINITY, 0.0, 0.0]);
        assert_eq!(s.rel_max, [f64::INFINITY, 0.0, 0.0]);
    }

    #[test]
    fn non_finite_values_and_all_zero_weights_are_refused() {
        let t = vec![[1.0; 3]; 3];
        let mut e = t.clone();
        e[2][1] = f32::NAN;
        let m = relative_error(&e, &t, &[1.0; 3]).unwrap_err().to_string();
        assert!(m.contains("estimate row 2"), "{m}");
        let m = relative_error(&t, &e, &[1.0; 3]).unwrap_err().to_string();
        assert!(m.contains("truth row 2"), "{m}");
        let m = relative_error(&t, &t, &[0.0; 3]).unwrap_err().to_string();
        assert!(m.contains("all zero"), "{m}");
    }

    #[test]
    fn mismatched_lengths_are_an_error() {
        assert!(relative_error(&[[0.0; 3]], &[], &[]).is_err());
    }
}
