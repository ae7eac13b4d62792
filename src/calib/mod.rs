//! Calibration methods: register the tracker frame, fit a model of the robot's errors, predict and invert.
//!
//! **Layering** (each file imports only files above it in this list; none imports the registry but the stages
//! that choose a method):
//!
//! 1. `rigid` (point-set registration by SVD), `regression/` (ridge models and their selection),
//!    `error_model` (the paper's error parameters on the DH chain) — no other file of calib;
//! 2. `tracker_frame` (the tracker frame and mounting every method starts from: `Registration`, `Observation`)
//!    — `rigid`; `correction` (ridge models of what a reference prediction leaves: `ResidualCorrection`)
//!    — `tracker_frame`, `regression`;
//! 3. `method` (the `Fitted` trait, `MethodInfo` — what a method is —, `Basis`, `FitContext`) — `tracker_frame`,
//!    `regression`, `error_model`; it knows no method;
//! 4. the methods, one file (or directory) each: `paper` (`nominal` and the paper's three), `kinematic/`
//!    (`kinematic`, `elastic`), `residual` (`residual-ridge`, and the hybrids, which are given their fitted base
//!    and name it by the `MethodInfo` constants of `kinematic`) — `method` and the files above;
//! 5. `registry` (`MethodKind`, `fit`, `SavedModel`: the list of methods and `model.json`) — everything above.
//!
//! **Adding a method touches 3 places**, none of them a string or `matches!` outside the method's own file
//! and the registry:
//!
//! 1. its own file: the model, its `impl Fitted` and its `const …: MethodInfo` (name, summary, whether it takes
//!    extra inputs, its base if it is a hybrid, the model its points are designed for — which also says whether
//!    it has robot parameters);
//! 2. `calib/mod.rs`: `pub mod …;`;
//! 3. `calib/registry.rs`: the `MethodKind` variant, its place in `MethodKind::ALL`, its arms in
//!    `MethodKind::info` and `fit` (the compiler asks for both), and for a new model type a `SavedModel`
//!    variant with its arms in `SavedModel::of` and `into_fitted` (the first is a downcast the compiler does not
//!    check: a forgotten type makes `save()` an error naming the method, and the registry's test that every
//!    method saves and loads fails; the second calls the model's own `validate`, since a saved model is input
//!    and must fit its own contents before it predicts).
//!
//! Everything else asks the descriptor (`MethodKind::info()`): the selection's check that a method has robot
//! parameters (`campaign::region`), which methods take extra inputs (`bin/real_data`), a hybrid's base
//! (`report::summary`), the model a campaign is designed for (`design::model`).
pub mod clock;
pub mod correction;
pub mod domain;
pub mod error_model;
pub mod kinematic;
pub mod method;
pub mod motion_inputs;
pub mod paper;
pub mod registry;
pub mod regression;
pub mod residual;
pub mod rigid;
pub mod tracker_frame;
