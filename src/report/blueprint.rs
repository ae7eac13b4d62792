//! The layout the viewer opens the recording on (rerun's *blueprint*), sent from here with the recording so that
//! nobody has to arrange 60 views by hand:
//!
//! - left: a 3-D view of `world/` framed on the first region, seen from the tracker's side (the tracker's beams
//!   left out of its query — add `world/tracker/beams` back in the view's entity list to see them), over a tab of
//!   the summary and the legend;
//! - right: one learning-curve plot per layout (every method a named series; the x axis is the log timeline
//!   [`super::rerun_common::N_TRAIN_LOG_TIMELINE`]), over one histogram view per method, before and after overlaid;
//! - the time panel on that log timeline, where the curves and the robot (at the detail campaign's first point)
//!   both show; the `point` timeline walks the robot through the campaign.
//!
//! The rerun crate's builder ([`rerun::blueprint::Blueprint`]) cannot set a 3-D view's camera, so the blueprint
//! is logged here archetype by archetype, the way that builder does it, into a blueprint store of its own. Ids are
//! derived from the view's place, so the same study gives the same blueprint.

use nalgebra::{Point3, Vector3};
use rerun::external::re_log_types::BlueprintActivationCommand;
use rerun::external::re_sdk_types::blueprint::archetypes::{
    ContainerBlueprint, EyeControls3D, PanelBlueprint, TimePanelBlueprint, ViewBlueprint,
    ViewContents, ViewportBlueprint,
};
use rerun::external::re_sdk_types::blueprint::components::{
    ActiveTab, AutoLayout, AutoViews, ColumnShare, ContainerKind, Eye3DKind, IncludedContent,
    PanelState, PlayState, QueryExpression, RootContainer, RowShare, TimelineName, ViewClass,
};
use rerun::external::re_sdk_types::components::Name;
use rerun::external::re_sdk_types::datatypes;
use rerun::external::uuid::Uuid;
use rerun::{RecordingStream, RecordingStreamBuilder};

use crate::error::Result;
use crate::robot::Chain;
use crate::study::StudyResult;

use super::aggregate::axes;
use super::rerun_common::{N_TRAIN_LOG_TIMELINE, sanitize};

/// A view or container of the layout.
pub enum Part {
    View {
        /// Rerun's view class: `3D`, `TimeSeries`, `BarChart`, `TextDocument`.
        class: &'static str,
        name: String,
        origin: String,
        /// Entity queries (`+ /path/**`, `- /path`).
        contents: Vec<String>,
        /// For a 3-D view: where the camera is and what it looks at (world frame, m).
        eye: Option<(Point3<f64>, Point3<f64>)>,
    },
    Container {
        kind: ContainerKind,
        name: String,
        children: Vec<Part>,
        /// Relative sizes of the children (columns of a horizontal container, rows of a vertical one).
        shares: Vec<f32>,
    },
}

/// A whole layout: its root and the timeline the time panel opens on.
pub struct Layout {
    pub root: Part,
    pub timeline: String,
}

/// A deterministic id for the `k`-th part of the blueprint of `name`.
fn id(name: &str, k: u64) -> Uuid {
    // FNV-1a over the name, then the index: stable across runs and platforms.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in name.bytes() {
        h = (h ^ b as u64).wrapping_mul(0x100_0000_01b3);
    }
    let mut bytes = [0u8; 16];
    bytes[..8].copy_from_slice(&h.to_be_bytes());
    bytes[8..].copy_from_slice(&k.to_be_bytes());
    // Version 8 (custom) and the RFC 4122 variant.
    bytes[6] = (bytes[6] & 0x0f) | 0x80;
    bytes[8] = (bytes[8] & 0x3f) | 0x80;
    Uuid::from_bytes(bytes)
}

struct Writer<'a> {
    stream: &'a RecordingStream,
    name: &'a str,
    next: u64,
}

