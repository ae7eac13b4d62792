//! Experiment design: how well a campaign's configurations determine a model's parameters, and which
//! configurations to measure so that they determine them best.
//!
//! - [`model`]: the model whose parameters a campaign must determine, as a Jacobian per configuration,
//!   columns scaled to a fixed, campaign-independent unit so that indices compare across campaigns;
//! - [`observability`]: the indices of a campaign (O1, O2, O3 and the D-criterion) from that Jacobian;
//! - [`select`]: D-optimal choice of N configurations from a candidate pool, greedy then DETMAX exchange,
//!   with low-rank determinant updates;
//! - [`lazy`]: lazy greedy evaluation for it (gains as upper bounds in a priority queue);
//! - [`layout`]: that choice as the selector of a campaign's `d-optimal` layout.
//!
//! Everything here works on the nominal model: it is what a user knows before measuring.

pub mod layout;
pub mod lazy;
pub mod model;
pub mod observability;
pub mod select;

pub use layout::DOptimal;
pub use model::DesignModel;
pub use observability::Indices;
pub use select::{SelectOptions, Selection, d_optimal};
