//! PNG plots: learning curves with their spread, before/after histograms like the paper's Figs. 2–5.
//!
//! Text is drawn with the DejaVu Sans embedded in the binary, so no system font is needed. Every plot is
//! returned as PNG bytes (`plots/<name>.png`, ready for [`crate::output::write_files`]): nothing lands in the
//! results directory until the whole report is ready. Plotters draws into an RGB buffer and the `image`
//! crate (the one plotters itself uses) encodes it, all in memory.

use std::error::Error as StdError;
use std::sync::OnceLock;

use image::ImageEncoder;

use plotters::coord::Shift;
use plotters::coord::cartesian::Cartesian2d;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use crate::calib::registry::MethodKind;
use crate::error::{Error, Result};
use crate::report::aggregate::{Curve, axes, floor_spread, learning_curves};
use crate::report::trajectory::Comparison;
use crate::study::StudyResult;

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

type Drawn = std::result::Result<(), Box<dyn StdError>>;

/// Registers the embedded font once, as plotters' default family.
fn ensure_font() -> Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(Error::Invalid(
            "the embedded font assets/DejaVuSans.ttf does not load".into(),
        ))
    }
}

/// Renders `draw` on a white `size` canvas and returns the PNG bytes.
fn render(
    name: &str,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend, Shift>) -> Drawn,
) -> Result<Vec<u8>> {
    ensure_font()?;
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    let drawn: Drawn = (|| {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE)?;
        draw(&root)?;
        root.present()?;
        Ok(())
    })();
    drawn.map_err(|e| Error::Invalid(format!("plot {name}: {e}")))?;
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&rgb, size.0, size.1, image::ColorType::Rgb8)
        .map_err(|e| Error::Invalid(format!("plot {name}: PNG encoding: {e}")))?;
    Ok(png)
}

/// A name safe as a file name: letters, digits, `-`, `_` and `.` kept, anything else `_`.
pub(super) fn file_safe(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Tableau's ten colours, one per method.
fn colour(i: usize) -> RGBColor {
    const TAB10: [(u8, u8, u8); 10] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ];
    let (r, g, b) = TAB10[i % TAB10.len()];
    RGBColor(r, g, b)
}

/// One PNG per region, `plots/learning_curves_<region>.png`: the median ground-truth mean (mm) against the
/// training-set size on log axes, a line per method with its interquartile band, one panel per layout, the
/// floor dashed.
pub fn learning_curves_png(study: &StudyResult) -> Result<Vec<(String, Vec<u8>)>> {
    let a = axes(study);
    let curves = learning_curves(study);
    let mut out = Vec::new();
    for region in &a.regions {
        let layouts: Vec<_> = a
            .layouts
            .iter()
            .copied()
            .filter(|d| curves.iter().any(|c| &c.region == region && c.layout == *d))
            .collect();
        if layouts.is_empty() {
            continue;
        }
        let cols = layouts.len().min(2);
        let rows = layouts.len().div_ceil(cols);
        let (pw, ph) = (1045u32, 680u32);
        let name = format!("plots/learning_curves_{}.png", file_safe(region));
        let png = render(&name, (pw * cols as u32, ph * rows as u32), |root| {
            let panels = root.split_evenly((rows, cols));
            for (panel, &d) in panels.iter().zip(&layouts) {
                let bands: Vec<(usize, Band)> = a
                    .methods
                    .iter()
                    .enumerate()
                    .filter_map(|(i, m)| {
                        curves
                            .iter()
                            .find(|c| &c.region == region && c.layout == d && &c.method == m)
                            .map(|c| (i, Band::of_truth(c)))
                    })
                    .collect();
                let these: Vec<(usize, &Band)> = bands.iter().map(|(i, b)| (*i, b)).collect();
                let floor: Vec<(f64, f64)> = a
                    .sizes
                    .iter()
                    .filter_map(|&n| {
                        floor_spread(study, region, d, n).map(|s| (n as f64, s.median))
                    })
                    .filter(|p| p.1 > 0.0)
                    .collect();
                learning_panel(
                    panel,
                    &format!("region {region}, {} layout", d.name()),
                    &these,
                    &floor,
                    STUDY_AXES,
                )?;
            }
            Ok(())
        })?;
        out.push((name, png));
    }
    Ok(out)
}

/// A method's line and its band, as a learning-curve panel draws them.
#[derive(Clone, Debug, PartialEq)]
pub struct Band {
    pub method: MethodKind,
    /// Per size: the size, then the band's low end, the line, the band's high end.
    pub points: Vec<[f64; 4]>,
}