impl Writer<'_> {
    /// Logs `part` and its children; returns its blueprint path.
    fn log(&mut self, part: &Part) -> rerun::RecordingStreamResult<String> {
        let uuid = id(self.name, self.next);
        self.next += 1;
        match part {
            Part::View {
                class,
                name,
                origin,
                contents,
                eye,
            } => {
                let path = format!("view/{uuid}");
                self.stream.log(
                    format!("{path}/ViewContents"),
                    &ViewContents::new(contents.iter().map(|q| QueryExpression(q.clone().into()))),
                )?;
                self.stream.log(
                    path.as_str(),
                    &ViewBlueprint::new(ViewClass((*class).into()))
                        .with_display_name(Name(name.clone().into()))
                        .with_space_origin(origin.as_str()),
                )?;
                if let Some((position, target)) = eye {
                    let p = |x: &Point3<f64>| [x.x as f32, x.y as f32, x.z as f32];
                    self.stream.log(
                        format!("{path}/EyeControls3D"),
                        &EyeControls3D::new()
                            .with_kind(Eye3DKind::Orbital)
                            .with_position(p(position))
                            .with_look_target(p(target))
                            .with_eye_up([0.0f32, 0.0, 1.0]),
                    )?;
                }
                Ok(path)
            }
            Part::Container {
                kind,
                name,
                children,
                shares,
            } => {
                let paths = children
                    .iter()
                    .map(|c| self.log(c))
                    .collect::<rerun::RecordingStreamResult<Vec<_>>>()?;
                let mut arch = ContainerBlueprint::new(*kind)
                    .with_display_name(Name(name.clone().into()))
                    .with_contents(paths.iter().map(|p| IncludedContent(p.clone().into())));
                match kind {
                    ContainerKind::Horizontal if !shares.is_empty() => {
                        arch = arch.with_col_shares(
                            shares.iter().map(|&s| ColumnShare(datatypes::Float32(s))),
                        );
                    }
                    ContainerKind::Vertical if !shares.is_empty() => {
                        arch = arch.with_row_shares(
                            shares.iter().map(|&s| RowShare(datatypes::Float32(s))),
                        );
                    }
                    ContainerKind::Tabs => {
                        if let Some(first) = paths.first() {
                            arch = arch.with_active_tab(ActiveTab(datatypes::EntityPath::from(
                                first.as_str(),
                            )));
                        }
                    }
                    _ => {}
                }
                let path = format!("container/{uuid}");
                self.stream.log(path.as_str(), &arch)?;
                Ok(path)
            }
        }
    }
}

/// Sends `layout` to `rec` as its blueprint, active and default for the application `app`; `name` (the
/// scenario's) keys the blueprint's ids.
pub fn send(rec: &RecordingStream, app: &'static str, name: &str, layout: &Layout) -> Result<()> {
    use super::rerun_common::rerun_error as err;
    let (stream, storage) = RecordingStreamBuilder::new(app)
        .recording_id(format!("calibench-{name}-blueprint"))
        .enabled(true)
        .blueprint()
        .memory()
        .map_err(err)?;
    // The viewer reads blueprint rows on this timeline.
    stream.set_time_sequence("blueprint", 0);
    let mut w = Writer {
        stream: &stream,
        name,
        next: 0,
    };
    let root = w.log(&layout.root).map_err(err)?;
    let root_id = root
        .strip_prefix("container/")
        .and_then(|u| Uuid::parse_str(u).ok())
        .unwrap_or_else(|| id(name, 0));
    stream
        .log(
            "viewport",
            &ViewportBlueprint::new()
                .with_root_container(RootContainer(datatypes::Uuid {
                    bytes: *root_id.as_bytes(),
                }))
                .with_auto_layout(AutoLayout(datatypes::Bool(false)))
                .with_auto_views(AutoViews(datatypes::Bool(false))),
        )
        .map_err(err)?;
    stream
        .log(
            "time_panel",
            &TimePanelBlueprint::new()
                .with_timeline(TimelineName(layout.timeline.clone().into()))
                .with_play_state(PlayState::Paused),
        )
        .map_err(err)?;
    // The views need the width more than the entity tree and the selection do; both open collapsed.
    for panel in ["blueprint_panel", "selection_panel"] {
        stream
            .log(
                panel,
                &PanelBlueprint::new().with_state(PanelState::Collapsed),
            )
            .map_err(err)?;
    }
    stream.flush_blocking().map_err(err)?;
    let messages = storage.take();
    let Some(blueprint_id) = messages.first().map(|m| m.store_id().clone()) else {
        return Err(err("the blueprint stream is empty"));
    };
    rec.send_blueprint(
        messages,
        BlueprintActivationCommand::make_active(blueprint_id),
    );
    Ok(())
}

/// A camera looking at `target` from `distance` away, from the side of `from` (horizontally) and raised 35°.
pub fn eye_towards(target: Point3<f64>, from: Point3<f64>, distance: f64) -> Point3<f64> {
    let mut d = from - target;
    d.z = 0.0;
    let horizontal = if d.norm() > 1e-9 {
        d.normalize()
    } else {
        Vector3::x()
    };
    let (s, c) = 35f64.to_radians().sin_cos();
    target + distance * (horizontal * c + Vector3::z() * s)
}

