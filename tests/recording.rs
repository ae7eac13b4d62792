//! The rerun recording: decode `campaign.rrd` bytes back in Rust and check the documented entity paths, their
//! archetypes and their row counts.

use std::collections::{BTreeMap, BTreeSet};

use calibench::calib::registry::MethodKind;
use calibench::campaign::LayoutKind;
use calibench::eval::Stats;
use calibench::report::recording::{self, arrow_factor};
use calibench::report::summary::Summary;
use calibench::robot::{Chain, flange_pose, urdf};
use calibench::scenario::Scenario;
use calibench::study::{
    Detail, DetailPoint, GridPoint, Histogram, RunKey, RunMetrics, StudyConfig, StudyResult,
};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rerun::StoreKind;
use rerun::external::re_log_encoding::DecoderApp;
use rerun::external::re_sdk_types::archetypes::RecordingInfo;
use rerun::external::re_sdk_types::blueprint::archetypes::{
    ContainerBlueprint, EyeControls3D, TimePanelBlueprint, ViewBlueprint, ViewContents,
    ViewportBlueprint,
};
use rerun::external::re_sdk_types::blueprint::components::{
    IncludedContent, QueryExpression, RootContainer, TimelineName, ViewClass, ViewOrigin,
};
use rerun::external::re_sdk_types::components::{Name, Position3D};
use rerun::log::{Chunk, LogMsg};

const SIZES: [usize; 3] = [10, 20, 40];
const SEEDS: u64 = 3;
const METHODS: [&str; 2] = ["kinematic", "residual-ridge"];

fn kind(name: &str) -> MethodKind {
    MethodKind::parse(name).unwrap()
}
const LAYOUTS: [LayoutKind; 2] = [LayoutKind::Uniform, LayoutKind::Sobol];
const N_POINTS: usize = 7;
const N_GRID: usize = 12;

fn chain() -> Chain {
    urdf::load_file("robots/iiwa7.urdf", None).expect("iiwa7 URDF")
}

fn stats(mean: f64) -> Stats {
    Stats::of(&[mean * 0.5, mean, mean * 1.5]).expect("finite stats")
}

