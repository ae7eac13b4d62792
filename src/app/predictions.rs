//! `predictions.csv` of `calibrate`: per point of the data, its split, the measured point, the nominal and the
//! calibrated prediction, and both errors (mm; with a 6-DoF probe, the orientations too).

use crate::calib::method::Fitted;
use crate::dataset::{Dataset, Split};
use crate::error::Result;
use crate::output::CsvText;

const POSITION_COLUMNS: [&str; 13] = [
    "point_id",
    "split",
    "measured_x",
    "measured_y",
    "measured_z",
    "nominal_x",
    "nominal_y",
    "nominal_z",
    "predicted_x",
    "predicted_y",
    "predicted_z",
    "error_before_mm",
    "error_after_mm",
];

const ORIENTATION_COLUMNS: [&str; 6] = [
    "predicted_qw",
    "predicted_qx",
    "predicted_qy",
    "predicted_qz",
    "orientation_before_rad",
    "orientation_after_rad",
];

/// The file's bytes for `model` on every point of `data`, labelled by `labels`.
pub fn predictions_csv(model: &dyn Fitted, data: &Dataset, labels: &[Split]) -> Result<Vec<u8>> {
    let observations = model.registration().observe(data)?;
    let with_orientation = model.registration().measures_orientation();
    let orientation: &[&str] = if with_orientation {
        &ORIENTATION_COLUMNS
    } else {
        &[]
    };
    let mut csv = CsvText::new(
        "predictions.csv",
        POSITION_COLUMNS.iter().chain(orientation),
    )?;
    for ((id, o), label) in data.point_ids.iter().zip(&observations).zip(labels) {
        let (np, nr) = model.nominal(&o.q);
        let p = model.predict_with(&o.q, &o.inputs);
        csv.text(id)?;
        csv.text(label.name())?;
        for v in [o.position.coords, np.coords, p.position.coords] {
            for x in v.iter() {
                csv.number(*x)?;
            }
        }
        csv.number((o.position - np).norm() * 1e3)?;
        csv.number((o.position - p.position).norm() * 1e3)?;
        if with_orientation {
            let q = p.orientation.quaternion();
            for v in [q.w, q.i, q.j, q.k] {
                csv.number(v)?;
            }
            let m = o.orientation.unwrap_or(nr);
            csv.number(m.angle_to(&nr))?;
            csv.number(m.angle_to(&p.orientation))?;
        }
        csv.end_row()?;
    }
    csv.finish()
}
