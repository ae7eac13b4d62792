//! Calibration methods. Registration first; the paper's method follows (issue 3).
pub mod error_model;
pub mod kinematic;
pub mod method;
pub mod paper;
pub mod registry;
pub mod regression;
pub mod residual;
pub mod rigid;
pub mod tracker_frame;