/// A hand-made study: a few detail points on the iiwa, a small grid, two methods × two layouts × three sizes
/// × three seeds of runs (one of them failed).
fn study(chain: &Chain) -> StudyResult {
    let scenario = Scenario::load("scenarios/paper_iiwa.toml").expect("shipped scenario");
    let regions = scenario.regions.clone();
    let region = regions[0].name.clone();

    let mut runs = Vec::new();
    for layout in LAYOUTS {
        for (m, method) in METHODS.iter().enumerate() {
            for &n_train in &SIZES {
                for seed in 0..SEEDS {
                    let mean = 1e-3 / (n_train as f64).sqrt()
                        * (1.0 + m as f64)
                        * (1.0 + seed as f64 * 0.1);
                    // One failed run: the curve must skip it, not lose the size.
                    let failed = m == 1 && n_train == SIZES[0] && seed == 2;
                    runs.push(RunMetrics {
                        key: RunKey {
                            region: region.clone(),
                            layout,
                            method: kind(method),
                            n_train,
                            seed,
                        },
                        failure: failed.then(|| "did not converge".to_string()),
                        test: (!failed).then(|| stats(mean)),
                        truth: (!failed).then(|| stats(mean)),
                        outside: None,
                        closed_loop: None,
                        floor_mean: None,
                        test_orientation: None,
                        truth_orientation: None,
                        by_distance: Vec::new(),
                        observability: None,
                        fit_ms: 1.0,
                    });
                }
            }
        }
    }

    let q_base = [0.0, 0.5, 0.0, -1.4, 0.0, 0.6, 0.0];
    let points: Vec<DetailPoint> = (0..N_POINTS)
        .map(|k| {
            let t = k as f64 / N_POINTS as f64;
            let q_cmd: Vec<f64> = q_base
                .iter()
                .enumerate()
                .map(|(j, q)| q + 0.3 * (t * 6.0 + j as f64).sin())
                .collect();
            let true_flange = flange_pose(chain, &q_cmd);
            let true_position = Point3::from(true_flange.translation.vector);
            let error_before = Vector3::new(0.8e-3 * t, -0.5e-3, 0.3e-3 * (1.0 - t));
            DetailPoint {
                q_cmd,
                true_flange,
                true_position,
                error_before,
                error_after: error_before * 0.05,
            }
        })
        .collect();
    let grid: Vec<GridPoint> = (0..N_GRID)
        .map(|k| GridPoint {
            true_position: Point3::new(0.6, -0.3 + 0.05 * k as f64, 0.4),
            residual: 1e-5 * (1 + k) as f64,
        })
        .collect();
    let histograms = METHODS
        .iter()
        .map(|m| {
            (
                kind(m),
                Histogram {
                    before: points.iter().map(|p| p.error_before.norm()).collect(),
                    after: points.iter().map(|p| p.error_after.norm()).collect(),
                },
            )
        })
        .collect();
    let tracker = Isometry3::from_parts(
        Translation3::new(2.2, 0.3, 0.9),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::PI),
    );
    let detail = Detail {
        region: region.clone(),
        layout: LayoutKind::Uniform,
        method: kind(METHODS[0]),
        n_train: SIZES[2],
        points,
        grid,
        histograms,
        tracker,
    };

    let config = StudyConfig {
        sizes: SIZES.to_vec(),
        layouts: LAYOUTS.to_vec(),
        methods: METHODS.iter().map(|m| kind(m)).collect(),
        seeds: SEEDS,
        validation_ratio: 0.5,
        test_points: 10,
        grid_points: N_GRID,
        shell_width_m: 0.05,
        shell_points: 10,
        closed_loop_points: 5,
        detail_method: None,
        distance_bands_m: vec![0.025, 0.05],
        targets_mm: vec![0.3, 0.1, 0.05, 0.02],
        move_s: 3.0,
        settle_s: 2.0,
        measure_s: 1.0,
        trajectory: None,
    };
    StudyResult {
        world: scenario.world.clone(),
        config,
        regions,
        runs,
        detail,
        orientation: false,
        limits: Vec::new(),
        trajectory: Vec::new(),
        trajectory_detail: None,
    }
}

/// What one entity holds across the whole recording.
#[derive(Default, Debug)]
pub(crate) struct Entity {
    /// Component identifiers, e.g. `Points3D:positions`.
    components: BTreeSet<String>,
    static_rows: usize,
    /// Rows per timeline name.
    pub(crate) timeline_rows: BTreeMap<String, usize>,
    /// Distinct times per timeline.
    pub(crate) times: BTreeMap<String, BTreeSet<i64>>,
}

pub(crate) fn decode(bytes: &[u8]) -> BTreeMap<String, Entity> {
    let mut entities: BTreeMap<String, Entity> = BTreeMap::new();
    let decoder = DecoderApp::decode_eager(bytes).expect("an .rrd stream");
    for msg in decoder {
        let msg = msg.expect("a decodable message");
        let LogMsg::ArrowMsg(store, arrow) = msg else {
            continue;
        };
        if store.kind() == StoreKind::Blueprint {
            continue;
        }
        let chunk = Chunk::from_arrow_msg(&arrow).expect("a chunk");
        // Rerun prints paths with a leading `/`; the documented scheme has none (the root stays `/`).
        let path = chunk.entity_path().to_string();
        let path = match path.trim_start_matches('/') {
            "" => "/".to_string(),
            p => p.to_string(),
        };
        let entity = entities.entry(path).or_default();
        entity.components.extend(
            chunk
                .components()
                .component_descriptors()
                .map(|d| d.component.to_string()),
        );
        if chunk.is_static() {
            entity.static_rows += chunk.num_rows();
        }
        for (name, column) in chunk.timelines() {
            *entity.timeline_rows.entry(name.to_string()).or_default() += chunk.num_rows();
            entity
                .times
                .entry(name.to_string())
                .or_default()
                .extend(column.times_raw().iter().copied());
        }
    }
    entities
}

