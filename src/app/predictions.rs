//! `predictions.csv` of `calibrate`: per point of the data, its split, the measured point, the nominal and the
//! calibrated prediction, and both errors (mm; with a 6-DoF probe, the orientations too). The model predicts
//! each point once, for this file and for judging it on the test split and against the truth.

use rayon::prelude::*;

use crate::calib::method::Fitted;
use crate::calib::tracker_frame::Observation;
use crate::dataset::{Dataset, Split};
use crate::error::Result;
use crate::eval::tables::{BeforeAfter, PointPrediction};
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

/// `model`'s [`PointPrediction`] of every point of `data`, in order: made once, for `predictions.csv` and for
/// judging the model on the test split and against the truth (the same configurations and inputs). In parallel;
/// each point's prediction is the same computation whatever the thread count.
pub fn predict_all(model: &dyn Fitted, data: &Dataset) -> Vec<PointPrediction> {
    (0..data.len())
        .into_par_iter()
        .map(|i| PointPrediction::of(model, &data.q[i], data.extra_inputs_of(i)))
        .collect()
}

/// The file's bytes for `model` on every point of `data`, labelled by `labels`; `predicted`: the model's
/// [`predict_all`] of `data`.
pub fn predictions_csv(
    model: &dyn Fitted,
    data: &Dataset,
    labels: &[Split],
    predicted: &[PointPrediction],
) -> Result<Vec<u8>> {
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
    let points = data.point_ids.iter().zip(&observations).zip(labels);
    for (((id, o), label), predicted) in points.zip(predicted) {
        let ((np, nr), p) = (predicted.nominal, &predicted.predicted);
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

/// The predictions of the test split's configurations, each made once: the measured points and the true ones
/// are judged at the same configurations with the same inputs.
pub struct TestPredicted<'a> {
    test: &'a Dataset,
    /// The model's, taken from its [`predict_all`] of the whole data.
    model: (&'a dyn Fitted, Vec<&'a PointPrediction>),
    /// The nominal model's, when it is not the model.
    nominal: Option<(&'a dyn Fitted, Vec<PointPrediction>)>,
}

impl<'a> TestPredicted<'a> {
    /// `test` is the data's points at `test_indices`; `predicted` the `model`'s [`predict_all`] of the data.
    pub fn of(
        test: &'a Dataset,
        test_indices: &[usize],
        (model, predicted): (&'a dyn Fitted, &'a [PointPrediction]),
        nominal: Option<&'a dyn Fitted>,
    ) -> TestPredicted<'a> {
        let nominal = nominal.map(|nominal| {
            let predicted = (0..test.len())
                .map(|i| PointPrediction::of(nominal, &test.q[i], test.extra_inputs_of(i)))
                .collect();
            (nominal, predicted)
        });
        TestPredicted {
            test,
            model: (model, test_indices.iter().map(|&i| &predicted[i]).collect()),
            nominal,
        }
    }

    /// The model's errors on `observed` (the test points, in order) and, with a nominal model, "before"
    /// measured by its errors on `nominal_observed` ([`BeforeAfter::measured_by`]).
    pub fn errors(
        &self,
        observed: &[Observation],
        nominal_observed: Option<&[Observation]>,
    ) -> BeforeAfter {
        let (model, predicted) = &self.model;
        let errors = self.at(*model, predicted.iter().copied(), observed);
        match (&self.nominal, nominal_observed) {
            (Some((nominal, predicted)), Some(observed)) => {
                errors.measured_by(&self.at(*nominal, predicted, observed))
            }
            _ => errors,
        }
    }

    /// `model`'s errors on `observed` from its predictions of the test points, `predicted`. A point observed at
    /// another configuration or with other inputs than the test point's is predicted anew (the callers' points
    /// are the test points: none is).
    fn at<'p>(
        &self,
        model: &dyn Fitted,
        predicted: impl IntoIterator<Item = &'p PointPrediction>,
        observed: &[Observation],
    ) -> BeforeAfter {
        let test = self.test;
        let anew: Vec<Option<PointPrediction>> = observed
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let same = o.q == test.q[i] && o.inputs == test.extra_inputs_of(i);
                (!same).then(|| PointPrediction::of(model, &o.q, &o.inputs))
            })
            .collect();
        let predicted = anew
            .iter()
            .zip(predicted)
            .map(|(a, p)| a.as_ref().unwrap_or(p));
        BeforeAfter::of_predicted(observed, predicted)
    }
}
