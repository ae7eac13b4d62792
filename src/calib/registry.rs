//! The methods a user can choose, and `model.json`: the one place that lists every method. It sits above the
//! methods' files (each of which knows only [`super::method`]); nothing in calib below it imports it.
//!
//! What a method is ([`MethodInfo`]: whether it takes extra inputs, has robot parameters, its base, its design
//! model) and how it fits ([`Method`]) are not said here: each entry of the list points to the method's own
//! file. A [`MethodKind`] is the typed value every configuration, run key and report row holds; it is read
//! from and written as the method's name, here and nowhere else.

use std::any::Any;
use std::fmt;
use std::path::Path;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::error_model::ErrorModelKind;
use super::kinematic::{Kinematic, KinematicModel};
use super::method::{FitContext, Fitted, Method, MethodInfo};
use super::paper::{Paper, PaperModel};
use super::residual::{
    Hybrid, HybridFitted, HybridModel, ResidualCorrection, ResidualModel, ResidualRidge,
};
use crate::dataset::Dataset;
use crate::error::{Error, Result};

/// The list of methods: `Variant => the method`, one line each, in the order reports list them. It makes the
/// [`MethodKind`] enum, [`MethodKind::ALL`] and [`MethodKind::method`].
macro_rules! methods {
    ($($kind:ident => $method:expr,)*) => {
        /// The methods a user can fit. `oracle` is not here: it needs the truth, and only the evaluation has it.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub enum MethodKind {
            $($kind,)*
        }

        impl MethodKind {
            pub const ALL: [MethodKind; [$(stringify!($kind)),*].len()] = [$(MethodKind::$kind,)*];

            /// The method: what it is and how it fits, from its own file.
            pub fn method(self) -> &'static dyn Method {
                match self {
                    $(MethodKind::$kind => $method,)*
                }
            }
        }
    };
}

methods! {
    Nominal => &Paper(None),
    PaperRotz => &Paper(Some(ErrorModelKind::RotZ)),
    PaperRotxyz => &Paper(Some(ErrorModelKind::RotXyz)),
    PaperRotxyzTransxyz => &Paper(Some(ErrorModelKind::RotXyzTransXyz)),
    Kinematic => &Kinematic { elastic: false },
    Elastic => &Kinematic { elastic: true },
    ResidualRidge => &ResidualRidge,
    Hybrid => &Hybrid { base: &Kinematic { elastic: true } },
    HybridKinematic => &Hybrid { base: &Kinematic { elastic: false } },
}

/// The method every report compares the others with: the uncalibrated robot on the registered tracker frame
/// (the paper's "Measured").
pub const REFERENCE: MethodKind = MethodKind::Nominal;

/// The method `calibrate` fits unless told otherwise: what the results recommend. On the real UR10 campaigns
/// it is the most accurate on a campaign other than the one it was fitted on, where the regression methods fall
/// back to their constant parts, and in the simulated study it reaches the lowest floor (with `hybrid`, which
/// adds a residual regression to it); within one layout the methods end close together.
pub const RECOMMENDED: MethodKind = MethodKind::Elastic;

/// Classical calibration, constant geometric parameters: the method the field's others are measured against
/// (the real-data tables give each best result as a margin below it).
pub const CLASSICAL: MethodKind = MethodKind::Kinematic;

/// The physical model of an arm, its geometry and joint compliances: what a twin of a measured arm is
/// identified with, and whose error on points it was not fitted on a twin reproduces.
pub const PHYSICAL: MethodKind = MethodKind::Elastic;

impl MethodKind {
    /// What the method is, as its own file states it.
    pub fn info(self) -> &'static MethodInfo {
        self.method().info()
    }

    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// The method of `info` (a hybrid's base, say); `None` for a method not in the list.
    pub fn of(info: &MethodInfo) -> Option<MethodKind> {
        MethodKind::ALL.into_iter().find(|m| m.info() == info)
    }

    /// Fits the method on `train`, with `val` for its hyper-parameters.
    pub fn fit(self, ctx: &FitContext, train: &Dataset, val: &Dataset) -> Result<Box<dyn Fitted>> {
        self.method().fit(ctx, train, val)
    }

    pub fn parse(name: &str) -> Result<MethodKind> {
        MethodKind::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = MethodKind::ALL.iter().map(|m| m.name()).collect();
                Error::Invalid(format!(
                    "unknown method '{name}'; choose one of {}",
                    names.join(", ")
                ))
            })
    }
}