/// The layout of a study's recording (see the module documentation).
pub fn study_layout(study: &StudyResult, chain: &Chain) -> Layout {
    let histograms = histogram_views(study);
    let tabs = |name: &str, children: Vec<Part>| Part::Container {
        kind: ContainerKind::Tabs,
        name: name.into(),
        children,
        shares: Vec::new(),
    };
    let left = Part::Container {
        kind: ContainerKind::Vertical,
        name: "world".into(),
        children: vec![world_view(study, chain), documents(study)],
        shares: vec![2.0, 1.0],
    };
    let mut right_children = vec![tabs("learning curves", curve_views(study))];
    if !histograms.is_empty() {
        right_children.push(tabs("histograms", histograms));
    }
    let right = Part::Container {
        kind: ContainerKind::Vertical,
        name: "curves".into(),
        shares: vec![1.0; right_children.len()],
        children: right_children,
    };
    Layout {
        root: Part::Container {
            kind: ContainerKind::Horizontal,
            name: "calibench".into(),
            children: vec![left, right],
            shares: vec![1.2, 1.0],
        },
        timeline: N_TRAIN_LOG_TIMELINE.into(),
    }
}

/// A view without a camera of its own.
fn view(class: &'static str, name: String, origin: &str, contents: Vec<String>) -> Part {
    Part::View {
        class,
        name,
        origin: origin.to_string(),
        contents,
        eye: None,
    }
}

/// The 3-D view of `world/`, without the tracker's beams.
fn world_view(study: &StudyResult, chain: &Chain) -> Part {
    // The camera: on the first region, from the tracker's side, far enough to see the whole box.
    let eye = study.regions.first().map(|r| {
        let centre = chain.base * Point3::from(Vector3::from(r.center_m));
        let diagonal = Vector3::from(r.size_m).norm();
        let tracker = Point3::from(study.detail.tracker.translation.vector);
        (
            eye_towards(centre, tracker, 2.2 * diagonal.max(0.3)),
            centre,
        )
    });
    Part::View {
        class: "3D",
        name: "robot, region, errors (world, m)".into(),
        origin: "/world".into(),
        contents: vec!["+ $origin/**".into(), "- /world/tracker/beams".into()],
        eye,
    }
}

/// The tabs of the text documents: the summary, the legend and, with a trajectory, its legend.
fn documents(study: &StudyResult) -> Part {
    let mut documents = vec![
        view(
            "TextDocument",
            "summary".into(),
            "/summary",
            vec!["+ $origin".into()],
        ),
        view(
            "TextDocument",
            "legend".into(),
            "/legend",
            vec!["+ $origin".into()],
        ),
    ];
    if study.trajectory_detail.is_some() {
        documents.push(view(
            "TextDocument",
            "trajectory".into(),
            "/legend_trajectory",
            vec!["+ $origin".into()],
        ));
    }
    Part::Container {
        kind: ContainerKind::Tabs,
        name: "summary".into(),
        children: documents,
        shares: Vec::new(),
    }
}

/// One learning-curve plot per (region, layout), then the tracker-time comparison if there is one.
fn curve_views(study: &StudyResult) -> Vec<Part> {
    let a = axes(study);
    let mut curves = Vec::new();
    for region in &a.regions {
        for d in &a.layouts {
            let origin = format!("/curves/{}/{}", sanitize(region), d.name());
            let name = if a.regions.len() > 1 {
                format!(
                    "{region}, {}: ground-truth mean (mm) vs 1000·log10(points)",
                    d.name()
                )
            } else {
                format!("{}: ground-truth mean (mm) vs 1000·log10(points)", d.name())
            };
            curves.push(view(
                "TimeSeries",
                name,
                &origin,
                vec!["+ $origin/**".into()],
            ));
        }
    }
    // The tracker-time comparison, plotted over the `tracker_s` timeline (the viewer opens on another: the
    // legend says to select it).
    if !study.trajectory.is_empty() {
        curves.push(view(
            "TimeSeries",
            "tracker time: ground-truth mean (mm) vs tracker seconds (timeline tracker_s)".into(),
            "/tracker_time",
            vec!["+ $origin/**".into()],
        ));
    }
    curves
}

/// One bar chart per method of the detail campaign, before and after overlaid.
fn histogram_views(study: &StudyResult) -> Vec<Part> {
    study
        .detail
        .histograms
        .keys()
        .map(|m| {
            view(
                "BarChart",
                format!("{m}: test error before (red) and after (blue), points per mm bin"),
                &format!("/histograms/{}", sanitize(m.name())),
                vec!["+ $origin/**".into()],
            )
        })
        .collect()
}
