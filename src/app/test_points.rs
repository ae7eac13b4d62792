//! Where each point lies against a fitted model's training domain (issue 13): `test_points.csv` of
//! `calibrate` and the `domain` columns of `calibrate apply`.

use crate::calib::domain::Placement;
use crate::calib::method::Fitted;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::output::CsvText;

/// The `domain` cell: `inside`, or `outside: <what lies outside>`.
pub fn domain_cell(p: &Placement) -> String {
    if p.inside {
        "inside".into()
    } else {
        format!("outside: {}", p.outside.join("; "))
    }
}

/// Where `model` places each point of `data`.
pub fn place_all(model: &dyn Fitted, data: &Dataset) -> Vec<Placement> {
    let points = (0..data.len()).map(|i| (data.q[i].as_slice(), data.extra_inputs_of(i)));
    model.basis().domain.place_all(model.joint_names(), points)
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
    let mut csv = CsvText::new(
        "test_points.csv",
        [
            "point_id",
            "error_before_mm",
            "error_after_mm",
            "domain_distance_rad",
            "status",
        ],
    )?;
    for (((id, p), b), a) in ids.iter().zip(placements).zip(before_m).zip(after_m) {
        csv.text(id)?;
        csv.number(b * 1e3)?;
        csv.number(a * 1e3)?;
        csv.number(p.distance_rad)?;
        match p.inside {
            true => csv.text("inside")?,
            false => csv.text(&domain_cell(p))?,
        }
        csv.end_row()?;
    }
    let outside = placements.iter().filter(|p| !p.inside).count();
    Ok((csv.finish()?, outside))
}