impl fmt::Display for MethodKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// A method is written to files by its name.
impl Serialize for MethodKind {
    fn serialize<S: Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

/// … and read from its name, with the list of names when it is none of them.
impl<'de> Deserialize<'de> for MethodKind {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        MethodKind::parse(&name).map_err(|e| serde::de::Error::custom(e.detail()))
    }
}

/// `model.json`: any fitted method, tagged by its model type, so `calibrate apply` can load what `calibrate`
/// saved.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case")]
pub enum SavedModel {
    Paper(PaperModel),
    Kinematic(Box<KinematicModel>),
    Residual(ResidualModel),
    Hybrid(SavedHybrid),
}

/// A hybrid in `model.json`: its name, its base's saved model and the residual model.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SavedHybrid {
    pub method: String,
    pub base: Box<SavedModel>,
    pub residual: ResidualCorrection,
}

impl SavedModel {
    /// What `model.json` holds for `model`; `None` for a model type it does not hold (the oracle).
    pub fn of(model: &dyn Fitted) -> Option<SavedModel> {
        let any: &dyn Any = model;
        if let Some(m) = any.downcast_ref::<PaperModel>() {
            return Some(SavedModel::Paper(m.clone()));
        }
        if let Some(m) = any.downcast_ref::<KinematicModel>() {
            return Some(SavedModel::Kinematic(Box::new(m.clone())));
        }
        if let Some(m) = any.downcast_ref::<ResidualModel>() {
            return Some(SavedModel::Residual(m.clone()));
        }
        let h = any.downcast_ref::<HybridFitted>()?;
        Some(SavedModel::Hybrid(SavedHybrid {
            method: h.model().method.clone(),
            base: Box::new(SavedModel::of(h.base())?),
            residual: h.model().residual.clone(),
        }))
    }

    /// The model, ready to predict, after checking it whole: a saved model is input, and one that does not
    /// fit its own contents (a DH row or coefficient too few) or holds numbers no fit gives (1e300) would
    /// panic or predict nonsense. Each model type checks itself (`validate` next to it); the error names the
    /// field by its path in the file (`base.dh.rows[2].d` in a hybrid's base). See [`SavedModel::read`].
    pub fn into_fitted(self) -> Result<Box<dyn Fitted>> {
        Ok(match self {
            SavedModel::Paper(m) => {
                m.validate()?;
                Box::new(m)
            }
            SavedModel::Kinematic(m) => {
                m.validate()?;
                m
            }
            SavedModel::Residual(m) => {
                m.validate()?;
                Box::new(m)
            }
            SavedModel::Hybrid(h) => {
                let base = h
                    .base
                    .into_fitted()
                    .map_err(|e| Error::Invalid(format!("base.{}", e.detail())))?;
                let hybrid = HybridModel {
                    method: h.method,
                    residual: h.residual,
                };
                hybrid.validate(base.as_ref())?;
                Box::new(hybrid.on(base))
            }
        })
    }

    /// Reads `model.json` at `path` into a model ready to predict ([`SavedModel::into_fitted`]); any fault is
    /// one `Error::Data` naming the file (and the field).
    pub fn read(path: &Path) -> Result<Box<dyn Fitted>> {
        let data = |message: String| Error::Data {
            origin: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| data(format!("cannot read: {e}")))?;
        let saved: SavedModel = serde_json::from_str(&text).map_err(|e| {
            // A model's fields are read through buffered content (its tag, its flattened basis), which loses
            // the place of a wrong type; find the number written as a string or null ourselves.
            let place = serde_json::from_str::<serde_json::Value>(&text)
                .ok()
                .and_then(|v| wrong_type_at(&v, &e.to_string(), ""))
                .map_or(String::new(), |field| format!("{field}: "));
            data(format!("not a calibrate model: {place}{e}"))
        })?;
        saved
            .into_fitted()
            .map_err(|e| data(format!("not a usable model: {}", e.detail())))
    }
}

/// Fields of `model.json` that may be `null`.
const NULLABLE: [&str; 7] = [
    "kind",
    "nest",
    "compliance",
    "gravity",
    "orientation_length_m",
    "validation_rms_m",
    "probe_rotation",
];

