//! Calibration methods. Registration first; the paper's method follows (issue 3).
pub mod registration;