impl Band {
    /// A study's curve: the median ground-truth mean with its interquartile band, at the sizes where a run
    /// succeeded.
    fn of_truth(c: &Curve) -> Band {
        let points = c
            .points
            .iter()
            .filter_map(|p| p.truth.map(|s| [p.n_train as f64, s.q1, s.median, s.q3]))
            .collect();
        Band {
            method: c.method,
            points,
        }
    }
}

/// The axis descriptions (x, y) of a study's learning curves.
const STUDY_AXES: (&str, &str) = (
    "training points (log scale)",
    "ground-truth mean error (mm, log scale)",
);

/// `calibrate curve`'s `curve.png`: per method the line and band of `bands` (the mean over draws of the
/// held-out mean error with its min–max) against the subset size, on log axes.
pub fn measured_curve_png(title: &str, bands: &[Band]) -> Result<Vec<u8>> {
    let these: Vec<(usize, &Band)> = bands.iter().enumerate().collect();
    let axes = (
        "points drawn: training + validation (log scale)",
        "held-out mean error (mm, log scale)",
    );
    render("curve.png", (1045, 680), |root| {
        learning_panel(root, title, &these, &[], axes)
    })
}

/// Width of the legend column right of each learning-curve panel (px): outside the plot, so it hides no curve.
const LEGEND_WIDTH: u32 = 275;

/// A hybrid (a method correcting another listed one) is drawn dashed: its curve often lies on its base's.
fn dashed(method: MethodKind) -> bool {
    method.info().base.is_some()
}

/// A line from `a` to `b`, solid or in dashes of 8 px with 6 px gaps.
fn line(points: &[(i32, i32)], style: ShapeStyle, dash: bool) -> Vec<PathElement<(i32, i32)>> {
    if !dash {
        return vec![PathElement::new(points.to_vec(), style)];
    }
    let mut out = Vec::new();
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        let length = (((b.0 - a.0).pow(2) + (b.1 - a.1).pow(2)) as f64).sqrt();
        let mut t = 0.0;
        while t < length {
            let end = (t + 8.0).min(length);
            let at = |s: f64| {
                (
                    a.0 + ((b.0 - a.0) as f64 * s / length).round() as i32,
                    a.1 + ((b.1 - a.1) as f64 * s / length).round() as i32,
                )
            };
            out.push(PathElement::new(vec![at(t), at(end)], style));
            t += 14.0;
        }
    }
    out
}

/// The chart of a learning-curve panel: log axes, ticks at the training-set sizes and at 1, 2, 5 × 10^k mm.
type LogChart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<WithKeyPoints<LogCoord<f64>>, WithKeyPoints<LogCoord<f64>>>,
>;

/// One learning-curve panel: each method's line with its band, the floor dashed, the legend in a column of its
/// own; `descs` describe the axes (x, y).
fn learning_panel(
    whole: &DrawingArea<BitMapBackend, Shift>,
    title: &str,
    curves: &[(usize, &Band)],
    floor: &[(f64, f64)],
    descs: (&str, &str),
) -> Drawn {
    let (width, _) = whole.dim_in_pixel();
    let (panel, legend) = whole.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let Some((xs, ys)) = plotted_values(curves, floor) else {
        whole.titled(&format!("{title}: no successful run"), (FAMILY, 26))?;
        return Ok(());
    };
    let (x0, x1) = min_max(&xs);
    let (y0, y1) = min_max(&ys);
    let mut chart = log_chart(
        &panel,
        title,
        &xs,
        (x0 / 1.25, x1 * 1.25),
        (y0 / 1.3, y1 * 2.5),
        descs,
    )?;
    for &(i, c) in curves {
        draw_curve(&mut chart, c, colour(i))?;
    }
    if !floor.is_empty() {
        let line: Vec<(f64, f64)> = if floor.len() == 1 {
            vec![(x0 / 1.25, floor[0].1), (x1 * 1.25, floor[0].1)]
        } else {
            floor.to_vec()
        };
        chart.draw_series(DashedLineSeries::new(line, 8, 6, BLACK.stroke_width(2)))?;
    }
    // The legend, in its own column: each swatch drawn as its line is (hybrids and the floor dashed).
    let mut entries: Vec<(String, RGBColor, u32, bool)> = curves
        .iter()
        .map(|&(i, c)| (c.method.to_string(), colour(i), 3, dashed(c.method)))
        .collect();
    if !floor.is_empty() {
        entries.push(("floor (oracle)".into(), BLACK, 2, true));
    }
    draw_legend(&legend, entries)
}

