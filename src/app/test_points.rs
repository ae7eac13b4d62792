//! Where each point lies against a fitted model's training domain (issue 13): `test_points.csv` of
//! `calibrate` and the `domain` columns of `calibrate apply`.

use crate::calib::domain::Placement;
use crate::calib::method::Fitted;
use crate::error::{Error, Result};

/// The `domain` cell: `inside`, or `outside: <what lies outside>`.
pub fn domain_cell(p: &Placement) -> String {
    if p.inside {
        "inside".into()
    } else {
        format!("outside: {}", p.outside.join("; "))
    }
}

/// Where `model` places `q` with `inputs`.
pub fn place(model: &dyn Fitted, q: &[f64], inputs: &[f64]) -> Placement {
    model.basis().domain.place(model.joint_names(), q, inputs)
}

/// `test_points.csv`: per test point its id, the Measured (nominal) and the calibrated error (mm), the
/// joint-space distance to the nearest training configuration and whether it lies inside the training
/// domain. Returns the file and how many points lie outside.
pub fn test_points_csv(
    ids: &[String],
    placements: &[Placement],
    before_m: &[f64],
    after_m: &[f64],
) -> Result<(Vec<u8>, usize)> {
    let csv_err = |e: csv::Error| Error::Invalid(format!("test_points.csv: {e}"));
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "point_id",
        "error_before_mm",
        "error_after_mm",
        "domain_distance_rad",
        "status",
    ])
    .map_err(csv_err)?;
    for (((id, p), b), a) in ids.iter().zip(placements).zip(before_m).zip(after_m) {
        w.write_record([
            id.clone(),
            (b * 1e3).to_string(),
            (a * 1e3).to_string(),
            p.distance_rad.to_string(),
            domain_cell(p),
        ])
        .map_err(csv_err)?;
    }
    let outside = placements.iter().filter(|p| !p.inside).count();
    let bytes = w
        .into_inner()
        .map_err(|e| Error::Invalid(format!("test_points.csv: {e}")))?;
    Ok((bytes, outside))
}