fn entity<'a>(entities: &'a BTreeMap<String, Entity>, path: &str) -> &'a Entity {
    entities.get(path).unwrap_or_else(|| {
        panic!(
            "no entity {path}; the recording has {:?}",
            entities.keys().collect::<Vec<_>>()
        )
    })
}

fn assert_has(entity: &Entity, path: &str, components: &[&str]) {
    for c in components {
        assert!(
            entity.components.contains(*c),
            "{path} lacks {c}; it has {:?}",
            entity.components
        );
    }
}

#[test]
fn recording_holds_the_documented_entities() {
    let chain = chain();
    let study = study(&chain);
    let bytes = recording::record(&study, &chain, &Summary::of(&study).expect("summary"))
        .expect("recording");
    assert!(bytes.len() > 1000, "recording of {} bytes", bytes.len());
    eprintln!("recording: {} bytes", bytes.len());
    if let Ok(path) = std::env::var("CALIBENCH_RRD_OUT") {
        std::fs::write(&path, &bytes).expect("write the recording");
    }
    let entities = decode(&bytes);

    // Z up at the root.
    assert_has(entity(&entities, "/"), "/", &["ViewCoordinates:xyz"]);

    // The robot: one transform per body per detail point on the `point` timeline, shapes static.
    let mut shapes = 0;
    for (i, body) in chain.bodies.iter().enumerate() {
        let path = format!("world/robot/link_{i}");
        let link = entity(&entities, &path);
        assert_has(
            link,
            &path,
            &["Transform3D:translation", "Transform3D:quaternion"],
        );
        assert_eq!(link.timeline_rows.get("point"), Some(&N_POINTS), "{path}");
        assert_eq!(link.times["point"].len(), N_POINTS, "{path}");
        assert!(
            !link.timeline_rows.contains_key("log_time"),
            "log_time must be off"
        );
        for collider in &body.colliders {
            let (child, component) = match collider.shape {
                calibench::robot::Shape::Cylinder { .. } => ("cylinders", "Cylinders3D:lengths"),
                calibench::robot::Shape::Capsule { .. } => ("capsules", "Capsules3D:lengths"),
                calibench::robot::Shape::Sphere { .. } => ("spheres", "Ellipsoids3D:half_sizes"),
                calibench::robot::Shape::Cuboid { .. } => ("boxes", "Boxes3D:half_sizes"),
            };
            let path = format!("world/robot/link_{i}/{child}");
            let shape = entity(&entities, &path);
            assert_has(shape, &path, &[component]);
            assert_eq!(shape.static_rows, 1, "{path}");
        }
        shapes += body.colliders.len();
    }
    assert!(shapes > 0, "the iiwa has collision shapes");
    let skeleton = entity(&entities, "world/robot/skeleton");
    assert_has(skeleton, "world/robot/skeleton", &["LineStrips3D:strips"]);
    assert_eq!(skeleton.timeline_rows.get("point"), Some(&N_POINTS));
    let flange = entity(&entities, "world/robot/flange");
    assert_has(
        flange,
        "world/robot/flange",
        &["Transform3D:translation", "TransformAxes3D:axis_length"],
    );
    assert_eq!(flange.timeline_rows.get("point"), Some(&N_POINTS));

    // Regions.
    for region in &study.regions {
        let path = format!("world/regions/{}", recording::sanitize(&region.name));
        let e = entity(&entities, &path);
        assert_has(e, &path, &["Boxes3D:half_sizes", "Boxes3D:centers"]);
        assert_eq!(e.static_rows, 1, "{path}");
    }

    // Tracker and beams.
    let tracker = entity(&entities, "world/tracker");
    assert_has(
        tracker,
        "world/tracker",
        &[
            "Transform3D:translation",
            "TransformAxes3D:axis_length",
            "Ellipsoids3D:half_sizes",
        ],
    );
    assert_has(
        entity(&entities, "world/tracker/beams"),
        "world/tracker/beams",
        &["LineStrips3D:strips"],
    );
    assert_eq!(
        entity(&entities, "world/tracker/beam")
            .timeline_rows
            .get("point"),
        Some(&N_POINTS)
    );

    // Points, arrows, grid: static, one row each (instance counts checked in the library's own terms).
    let factor = arrow_factor(&study.detail.points);
    assert!(factor > 1, "sub-millimetre errors are magnified");
    let method = &study.detail.method;
    for (path, components) in [
        (
            "world/points/before".to_string(),
            &["Points3D:positions", "Points3D:colors"][..],
        ),
        (
            format!("world/arrows/before_x{factor}"),
            &["Arrows3D:vectors", "Arrows3D:origins", "Arrows3D:colors"][..],
        ),
        (
            format!(
                "world/arrows/after_x{}_{method}",
                recording::arrow_factor_after(&study.detail.points)
            ),
            &["Arrows3D:vectors", "Arrows3D:origins", "Arrows3D:colors"][..],
        ),
        (
            format!("world/grid/{method}"),
            &["Points3D:positions", "Points3D:colors"][..],
        ),
    ] {
        let e = entity(&entities, &path);
        assert_has(e, &path, components);
        assert_eq!(e.static_rows, 1, "{path}");
        assert!(e.timeline_rows.is_empty(), "{path} is static");
    }

    // Histograms: one entity per method and side.
    let histogram_methods: BTreeSet<&str> = entities
        .keys()
        .filter_map(|k| k.strip_prefix("histograms/"))
        .filter_map(|k| k.split('/').next())
        .collect();
    assert_eq!(histogram_methods, METHODS.iter().copied().collect());
    for m in METHODS {
        for side in ["before", "after"] {
            let path = format!("histograms/{m}/{side}");
            let e = entity(&entities, &path);
            assert_has(e, &path, &["BarChart:values", "BarChart:abscissa"]);
            assert_eq!(e.static_rows, 1, "{path}");
        }
    }

    // Learning curves: one series per region × layout × method, one row per size, a named series.
    let region = recording::sanitize(&study.regions[0].name);
    let curve_paths: BTreeSet<&String> = entities
        .keys()
        .filter(|k| k.starts_with("curves/"))
        .collect();
    assert_eq!(curve_paths.len(), LAYOUTS.len() * METHODS.len());
    for layout in LAYOUTS {
        for m in METHODS {
            let path = format!("curves/{region}/{}/{m}", layout.name());
            let e = entity(&entities, &path);
            assert_has(e, &path, &["Scalars:scalars", "SeriesLines:names"]);
            assert_eq!(e.timeline_rows.get("n_train"), Some(&SIZES.len()), "{path}");
            assert_eq!(
                e.times["n_train"],
                SIZES.iter().map(|&n| n as i64).collect::<BTreeSet<_>>(),
                "{path}"
            );
            assert!(
                !e.timeline_rows.contains_key("point"),
                "{path} must not carry the point timeline"
            );
        }
    }
    let curves = recording::learning_curves(&study);
    // The log timeline of the curves, where the viewer opens: 1000 · log10(n).
    for layout in LAYOUTS {
        let e = entity(
            &entities,
            &format!("curves/{region}/{}/{}", layout.name(), METHODS[0]),
        );
        assert_eq!(
            e.times["n_train_log"],
            SIZES
                .iter()
                .map(|&n| recording::log_time(n))
                .collect::<BTreeSet<_>>()
        );
    }
    assert_eq!(recording::log_time(1000), 3000);
    assert_eq!(recording::log_time(15), 1176);
    // The robot is drawn on the curves' timelines too (its first pose), not only along `point`.
    let link = entity(&entities, "world/robot/link_3");
    assert_eq!(link.timeline_rows.get("n_train_log"), Some(&1));
    assert_eq!(link.timeline_rows.get("n_train"), Some(&1));
    let failed_size = &curves[&(
        region.clone(),
        "uniform".to_string(),
        "residual-ridge".to_string(),
    )];
    assert_eq!(failed_size.len(), SIZES.len());

    // Documents.
    for path in ["summary", "legend"] {
        let e = entity(&entities, path);
        assert_has(e, path, &["TextDocument:text", "TextDocument:media_type"]);
        assert_eq!(e.static_rows, 1, "{path}");
    }
}