/// The sizes (x) and errors (y: bands and lines, the floor) a panel shows, positive ones only; `None` when there
/// is nothing to draw on log axes.
fn plotted_values(curves: &[(usize, &Band)], floor: &[(f64, f64)]) -> Option<(Vec<f64>, Vec<f64>)> {
    let mut xs: Vec<f64> = Vec::new();
    let mut ys: Vec<f64> = floor.iter().map(|p| p.1).collect();
    for (_, c) in curves {
        for p in &c.points {
            xs.push(p[0]);
            ys.extend(&p[1..]);
        }
    }
    xs.extend(floor.iter().map(|p| p.0));
    ys.retain(|y| y.is_finite() && *y > 0.0);
    xs.retain(|x| *x > 0.0);
    (!xs.is_empty() && !ys.is_empty()).then_some((xs, ys))
}

/// The chart on `panel`, its mesh drawn: x over `x_range` with a tick at each of `xs`, y over `y_range`, the
/// axes described by `descs` (x, y).
fn log_chart<'a, 'b>(
    panel: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    title: &str,
    xs: &[f64],
    x_range: (f64, f64),
    (ylo, yhi): (f64, f64),
    (x_desc, y_desc): (&str, &str),
) -> std::result::Result<LogChart<'a, 'b>, Box<dyn StdError>> {
    // Ticks: the training-set sizes on x; 1, 2, 5 × 10^k on y (every digit as a light line).
    let mut sizes: Vec<f64> = xs.to_vec();
    sizes.sort_by(f64::total_cmp);
    sizes.dedup();
    let decades = (ylo.log10().floor() as i32)..=(yhi.log10().ceil() as i32);
    let ticks = |digits: &[f64]| -> Vec<f64> {
        decades
            .clone()
            .flat_map(|k| digits.iter().map(move |d| d * 10f64.powi(k)))
            .filter(|y| (ylo..=yhi).contains(y))
            .collect()
    };
    let bold = ticks(&[1.0, 2.0, 5.0]);
    let light = ticks(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    let mut chart = ChartBuilder::on(panel)
        .caption(title, (FAMILY, 26))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(86)
        .build_cartesian_2d(
            (x_range.0..x_range.1).log_scale().with_key_points(sizes),
            (ylo..yhi)
                .log_scale()
                .with_key_points(bold)
                .with_light_points(light),
        )?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| {
            let decimals = (-y.log10().floor()).max(0.0) as usize;
            format!("{y:.decimals$}")
        })
        .label_style((FAMILY, 17))
        .axis_desc_style((FAMILY, 19))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    Ok(chart)
}

/// One method's curve: its band (a bar when there is a single size), its line (dashed for a hybrid) and a dot
/// at each size.
fn draw_curve(chart: &mut LogChart, c: &Band, col: RGBColor) -> Drawn {
    let band: Vec<(f64, f64, f64, f64)> = c
        .points
        .iter()
        .map(|p| (p[0], p[1], p[2], p[3]))
        .filter(|p| p.1 > 0.0 && p.2 > 0.0 && p.3 > 0.0)
        .collect();
    if band.is_empty() {
        return Ok(());
    }
    if band.len() > 1 {
        let polygon: Vec<(f64, f64)> = band
            .iter()
            .map(|p| (p.0, p.3))
            .chain(band.iter().rev().map(|p| (p.0, p.1)))
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(
            polygon,
            col.mix(0.15).filled(),
        )))?;
    } else {
        let p = band[0];
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(p.0, p.1), (p.0, p.3)],
            col.stroke_width(2),
        )))?;
    }
    let median: Vec<(f64, f64)> = band.iter().map(|p| (p.0, p.2)).collect();
    if dashed(c.method) {
        chart.draw_series(DashedLineSeries::new(median, 10, 6, col.stroke_width(3)))?;
    } else {
        chart.draw_series(LineSeries::new(median, col.stroke_width(3)))?;
    }
    chart.draw_series(
        band.iter()
            .map(|p| Circle::new((p.0, p.2), 4, col.filled())),
    )?;
    Ok(())
}

