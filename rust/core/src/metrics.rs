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
    if weights.iter().any(|w| !w.is_finite() || *w < 0.0) {
        return Err(Error::InvalidArgument(
            "weights must be finite and >= 0".into(),
        ));
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
        stats.rel_max[c] = worst;
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
    fn mismatched_lengths_are_an_error() {
        assert!(relative_error(&[[0.0; 3]], &[], &[]).is_err());
    }
}
