//! Summary statistics of a set of errors (Tables 1 and 2 of the paper, plus RMS and 95th percentile).

use serde::{Deserialize, Serialize};

/// In the unit of the values (SI inside the code; reports convert).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Stats {
    pub n: usize,
    pub mean: f64,
    pub max: f64,
    /// Population standard deviation (ddof = 0, as numpy's default that the paper's tables likely used).
    pub std: f64,
    pub rms: f64,
    /// 95th percentile, linear interpolation between order statistics (numpy's default).
    pub p95: f64,
}

impl Stats {
    /// `None` for an empty set or one holding a non-finite value.
    pub fn of(values: &[f64]) -> Option<Stats> {
        if values.is_empty() || values.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        let rms = (values.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let rank = 0.95 * (sorted.len() - 1) as f64;
        let (lo, frac) = (rank.floor() as usize, rank.fract());
        let p95 = if lo + 1 < sorted.len() {
            sorted[lo] + frac * (sorted[lo + 1] - sorted[lo])
        } else {
            sorted[lo]
        };
        Some(Stats {
            n: values.len(),
            mean,
            max: sorted[sorted.len() - 1],
            std: var.sqrt(),
            rms,
            p95,
        })
    }

    /// The same statistics scaled (e.g. metres to millimetres).
    pub fn scaled(&self, factor: f64) -> Stats {
        Stats {
            n: self.n,
            mean: self.mean * factor,
            max: self.max * factor,
            std: self.std * factor,
            rms: self.rms * factor,
            p95: self.p95 * factor,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_of_a_known_set() {
        let s = Stats::of(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(s.mean, 2.5);
        assert_eq!(s.max, 4.0);
        assert!((s.std - 1.25f64.sqrt()).abs() < 1e-15);
        assert!((s.rms - 7.5f64.sqrt()).abs() < 1e-15);
        // numpy.percentile([1, 2, 3, 4], 95) = 3.85
        assert!((s.p95 - 3.85).abs() < 1e-12);
        assert!(Stats::of(&[]).is_none());
        assert!(Stats::of(&[1.0, f64::NAN]).is_none());
    }
}