/// The path (`dh.rows[1].d`) of the first value that serde's `error` is about when it is a wrong type where
/// a number belongs: a `null` in a list or in a field that is never null, or the very string it names
/// (`"NaN"`). `None` for any other error.
fn wrong_type_at(value: &serde_json::Value, error: &str, path: &str) -> Option<String> {
    use serde_json::Value;
    let culprit = |k: Option<&str>, v: &Value| match v {
        Value::Null => {
            error.contains("invalid type: null") && k.is_none_or(|k| !NULLABLE.contains(&k))
        }
        Value::String(s) => error.contains(&format!("invalid type: string {s:?}")),
        _ => false,
    };
    match value {
        Value::Array(items) => items.iter().enumerate().find_map(|(i, v)| {
            let field = format!("{path}[{i}]");
            if culprit(None, v) {
                Some(field)
            } else {
                wrong_type_at(v, error, &field)
            }
        }),
        Value::Object(fields) => fields.iter().find_map(|(k, v)| {
            let field = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            if culprit(Some(k), v) {
                Some(field)
            } else {
                wrong_type_at(v, error, &field)
            }
        }),
        _ => None,
    }
}

/// `model.save()`: what `model.json` holds, for any model of a type it holds (see [`SavedModel::of`]); a model
/// it does not hold (the oracle, or a new model type the registry was not told of) is an error, not a panic.
pub trait Save {
    fn save(&self) -> Result<SavedModel>;
}

impl Save for dyn Fitted {
    fn save(&self) -> Result<SavedModel> {
        SavedModel::of(self).ok_or_else(|| {
            Error::Invalid(format!(
                "{}: model.json cannot hold this model (its type is not in calib::registry::SavedModel)",
                self.method()
            ))
        })
    }
}

impl<T: Fitted> Save for T {
    fn save(&self) -> Result<SavedModel> {
        (self as &dyn Fitted).save()
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Point3};

    use super::*;
    use crate::calib::method::{Basis, FitShare};
    use crate::calib::tracker_frame::{Registration, TrackerFrame};
    use crate::robot::dh::DhChain;
    use crate::robot::urdf;