#[test]
fn arrow_factor_is_a_1_2_5_number_under_the_target() {
    let point = |e: f64| DetailPoint {
        q_cmd: vec![0.0; 7],
        true_flange: Isometry3::identity(),
        true_position: Point3::origin(),
        error_before: Vector3::new(e, 0.0, 0.0),
        error_after: Vector3::zeros(),
    };
    assert_eq!(arrow_factor(&[point(1e-3)]), 100);
    assert_eq!(arrow_factor(&[point(3e-3)]), 20);
    assert_eq!(arrow_factor(&[point(0.4e-3), point(-0.9e-3)]), 100);
    assert_eq!(arrow_factor(&[point(0.3)]), 1);
    assert_eq!(arrow_factor(&[]), 1);
}

/// The chunks of the recording's data and of its blueprint, and whether a blueprint activation was sent.
fn stores(bytes: &[u8]) -> (Vec<Chunk>, Vec<Chunk>, bool) {
    let (mut data, mut blueprint, mut activated) = (Vec::new(), Vec::new(), false);
    for msg in DecoderApp::decode_eager(bytes).expect("an .rrd stream") {
        match msg.expect("a decodable message") {
            LogMsg::ArrowMsg(store, arrow) => {
                let chunk = Chunk::from_arrow_msg(&arrow).expect("a chunk");
                if store.kind() == StoreKind::Blueprint {
                    blueprint.push(chunk);
                } else {
                    data.push(chunk);
                }
            }
            LogMsg::BlueprintActivationCommand(cmd) => activated |= cmd.make_active,
            LogMsg::SetStoreInfo(_) => {}
        }
    }
    (data, blueprint, activated)
}