/// A legend in its own area: per entry (label, colour, line width, dashed) a swatch drawn as its line is.
fn draw_legend(
    legend: &DrawingArea<BitMapBackend, Shift>,
    entries: Vec<(String, RGBColor, u32, bool)>,
) -> Drawn {
    for (k, (label, col, width, dash)) in entries.into_iter().enumerate() {
        let y = 70 + 28 * k as i32;
        for segment in line(&[(8, y), (44, y)], col.stroke_width(width), dash) {
            legend.draw(&segment)?;
        }
        legend.draw(&Text::new(label, (52, y - 10), (FAMILY, 17)))?;
    }
    Ok(())
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
}

/// Number of histogram bins.
const BINS: usize = 40;

/// One PNG per method of the detail run, `plots/histogram_<method>.png`: its test-split position errors (mm)
/// before calibration (nominal) and after, overlaid on the same bins, like the paper's Figs. 2–5.
pub fn histograms_png(study: &StudyResult) -> Result<Vec<(String, Vec<u8>)>> {
    let d = &study.detail;
    let mut out = Vec::new();
    for (method, h) in &d.histograms {
        let before: Vec<f64> = h
            .before
            .iter()
            .filter(|v| v.is_finite())
            .map(|v| v * 1e3)
            .collect();
        let after: Vec<f64> = h
            .after
            .iter()
            .filter(|v| v.is_finite())
            .map(|v| v * 1e3)
            .collect();
        if before.is_empty() && after.is_empty() {
            continue;
        }
        let name = format!("plots/histogram_{}.png", file_safe(method.name()));
        let title = format!(
            "{method}: test-split position error, region {}, {} layout, {} training points",
            d.region,
            d.layout.name(),
            d.n_train
        );
        let png = render(&name, (1200, 720), |root| {
            histogram_panel(root, &title, &before, &after)
        })?;
        out.push((name, png));
    }
    Ok(out)
}

fn counts(values: &[f64], width: f64) -> Vec<usize> {
    let mut c = vec![0; BINS];
    for &v in values {
        let i = ((v.max(0.0) / width) as usize).min(BINS - 1);
        c[i] += 1;
    }
    c
}

fn histogram_panel(
    root: &DrawingArea<BitMapBackend, Shift>,
    title: &str,
    before: &[f64],
    after: &[f64],
) -> Drawn {
    let top = before.iter().chain(after).fold(0.0f64, |m, &v| m.max(v));
    let x1 = if top > 0.0 { top * 1.02 } else { 1e-3 };
    let width = x1 / BINS as f64;
    let (cb, ca) = (counts(before, width), counts(after, width));
    let ymax = cb.iter().chain(&ca).copied().max().unwrap_or(0).max(1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 24))
        .margin(18)
        .x_label_area_size(56)
        .y_label_area_size(76)
        .build_cartesian_2d(0.0..x1, 0.0..ymax as f64 * 1.12)?;
    chart
        .configure_mesh()
        .x_desc("position error (mm)")
        .y_desc("points")
        .y_label_formatter(&|y| format!("{y:.0}"))
        .label_style((FAMILY, 17))
        .axis_desc_style((FAMILY, 19))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let series = [
        (
            format!(
                "before (nominal): n = {}, mean {:.4} mm, max {:.4} mm",
                before.len(),
                mean(before),
                before.iter().fold(0.0f64, |m, &v| m.max(v))
            ),
            &cb,
            RGBColor(214, 39, 40),
        ),
        (
            format!(
                "after: n = {}, mean {:.4} mm, max {:.4} mm",
                after.len(),
                mean(after),
                after.iter().fold(0.0f64, |m, &v| m.max(v))
            ),
            &ca,
            RGBColor(31, 119, 180),
        ),
    ];
    for (label, c, col) in series {
        chart
            .draw_series(
                c.iter()
                    .enumerate()
                    .filter(|(_, k)| **k > 0)
                    .map(|(i, &k)| {
                        Rectangle::new(
                            [(i as f64 * width, 0.0), ((i + 1) as f64 * width, k as f64)],
                            col.mix(0.45).filled(),
                        )
                    }),
            )?
            .label(label)
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 7), (x + 20, y + 7)], col.mix(0.45).filled())
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FAMILY, 18))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()?;
    Ok(())
}

/// Width of the tracker-time plot's legend column (px): the longest label is a hybrid's `+ motion`.
const TRACKER_LEGEND_WIDTH: u32 = 330;

/// A method's colour index, label, whether it is dashed (the motion as inputs) and (tracker minutes, mean mm)
/// points.
type MethodLine = (usize, String, bool, Vec<(f64, f64)>);

