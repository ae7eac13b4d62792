//! Calibration methods: register the tracker frame, fit a model of the robot's errors, predict and invert.
//!
//! **Layering** (each file imports only files above it in this list; none imports the registry but the stages
//! that choose a method):
//!
//! 1. `rigid` (point-set registration by SVD), `regression/` (ridge models and their selection),
//!    `error_model` (the paper's error parameters on the DH chain), `reduced` (a tall least-squares problem
//!    as Levenberg–Marquardt's equivalent small one), `min_norm` (eq. 13's minimum-norm solve) — no other
//!    file of calib;
//! 2. `tracker_frame` (the tracker frame and mounting every method starts from: `Registration`, `Observation`)
//!    — `rigid`, `reduced`; `correction` (ridge models of what a reference prediction leaves: `ResidualCorrection`)
//!    — `tracker_frame`, `regression`;
//! 3. `method` (the `Method` trait — how a method fits —, the `Fitted` trait, `MethodInfo` — what a method is —,
//!    `Basis`, `FitContext`) — `tracker_frame`, `regression`, `error_model`; it knows no method;
//! 4. the methods, one file (or directory) each, each with its `MethodInfo` constants and its `impl Method`:
//!    `paper` (`nominal` and the paper's three: `Paper`), `kinematic/` (`kinematic`, `elastic`: `Kinematic`),
//!    `residual` (`residual-ridge`, and `Hybrid`, a base method's prediction plus a residual model) — `method`
//!    and the files above;
//! 5. `registry` (the list of methods, which makes `MethodKind`; `SavedModel`: `model.json`) — everything above.
//!
//! **Adding a method** is its own file (the model, its `impl Fitted`, its `const …: MethodInfo` — name, summary,
//! whether it takes extra inputs, its base if it is a hybrid, the robot parameters it identifies — and its
//! `impl Method`), its `pub mod` below, and one line in the registry's list, `Variant => &TheMethod,`. A method
//! whose fitted model is of a new type also needs a `SavedModel` variant, with its arms in `SavedModel::of` (a
//! downcast the compiler does not check: a forgotten type makes `save()` an error naming the method, and the
//! registry's test that every method saves and loads fails) and `into_fitted` (which calls the model's own
//! `validate`, since a saved model is input and must fit its own contents before it predicts).
//!
//! Everything else holds a `MethodKind` and asks it: `info()` for what the method is (the selection's check
//! that a method has robot parameters, which methods take extra inputs, a hybrid's base, the model a campaign
//! is designed for), `fit()` to fit it. No file outside calib spells a method's name (`house_rules` checks it):
//! the reports find the uncalibrated reference as `registry::REFERENCE`.
pub mod clock;
pub mod correction;
pub mod domain;
pub mod error_model;
pub mod kinematic;
pub mod method;
pub mod min_norm;
pub mod reduced;
pub mod motion_inputs;
pub mod paper;
pub mod registry;
pub mod regression;
pub mod residual;
pub mod rigid;
pub mod tracker_frame;