/// The strings of one component over the chunks at `path` (blueprint paths have no leading `/`).
fn texts<C>(chunks: &[Chunk], path: &str, descriptor: rerun::ComponentDescriptor) -> Vec<String>
where
    C: rerun::Component + std::ops::Deref<Target = rerun::external::re_sdk_types::datatypes::Utf8>,
{
    chunks
        .iter()
        .filter(|c| c.entity_path().to_string().trim_start_matches('/') == path)
        .flat_map(|c| {
            c.iter_component::<C>(descriptor.component)
                .flat_map(|batch| {
                    batch
                        .iter()
                        .map(|v| v.as_str().to_string())
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn recording_opens_on_a_designed_blueprint_and_is_named_after_the_scenario() {
    let chain = chain();
    let study = study(&chain);
    let summary = Summary::of(&study).expect("summary");
    let bytes = recording::record(&study, &chain, &summary).expect("recording");
    let (data, blueprint, activated) = stores(&bytes);
    assert!(activated, "the blueprint is made active");

    // The summary document is the study's summary.md, word for word.
    let shown =
        texts::<rerun::components::Text>(&data, "summary", rerun::TextDocument::descriptor_text());
    assert_eq!(shown, [summary.markdown()]);

    // The recording's name.
    let names: Vec<String> = data
        .iter()
        .flat_map(|c| {
            c.iter_component::<Name>(RecordingInfo::descriptor_name().component)
                .flat_map(|b| b.iter().map(|n| n.as_str().to_string()).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(names, ["calibench study 'paper_iiwa'"]);

    // Every view: its class, name, origin and entity queries.
    let view_paths: BTreeSet<String> = blueprint
        .iter()
        .map(|c| {
            c.entity_path()
                .to_string()
                .trim_start_matches('/')
                .to_string()
        })
        .filter(|p| p.starts_with("view/") && p.matches('/').count() == 1)
        .collect();
    let mut views = Vec::new();
    for path in &view_paths {
        let class = texts::<ViewClass>(
            &blueprint,
            path,
            ViewBlueprint::descriptor_class_identifier(),
        );
        let name = texts::<Name>(&blueprint, path, ViewBlueprint::descriptor_display_name());
        let origin: Vec<String> = blueprint
            .iter()
            .filter(|c| c.entity_path().to_string().trim_start_matches('/') == path.as_str())
            .flat_map(|c| {
                c.iter_component::<ViewOrigin>(ViewBlueprint::descriptor_space_origin().component)
                    .flat_map(|b| b.iter().map(|o| o.0.to_string()).collect::<Vec<_>>())
                    .collect::<Vec<_>>()
            })
            .collect();
        let queries = texts::<QueryExpression>(
            &blueprint,
            &format!("{path}/ViewContents"),
            ViewContents::descriptor_query(),
        );
        assert_eq!((class.len(), name.len(), origin.len()), (1, 1, 1), "{path}");
        views.push((
            path.clone(),
            class[0].clone(),
            name[0].clone(),
            origin[0].clone(),
            queries,
        ));
    }
    let of_class = |k: &str| views.iter().filter(|v| v.1 == k).collect::<Vec<_>>();

    // One 3-D view of the world, the tracker's beams out of its query, framed on the region.
    let spatial = of_class("3D");
    assert_eq!(spatial.len(), 1);
    let (path, _, _, origin, queries) = spatial[0];
    assert_eq!(origin, "/world");
    assert!(queries.contains(&"+ $origin/**".to_string()), "{queries:?}");
    assert!(
        queries.contains(&"- /world/tracker/beams".to_string()),
        "{queries:?}"
    );
    let targets: Vec<[f32; 3]> = blueprint
        .iter()
        .filter(|c| {
            c.entity_path().to_string().trim_start_matches('/') == format!("{path}/EyeControls3D")
        })
        .flat_map(|c| {
            c.iter_component::<Position3D>(EyeControls3D::descriptor_look_target().component)
                .flat_map(|b| b.iter().map(|p| p.0.0).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .collect();
    let region = &study.regions[0];
    let centre = chain.base * Point3::from(Vector3::from(region.center_m));
    assert_eq!(targets.len(), 1, "one camera");
    for (k, v) in targets[0].iter().enumerate() {
        assert!(
            (*v as f64 - centre[k]).abs() < 1e-5,
            "{targets:?} vs {centre}"
        );
    }

    // One learning-curve plot per layout, each showing every method of that layout.
    let series = of_class("TimeSeries");
    assert_eq!(series.len(), LAYOUTS.len());
    for d in LAYOUTS {
        let v = series
            .iter()
            .find(|v| v.3 == format!("/curves/paper/{}", d.name()))
            .unwrap_or_else(|| panic!("no curve view for {}: {series:?}", d.name()));
        assert!(v.2.contains("(mm)") && v.2.contains("log10"), "{}", v.2);
        assert_eq!(v.4, ["+ $origin/**"]);
    }
    // One histogram view per method (before and after under its origin), the summary and the legend.
    let bars = of_class("BarChart");
    assert_eq!(
        bars.iter().map(|v| v.3.as_str()).collect::<BTreeSet<_>>(),
        METHODS
            .iter()
            .map(|m| format!("/histograms/{m}"))
            .collect::<BTreeSet<_>>()
            .iter()
            .map(String::as_str)
            .collect()
    );
    let documents: BTreeSet<&str> = of_class("TextDocument")
        .iter()
        .map(|v| v.3.as_str())
        .collect();
    assert_eq!(documents, ["/legend", "/summary"].into_iter().collect());
    assert_eq!(views.len(), 1 + LAYOUTS.len() + METHODS.len() + 2);

    // Every view sits in a container under the viewport's root, and the time panel opens on the log timeline.
    let contained: BTreeSet<String> = blueprint
        .iter()
        .filter(|c| {
            c.entity_path()
                .to_string()
                .trim_start_matches('/')
                .starts_with("container/")
        })
        .flat_map(|c| {
            c.iter_component::<IncludedContent>(ContainerBlueprint::descriptor_contents().component)
                .flat_map(|b| b.iter().map(|i| i.0.to_string()).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .map(|p| p.trim_start_matches('/').to_string())
        .collect();
    for (path, ..) in &views {
        assert!(
            contained.contains(path),
            "{path} is in no container: {contained:?}"
        );
    }
    let roots: Vec<_> = blueprint
        .iter()
        .filter(|c| c.entity_path().to_string().trim_start_matches('/') == "viewport")
        .flat_map(|c| {
            c.iter_component::<RootContainer>(
                ViewportBlueprint::descriptor_root_container().component,
            )
            .flat_map(|b| b.to_vec())
            .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(roots.len(), 1);
    assert_eq!(
        texts::<TimelineName>(
            &blueprint,
            "time_panel",
            TimePanelBlueprint::descriptor_timeline()
        ),
        ["n_train_log"]
    );
}

/// Issue 16: with `[study.trajectory]` the recording holds the detail trajectory (a static path, its samples,
/// the current sample on the `time` timeline) and the tracker-time comparison on the `tracker_s` timeline: per
/// method and size, stop and go (points × (move + settle + measure)) and each speed at its tracker time.
#[test]
fn recording_shows_the_trajectory_and_the_tracker_time_comparison() {
    use calibench::study::trajectory::{
        TrajectoryDetail, TrajectoryRun, TrajectorySample, TrajectoryStudy,
    };
    let chain = chain();
    let mut study = study(&chain);
    let region = study.regions[0].name.clone();
    let n = SIZES[2];
    let speeds = [0.5, 1.0];
    study.config.trajectory = Some(TrajectoryStudy {
        speeds: speeds.to_vec(),
        sizes: vec![n],
        seeds: 2,
        acceleration_rad_s2: 5.0,
        sample_rate_hz: 1000.0,
        keep_every: 100,
        clock_offset_s: 0.003,
        jitter_s: 5e-6,
        clock_bound_s: 0.05,
        motion_inputs: false,
    });
    // Tracker time: 60 s at half speed, 40 s at full; stop and go is the study's own cost per point.
    for method in METHODS {
        for seed in 0..2 {
            for (k, speed) in speeds.iter().enumerate() {
                study.trajectory.push(TrajectoryRun {
                    region: region.clone(),
                    method: kind(method),
                    motion_inputs: false,
                    speed: *speed,
                    n_targets: n,
                    seed,
                    samples: 500,
                    tracker_s: [60.0, 40.0][k],
                    clock_error_s: 1e-5,
                    dynamic_max_m: 1e-4,
                    truth: Some(stats(1e-3)),
                    failure: None,
                });
            }
        }
    }
    let samples: Vec<TrajectorySample> = (0..25)
        .map(|k| TrajectorySample {
            t: k as f64 * 0.1,
            true_position: Point3::new(0.6, -0.3 + 0.02 * k as f64, 0.4),
            error_after: 1e-5 * k as f64,
            dynamic: 1e-6 * k as f64,
        })
        .collect();
    study.trajectory_detail = Some(TrajectoryDetail {
        region: region.clone(),
        method: kind(METHODS[0]),
        speed: 1.0,
        n_targets: n,
        samples,
    });
    let bytes = recording::record(&study, &chain, &Summary::of(&study).expect("summary"))
        .expect("recording");
    let entities = decode(&bytes);

    let path = entity(&entities, "world/trajectory/path");
    assert_has(path, "world/trajectory/path", &["LineStrips3D:strips"]);
    assert_eq!(path.static_rows, 1);
    let all = entity(&entities, "world/trajectory/samples");
    assert_has(
        all,
        "world/trajectory/samples",
        &["Points3D:positions", "Points3D:colors"],
    );
    let current = entity(&entities, "world/trajectory/current");
    assert_eq!(current.timeline_rows.get("time"), Some(&25));
    // Duration timelines are stored in nanoseconds.
    assert!(
        current.times["time"].contains(&2_400_000_000),
        "{:?}",
        current.times["time"]
    );
    assert_eq!(entity(&entities, "legend_trajectory").static_rows, 1);

    let stop_s = (study.config.campaign_points(n) as f64
        * (study.config.move_s + study.config.settle_s + study.config.measure_s))
        .round() as i64;
    for method in METHODS {
        let p = format!("tracker_time/{region}/{n}/{method}");
        let e = entity(&entities, &p);
        assert_has(e, &p, &["Scalars:scalars", "SeriesLines:names"]);
        assert_eq!(
            e.times["tracker_s"],
            BTreeSet::from([40, 60, stop_s]),
            "{p}"
        );
    }
}