/// One PNG per region, `plots/tracker_time_<region>.png` (`[study.trajectory]`): the ground-truth mean (mm)
/// against the tracker time (min, log scale), one panel per number of targets, a line per method through its
/// trajectories at each speed and its stop-and-go campaign (the rightmost point).
pub fn tracker_time_png(study: &StudyResult) -> Result<Vec<(String, Vec<u8>)>> {
    let rows = super::trajectory::comparison(study);
    let mut regions: Vec<&str> = rows.iter().map(|r| r.region.as_str()).collect();
    regions.dedup();
    let mut out = Vec::new();
    for region in regions {
        let mut sizes: Vec<usize> = rows
            .iter()
            .filter(|r| r.region == region)
            .map(|r| r.n_targets)
            .collect();
        sizes.sort_unstable();
        sizes.dedup();
        let name = format!("plots/tracker_time_{}.png", file_safe(region));
        let (pw, ph) = (1200u32, 680u32);
        let png = render(&name, (pw * sizes.len() as u32, ph), |root| {
            for (whole, &n) in root.split_evenly((1, sizes.len())).iter().zip(&sizes) {
                // The legend in a column of its own, right of the plot, so it hides no line.
                let (panel, legend) = whole.split_horizontally(pw - TRACKER_LEGEND_WIDTH);
                let lines = method_lines(study, &rows, region, n);
                tracker_time_panel(&panel, &legend, region, n, &lines)?;
            }
            Ok(())
        })?;
        out.push((name, png));
    }
    Ok(out)
}

/// The lines of one panel of the tracker-time plot: per method of `region` through `n` targets, its
/// (tracker minutes, mean mm) points, stop and go and each speed, by increasing time.
fn method_lines(
    study: &StudyResult,
    rows: &[Comparison],
    region: &str,
    n: usize,
) -> Vec<MethodLine> {
    rows.iter()
        .filter(|r| r.region == region && r.n_targets == n)
        .map(|r| {
            let mut pts: Vec<(f64, f64)> = std::iter::once(r.stop)
                .chain(r.speeds.iter().map(|(_, m)| *m))
                .filter_map(|m| Some((m.tracker_s? / 60.0, m.mean_mm?)))
                .filter(|p| p.0 > 0.0 && p.1.is_finite())
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let i = super::trajectory::method_index(study, r.method);
            (i, r.label(), r.motion_inputs, pts)
        })
        .collect()
}

/// One panel of the tracker-time plot: the mean against the tracker time (log scale), a line per method, its
/// legend in `legend`.
fn tracker_time_panel(
    panel: &DrawingArea<BitMapBackend, Shift>,
    legend: &DrawingArea<BitMapBackend, Shift>,
    region: &str,
    n: usize,
    lines: &[MethodLine],
) -> Drawn {
    let all: Vec<(f64, f64)> = lines.iter().flat_map(|l| l.3.clone()).collect();
    if all.is_empty() {
        panel.titled(&format!("{n} targets: no successful run"), (FAMILY, 26))?;
        return Ok(());
    }
    let mut xs: Vec<f64> = all.iter().map(|p| p.0).collect();
    let (x0, x1) = min_max(&xs);
    xs.sort_by(f64::total_cmp);
    xs.dedup_by(|a, b| (*a - *b).abs() < 0.05 * *b);
    let (_, y1) = min_max(&all.iter().map(|p| p.1).collect::<Vec<_>>());
    let mut chart = ChartBuilder::on(panel)
        .caption(
            format!("region {region}, {n} targets: accuracy against tracker time"),
            (FAMILY, 24),
        )
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(86)
        .build_cartesian_2d(
            (x0 / 1.3..x1 * 1.3).log_scale().with_key_points(xs),
            0.0..y1 * 1.1,
        )?;
    chart
        .configure_mesh()
        .x_desc("tracker time (min, log scale); rightmost point: stop and go")
        .y_desc("ground-truth mean error (mm)")
        .x_label_formatter(&|x| format!("{x:.1}"))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .label_style((FAMILY, 17))
        .axis_desc_style((FAMILY, 19))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let mut entries = Vec::new();
    for (i, label, dash, pts) in lines {
        let c = colour(*i);
        // Fitted with the motion as inputs: dashed, in its method's colour.
        let dash = *dash;
        if dash {
            chart.draw_series(DashedLineSeries::new(pts.clone(), 10, 6, c.stroke_width(2)))?;
        } else {
            chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?;
        }
        chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, c.filled())))?;
        entries.push((label.clone(), c, 2, dash));
    }
    draw_legend(legend, entries)
}
