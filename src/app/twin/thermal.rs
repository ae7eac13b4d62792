//! The warm-up a pilot's temperature column shows, as the truth's thermal profile: the links' temperature
//! `T(t) = T_end + (T_start − T_end) e^(−t/τ)` over the campaign's time, fitted to the column by least squares
//! (for each τ of a logarithmic grid, start and end are linear), with the points' spacing in time from the
//! pilot's time column or, without one, the stop-and-go time per point the studies assume.

use crate::truth::ThermalProfile;

/// Seconds from one point to the next without a time column: move, settle, measure (the study's defaults,
/// `scenarios/README.md`).
const SECONDS_PER_POINT: f64 = 6.0;
/// Linear expansion of the links (1/K): aluminium castings, 23e-6 /K (as `scenarios/README.md` cites).
const EXPANSION_PER_K: f64 = 23e-6;
/// The temperature at which a robot's nominal lengths hold (°C): ISO 1's standard reference temperature.
const REFERENCE_C: f64 = 20.0;
/// The warm-up's time constant is searched between these (s), on a logarithmic grid of this many steps.
const TAU_RANGE_S: (f64, f64) = (60.0, 1e6);
const TAU_STEPS: usize = 200;

/// The profile that follows `temperature` (°C, one per point in order), and where its values come from.
pub fn warm_up(temperature: &[f64], time: Option<&[f64]>) -> (ThermalProfile, String) {
    let n = temperature.len();
    let (t, spacing): (Vec<f64>, String) = match time {
        Some(time) if time.len() == n => {
            let t0 = time[0];
            (
                time.iter().map(|s| s - t0).collect(),
                "the pilot's time column".into(),
            )
        }
        _ => (
            (0..n).map(|k| k as f64 * SECONDS_PER_POINT).collect(),
            format!(
                "{SECONDS_PER_POINT} s per point (no time column; the studies' stop-and-go time)"
            ),
        ),
    };
    let seconds_per_point = t.last().copied().unwrap_or(0.0) / (n.max(2) - 1) as f64;
    // The level the links settle at is held to at most as far again beyond what the pilot saw as the pilot's
    // own span: a column still rising at its end says little about where it stops, and an exponential
    // fitted to a straight ramp would put it anywhere (a long τ with a far end fits a line as well as a
    // short one with a near end). A curved column that has not yet levelled off still finds its end.
    let (lo_c, hi_c) = temperature
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let (lo_c, hi_c) = (lo_c - (hi_c - lo_c), hi_c + (hi_c - lo_c));
    // T = end + (start − end) e^(−t/τ) is linear in (end, start − end) for a given τ: least squares there,
    // and τ by a logarithmic grid refined once around its best step.
    let fit_at = |tau: f64| -> Option<(f64, f64, f64, f64)> {
        let e: Vec<f64> = t.iter().map(|s| (-s / tau).exp()).collect();
        let (s1, se, see) = (
            n as f64,
            e.iter().sum::<f64>(),
            e.iter().map(|x| x * x).sum::<f64>(),
        );
        let sy: f64 = temperature.iter().sum();
        let sey: f64 = e.iter().zip(temperature).map(|(x, y)| x * y).sum();
        let det = s1 * see - se * se;
        if det.abs() < 1e-12 {
            return None;
        }
        let mut end = (see * sy - se * sey) / det;
        let mut amplitude = (s1 * sey - se * sy) / det;
        if !(lo_c..=hi_c).contains(&end) {
            // Beyond the bound: the end at the nearer bound, the amplitude alone by least squares.
            end = end.clamp(lo_c, hi_c);
            amplitude = (sey - end * se) / see;
        }
        let sse: f64 = e
            .iter()
            .zip(temperature)
            .map(|(x, y)| (end + amplitude * x - y).powi(2))
            .sum();
        Some((sse, tau, end + amplitude, end))
    };
    let grid = |lo: f64, hi: f64| {
        (0..TAU_STEPS)
            .filter_map(|k| fit_at(lo * (hi / lo).powf(k as f64 / (TAU_STEPS - 1) as f64)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
    };
    let (lo, hi) = TAU_RANGE_S;
    let step = (hi / lo).powf(1.0 / (TAU_STEPS - 1) as f64);
    let coarse = grid(lo, hi);
    let best = coarse
        .and_then(|c| grid((c.1 / step).max(lo), (c.1 * step).min(hi)))
        .or(coarse)
        .unwrap_or((0.0, lo, temperature[0], temperature[n - 1]));
    let (sse, tau, start, end) = best;
    let profile = ThermalProfile {
        start_c: start,
        end_c: end,
        time_constant_s: tau,
        seconds_per_point,
        expansion_per_k: EXPANSION_PER_K,
        reference_c: REFERENCE_C,
    };
    let source = format!(
        "fitted to the pilot's temperature column ({:.2} → {:.2} °C, τ {:.0} s, RMS {:.3} K; spacing: {spacing}); \
         expansion of aluminium 23e-6 /K, nominal lengths at ISO 1's 20 °C",
        start,
        end,
        tau,
        (sse / n as f64).sqrt()
    );
    (profile, source)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A warm-up sampled without noise comes back: start, end and time constant.
    #[test]
    fn a_sampled_warm_up_is_recovered() {
        let truth = ThermalProfile {
            start_c: 21.0,
            end_c: 23.5,
            time_constant_s: 1800.0,
            seconds_per_point: SECONDS_PER_POINT,
            expansion_per_k: EXPANSION_PER_K,
            reference_c: REFERENCE_C,
        };
        let column: Vec<f64> = (0..300).map(|k| truth.temperature(k)).collect();
        let (fit, _) = warm_up(&column, None);
        assert!((fit.start_c - 21.0).abs() < 0.01, "{fit:?}");
        assert!((fit.end_c - 23.5).abs() < 0.01, "{fit:?}");
        assert!((fit.time_constant_s / 1800.0 - 1.0).abs() < 0.05, "{fit:?}");
    }

    /// A column still rising at its end (a ramp) does not put the settled temperature further beyond what was
    /// seen than the pilot's own span.
    #[test]
    fn a_ramp_settles_within_what_was_seen() {
        let column: Vec<f64> = (0..400).map(|k| 21.5 + 0.001 * k as f64).collect();
        let (fit, _) = warm_up(&column, None);
        assert!(fit.end_c <= 21.5 + 2.0 * 0.399 + 1e-9, "{fit:?}");
        assert!((fit.start_c - 21.5).abs() < 0.05, "{fit:?}");
    }
}