    /// `model.json` writes the shared fields where the models wrote them before they shared a `Basis`, and
    /// the method by its name.
    #[test]
    fn saved_models_keep_their_field_order() {
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let basis = Basis {
            joint_names: chain.joint_names(),
            dh: DhChain::from_chain(&chain).unwrap(),
            registration: Registration {
                frame: TrackerFrame {
                    tracker_to_base: Isometry3::identity(),
                    mounting: Point3::new(0.0, 0.0, 0.03),
                    rms: 0.0,
                    evaluations: 0,
                },
                nest: None,
                probe_rotation: None,
                base_frame: false,
            },
            domain: Default::default(),
        };
        let paper = PaperModel {
            method: &crate::calib::paper::NOMINAL,
            kind: None,
            basis: basis.clone(),
            candidates: Vec::new(),
            extra_inputs: Vec::new(),
            extra_input_means: Vec::new(),
            position: Vec::new(),
            orientation: Vec::new(),
            features: Default::default(),
        };
        let order = |text: &str, keys: &[&str]| {
            let at: Vec<usize> = keys
                .iter()
                .map(|k| text.find(&format!("\"{k}\":")).unwrap())
                .collect();
            assert!(at.windows(2).all(|w| w[0] < w[1]), "{keys:?} in {text}");
        };
        let text = serde_json::to_string(&SavedModel::of(&paper).unwrap()).unwrap();
        assert!(
            text.starts_with(r#"{"model":"paper","method":"nominal","kind":null,"joint_names":"#)
        );
        order(
            &text,
            &[
                "joint_names",
                "dh",
                "registration",
                "candidates",
                "extra_inputs",
                "extra_input_means",
                "position",
                "orientation",
            ],
        );
        let back: SavedModel = serde_json::from_str(&text).unwrap();
        assert_eq!(serde_json::to_string(&back).unwrap(), text);
        assert_eq!(back.into_fitted().unwrap().method(), "nominal");
    }

    /// The list is consistent: names unique, each kind's method says it is that kind, a hybrid's description
    /// names the base it fits, and every name reads back as its kind.
    #[test]
    fn the_list_is_consistent() {
        for (i, kind) in MethodKind::ALL.into_iter().enumerate() {
            assert_eq!(MethodKind::parse(kind.name()).unwrap(), kind);
            assert_eq!(MethodKind::of(kind.info()), Some(kind));
            // Tables align a method's name in a column.
            assert_eq!(format!("{kind:<25}|").find('|'), Some(25));
            assert_eq!(format!("{:<25}|", kind.info()).find('|'), Some(25));
            assert!(
                MethodKind::ALL[..i].iter().all(|m| m.name() != kind.name()),
                "{kind} twice"
            );
            let json = serde_json::to_string(&kind).unwrap();
            assert_eq!(json, format!("\"{kind}\""));
            assert_eq!(serde_json::from_str::<MethodKind>(&json).unwrap(), kind);
        }
        for (hybrid, base) in [
            (MethodKind::Hybrid, MethodKind::Elastic),
            (MethodKind::HybridKinematic, MethodKind::Kinematic),
        ] {
            assert_eq!(hybrid.info().base, Some(base.info()));
        }
        let e = serde_json::from_str::<MethodKind>("\"oracle\"").unwrap_err();
        assert!(e.to_string().contains("unknown method 'oracle'"), "{e}");
    }

    /// Every method of the list saves, and its `model.json` loads into a model that predicts the same, bit for
    /// bit: a model type missing from `SavedModel` fails here, not in a user's `calibrate`.
    #[test]
    fn every_method_saves_and_loads() {
        use rand::{Rng, SeedableRng};
        let chain = urdf::load_file("robots/iiwa7.urdf", None).unwrap();
        let dh = DhChain::from_chain(&chain).unwrap();
        let ctx = FitContext::new(&chain, &dh);
        let (lower, upper) = ctx.limits();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let reflector = Point3::new(0.01, 0.02, 0.08);
        let mut set = |n: usize| {
            let q: Vec<Vec<f64>> = (0..n)
                .map(|_| {
                    (0..lower.len())
                        .map(|j| 0.6 * rng.random_range(lower[j]..upper[j]))
                        .collect()
                })
                .collect();
            // A small error the joints explain smoothly, so every model has something to fit.
            let measured = q
                .iter()
                .map(|q| {
                    let p = dh.flange_pose(q) * reflector;
                    vec![p + nalgebra::Vector3::new(1e-4 * q[1].sin(), 5e-5 * q[3], 0.0)]
                })
                .collect();
            Dataset::in_memory("synthetic", chain.joint_names(), q, measured)
        };
        let (train, val, test) = (set(150), set(75), set(10));
        // Every method fitted at once on the same sets, sharing what they compute alike: the models below,
        // fitted alone, are the same to the bit (their `model.json` text).
        let share = FitShare::new(&train, &val);
        let sharing = ctx.sharing(&share);
        let (sharing, train_ref, val_ref) = (&sharing, &train, &val);
        let shared: Vec<String> = std::thread::scope(|s| {
            let fits: Vec<_> = MethodKind::ALL
                .into_iter()
                .map(|kind| s.spawn(move || kind.fit(sharing, train_ref, val_ref).unwrap()))
                .collect();
            fits.into_iter()
                .map(|f| serde_json::to_string(&f.join().unwrap().save().unwrap()).unwrap())
                .collect()
        });
        for (kind, shared) in MethodKind::ALL.into_iter().zip(shared) {
            let model = kind
                .fit(&ctx, &train, &val)
                .unwrap_or_else(|e| panic!("{kind:?}: {e}"));
            let text = serde_json::to_string(&model.save().unwrap()).unwrap();
            assert_eq!(text, shared, "{kind:?}");
            let back = serde_json::from_str::<SavedModel>(&text)
                .unwrap()
                .into_fitted()
                .unwrap();
            assert_eq!(back.method(), kind.name());
            for q in &test.q {
                let (a, b) = (model.predict(q), back.predict(q));
                assert_eq!(a.position, b.position, "{kind:?}");
                assert_eq!(a.orientation, b.orientation, "{kind:?}");
            }
        }

        // The same points with an extra input (as a trajectory campaign's `+ motion` fits have): fitted
        // beside the fits above, taking from them what does not read the inputs (the registration, the
        // kinematic fits under the hybrids, the paper's frames), every model is again the one fitted alone —
        // its training domain included, which covers the input.
        let with_input = |d: &Dataset, scale: f64| Dataset {
            extra_inputs: Some(crate::dataset::ExtraInputs {
                names: vec!["load".into()],
                values: d.q.iter().map(|q| vec![scale * q[1].cos()]).collect(),
            }),
            ..d.clone()
        };
        let (train_in, val_in) = (with_input(&train, 3.0), with_input(&val, 3.0));
        assert!(FitShare::beside(&share, &val_in, &train_in).is_none());
        let beside = FitShare::beside(&share, &train_in, &val_in).expect("the same points");
        let sharing = ctx.sharing(&beside);
        for kind in MethodKind::ALL {
            let alone = kind
                .fit(&ctx, &train_in, &val_in)
                .unwrap_or_else(|e| panic!("{kind:?}: {e}"));
            let shared = kind.fit(&sharing, &train_in, &val_in).unwrap();
            let text = |m: &dyn Fitted| serde_json::to_string(&m.save().unwrap()).unwrap();
            assert_eq!(text(alone.as_ref()), text(shared.as_ref()), "{kind:?}");
        }
    }
}
