//! CSV logs and PNG figures of a closed-loop run.
//!
//! [`write_csv`] writes the [`Sample`] log as CSV (NaN as an empty cell); [`write_plots`] draws
//! the four figures of the paper's evaluation (position, body rates, thrust, solver time) with
//! plotters' bitmap backend. Text is rendered with an embedded DejaVu Sans Mono font (see
//! `sim/assets/LICENSE-DejaVu.txt`), so no system font or fontconfig is needed.

use std::error::Error as StdError;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, register_font};

use crate::log::Sample;

/// Width of every figure \[px\].
pub const WIDTH: u32 = 1200;
/// Height of every figure \[px\].
pub const HEIGHT: u32 = 900;

/// The embedded font (DejaVu Sans Mono, Bitstream Vera licence).
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");
/// Font family under which the embedded font is registered (plotters' default family).
const FONT: &str = "sans-serif";
/// Advance width of one DejaVu Sans Mono glyph, in em.
const MONO_ADVANCE_EM: f64 = 0.602;
/// Lines and point clouds longer than this are decimated (min/max per bucket) before drawing.
const MAX_LINE_POINTS: usize = 4000;
/// Font size of legend entries \[px\].
const LEGEND_FONT_PX: u32 = 14;
/// Maximum number of labelled ticks on the time and value axes.
const X_TICKS: usize = 12;
const Y_TICKS: usize = 6;
/// Legend margin and sample-line area \[px\] (as passed to plotters).
const LEGEND_MARGIN: i32 = 8;
const LEGEND_SAMPLE: i32 = 30;

/// An error while writing a log or a figure.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// There are no samples to plot.
    #[error("cannot plot {path}: the log has no samples")]
    Empty {
        /// The figure that was to be written.
        path: PathBuf,
    },
    /// The output directory could not be created.
    #[error("cannot create output directory {path}: {source}")]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Writing the CSV file failed.
    #[error("cannot write CSV log {path}: {source}")]
    Csv {
        /// The CSV file.
        path: PathBuf,
        /// The csv crate's error.
        #[source]
        source: csv::Error,
    },
    /// The embedded font could not be registered with plotters.
    #[error("cannot register the embedded plot font (DejaVu Sans Mono)")]
    Font,
    /// Drawing or encoding a figure failed.
    #[error("cannot draw figure {path}: {source}")]
    Draw {
        /// The PNG file.
        path: PathBuf,
        /// The plotters error.
        #[source]
        source: Box<dyn StdError + Send + Sync>,
    },
}

/// Writes `samples` to `path` as CSV.
///
/// The header row holds the [`Sample`] field names in declaration order (also for an empty
/// log); NaN values are written as empty cells. The parent directory is created if missing.
///
/// # Errors
/// [`PlotError::CreateDir`] or [`PlotError::Csv`] if the file cannot be written.
pub fn write_csv(path: &Path, samples: &[Sample]) -> Result<(), PlotError> {
    let csv_err = |source: csv::Error| PlotError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let io_err = |e: std::io::Error| csv_err(csv::Error::from(e));
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| PlotError::CreateDir {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    let mut out = csv::WriterBuilder::new()
        .has_headers(false)
        .from_path(path)
        .map_err(csv_err)?;
    out.write_record(&csv_header().map_err(csv_err)?)
        .map_err(csv_err)?;
    // Serialize in chunks into memory (serde gives "NaN" for NaN floats), then copy each
    // record to the file with the NaN cells emptied. `Sample` has no string fields, so "NaN"
    // can only come from a float.
    let mut record = csv::ByteRecord::new();
    for chunk in samples.chunks(1024) {
        let mut mem = csv::WriterBuilder::new()
            .has_headers(false)
            .from_writer(Vec::new());
        for s in chunk {
            mem.serialize(s).map_err(csv_err)?;
        }
        let bytes = mem.into_inner().map_err(|e| io_err(e.into_error()))?;
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(false)
            .from_reader(bytes.as_slice());
        while rdr.read_byte_record(&mut record).map_err(csv_err)? {
            out.write_record(
                record
                    .iter()
                    .map(|f| if f == b"NaN" { &b""[..] } else { f }),
            )
            .map_err(csv_err)?;
        }
    }
    out.flush().map_err(io_err)
}

/// The CSV header: the serde field names of [`Sample`], in order.
fn csv_header() -> Result<csv::StringRecord, csv::Error> {
    let mut mem = csv::Writer::from_writer(Vec::new());
    mem.serialize(Sample::default())?;
    let bytes = mem
        .into_inner()
        .map_err(|e| csv::Error::from(e.into_error()))?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .from_reader(bytes.as_slice());
    let mut header = csv::StringRecord::new();
    rdr.read_record(&mut header)?;
    Ok(header)
}

/// The four PNG figures written by [`write_plots`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlotSet {
    /// Position x, y, z (true and reference) vs time: `{prefix}position.png`.
    pub position: PathBuf,
    /// Body rates (true, commanded, and the mission's pitch-rate reference): `{prefix}rates.png`.
    pub rates: PathBuf,
    /// Collective thrust (commanded and actual) and rotor thrusts: `{prefix}thrust.png`.
    pub thrust: PathBuf,
    /// Solver time and QP iterations per outer step: `{prefix}solver_time.png`.
    pub solver_time: PathBuf,
}

/// Registers the embedded font as plotters' `sans-serif` family (once per process).
///
/// [`write_plots`] calls this itself; other modules drawing text with plotters may call it
/// before drawing.
///
/// # Errors
/// [`PlotError::Font`] if the embedded font cannot be parsed.
pub fn register_embedded_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, FONT_BYTES).is_ok());
    if ok { Ok(()) } else { Err(PlotError::Font) }
}

/// Draws the four figures of a run into `dir` (created if missing), [`WIDTH`] x [`HEIGHT`] PNG.
///
/// Files are `{prefix}position.png`, `{prefix}rates.png`, `{prefix}thrust.png` and
/// `{prefix}solver_time.png`; `title` heads every figure. Phase changes (where
/// [`Sample::phase`] changes) are marked by dashed vertical lines and alternate shading, and
/// each phase is labelled with `phase_names[phase]` (or `phase N` if the name is missing) when
/// the label fits. NaN values are skipped (lines break at them); an all-NaN series leaves its
/// panel with empty axes.
///
/// # Errors
/// [`PlotError::Empty`] if `samples` is empty; [`PlotError::CreateDir`], [`PlotError::Font`] or
/// [`PlotError::Draw`] if a figure cannot be drawn or written.
pub fn write_plots(
    dir: &Path,
    prefix: &str,
    title: &str,
    samples: &[Sample],
    phase_names: &[&str],
) -> Result<PlotSet, PlotError> {
    let set = PlotSet {
        position: dir.join(format!("{prefix}position.png")),
        rates: dir.join(format!("{prefix}rates.png")),
        thrust: dir.join(format!("{prefix}thrust.png")),
        solver_time: dir.join(format!("{prefix}solver_time.png")),
    };
    if samples.is_empty() {
        return Err(PlotError::Empty { path: set.position });
    }
    std::fs::create_dir_all(dir).map_err(|source| PlotError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })?;
    register_embedded_font()?;
    let phases = PhaseMarks::new(samples, phase_names);

    let figures = [
        (&set.position, "position", position_panels()),
        (&set.rates, "body rates", rate_panels()),
        (&set.thrust, "thrust", thrust_panels()),
        (&set.solver_time, "outer-loop solver", solver_panels()),
    ];
    for (path, what, panels) in figures {
        let caption = if title.is_empty() {
            what.to_string()
        } else {
            format!("{title}: {what}")
        };
        draw_figure(path, &caption, samples, &panels, &phases).map_err(|source| {
            PlotError::Draw {
                path: path.clone(),
                source,
            }
        })?;
    }
    Ok(set)
}

/// How a series is drawn.
#[derive(Clone, Copy)]
enum Style {
    /// Solid line.
    Line,
    /// Dashed line.
    Dashed,
    /// Dots (one per finite sample).
    Points,
}

/// One series of a panel.
struct SeriesSpec {
    label: &'static str,
    color: RGBColor,
    style: Style,
    value: fn(&Sample) -> f64,
}

/// One panel (a chart with its own y axis) of a figure.
struct PanelSpec {
    y_label: &'static str,
    series: Vec<SeriesSpec>,
}

const TRUE_COLOR: RGBColor = RGBColor(0x1f, 0x4e, 0xb4);
const REF_COLOR: RGBColor = RGBColor(0xd6, 0x27, 0x28);
const EXTRA_COLOR: RGBColor = RGBColor(0x2c, 0xa0, 0x2c);
const ROTOR_COLORS: [RGBColor; 4] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x94, 0x67, 0xbd),
];
const SHADE_COLOR: RGBColor = RGBColor(0xee, 0xee, 0xee);
const PHASE_LINE_COLOR: RGBColor = RGBColor(0x70, 0x70, 0x70);

fn series(
    label: &'static str,
    color: RGBColor,
    style: Style,
    value: fn(&Sample) -> f64,
) -> SeriesSpec {
    SeriesSpec {
        label,
        color,
        style,
        value,
    }
}

fn position_panels() -> Vec<PanelSpec> {
    vec![
        PanelSpec {
            y_label: "x [m]",
            series: vec![
                series("x", TRUE_COLOR, Style::Line, |s| s.x),
                series("x ref", REF_COLOR, Style::Dashed, |s| s.x_ref),
            ],
        },
        PanelSpec {
            y_label: "y [m]",
            series: vec![
                series("y", TRUE_COLOR, Style::Line, |s| s.y),
                series("y ref", REF_COLOR, Style::Dashed, |s| s.y_ref),
            ],
        },
        PanelSpec {
            y_label: "z [m]",
            series: vec![
                series("z", TRUE_COLOR, Style::Line, |s| s.z),
                series("z ref", REF_COLOR, Style::Dashed, |s| s.z_ref),
            ],
        },
    ]
}

fn rate_panels() -> Vec<PanelSpec> {
    vec![
        PanelSpec {
            y_label: "roll rate ωx [rad/s]",
            series: vec![
                series("ωx", TRUE_COLOR, Style::Line, |s| s.wx),
                series("ωx cmd", REF_COLOR, Style::Dashed, |s| s.wx_cmd),
            ],
        },
        PanelSpec {
            y_label: "pitch rate ωy [rad/s]",
            series: vec![
                series("ωy", TRUE_COLOR, Style::Line, |s| s.wy),
                series("ωy cmd", REF_COLOR, Style::Dashed, |s| s.wy_cmd),
                series("ωy ref", EXTRA_COLOR, Style::Dashed, |s| s.wy_ref),
            ],
        },
        PanelSpec {
            y_label: "yaw rate ωz [rad/s]",
            series: vec![
                series("ωz", TRUE_COLOR, Style::Line, |s| s.wz),
                series("ωz cmd", REF_COLOR, Style::Dashed, |s| s.wz_cmd),
            ],
        },
    ]
}

fn thrust_panels() -> Vec<PanelSpec> {
    vec![
        PanelSpec {
            y_label: "collective thrust [N]",
            series: vec![
                series("actual", TRUE_COLOR, Style::Line, |s| s.thrust),
                series("commanded", REF_COLOR, Style::Dashed, |s| s.thrust_cmd),
            ],
        },
        PanelSpec {
            y_label: "rotor thrust [N]",
            series: vec![
                series("f1", ROTOR_COLORS[0], Style::Line, |s| s.f1),
                series("f2", ROTOR_COLORS[1], Style::Line, |s| s.f2),
                series("f3", ROTOR_COLORS[2], Style::Line, |s| s.f3),
                series("f4", ROTOR_COLORS[3], Style::Line, |s| s.f4),
            ],
        },
    ]
}

fn solver_panels() -> Vec<PanelSpec> {
    vec![
        PanelSpec {
            y_label: "solver time [µs]",
            series: vec![series("solve time", TRUE_COLOR, Style::Points, |s| {
                s.solver_us
            })],
        },
        PanelSpec {
            y_label: "QP iterations",
            series: vec![series("QP iterations", REF_COLOR, Style::Points, |s| {
                s.qp_iterations
            })],
        },
    ]
}

/// Phase intervals of a log: `(t_start, t_end, label)`, in time order.
struct PhaseMarks {
    intervals: Vec<(f64, f64, String)>,
}

impl PhaseMarks {
    fn new(samples: &[Sample], names: &[&str]) -> Self {
        let mut intervals: Vec<(f64, f64, String)> = Vec::new();
        let mut current: Option<u8> = None;
        for s in samples.iter().filter(|s| s.t.is_finite()) {
            if current != Some(s.phase) {
                if let Some(last) = intervals.last_mut() {
                    last.1 = s.t;
                }
                let label = names
                    .get(usize::from(s.phase))
                    .map_or_else(|| format!("phase {}", s.phase), |n| (*n).to_string());
                intervals.push((s.t, s.t, label));
                current = Some(s.phase);
            }
            if let Some(last) = intervals.last_mut() {
                last.1 = s.t;
            }
        }
        Self { intervals }
    }
}

type DrawResult<T> = Result<T, Box<dyn StdError + Send + Sync>>;

/// Finite (min, max) of an iterator, or `None`.
fn finite_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
}

/// An axis range around `range` with a margin; a default one if there is no data.
fn padded(range: Option<(f64, f64)>, frac: f64) -> (f64, f64) {
    match range {
        None => (-1.0, 1.0),
        Some((lo, hi)) => {
            let span = hi - lo;
            if span > 1e-9 * hi.abs().max(lo.abs()).max(1e-300) {
                (lo - frac * span, hi + frac * span)
            } else {
                let pad = (0.1 * hi.abs()).max(0.5);
                (lo - pad, hi + pad)
            }
        }
    }
}

/// Splits a series into runs of finite points, each decimated to a drawable size.
fn finite_runs(
    samples: &[Sample],
    value: fn(&Sample) -> f64,
    max_points: usize,
) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut run = Vec::new();
    for s in samples {
        let v = value(s);
        if s.t.is_finite() && v.is_finite() {
            run.push((s.t, v));
        } else if !run.is_empty() {
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    let total: usize = runs.iter().map(Vec::len).sum();
    if total > max_points {
        let buckets_per_point = max_points as f64 / 2.0 / total as f64;
        for r in &mut runs {
            let buckets = ((r.len() as f64 * buckets_per_point).ceil() as usize).max(1);
            *r = decimate(r, buckets);
        }
    }
    runs
}

/// Keeps the min and max point (in time order) of each of `buckets` consecutive chunks.
fn decimate(points: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    if points.len() <= 2 * buckets {
        return points.to_vec();
    }
    let chunk = points.len().div_ceil(buckets);
    let mut out = Vec::with_capacity(2 * buckets + 2);
    for c in points.chunks(chunk) {
        let (mut imin, mut imax) = (0, 0);
        for (i, p) in c.iter().enumerate() {
            if p.1 < c[imin].1 {
                imin = i;
            }
            if p.1 > c[imax].1 {
                imax = i;
            }
        }
        let (a, b) = (imin.min(imax), imin.max(imax));
        out.push(c[a]);
        if b != a {
            out.push(c[b]);
        }
    }
    // Keep the run's exact end so that lines reach the last sample.
    if let (Some(last), Some(end)) = (points.last(), out.last())
        && last != end
    {
        out.push(*last);
    }
    out
}

fn draw_figure(
    path: &Path,
    caption: &str,
    samples: &[Sample],
    panels: &[PanelSpec],
    phases: &PhaseMarks,
) -> DrawResult<()> {
    // Drawn into an RGB buffer and encoded with the `png` crate (plotters' own encoder
    // would pull in the whole `image` crate).
    let mut rgb = vec![0u8; WIDTH as usize * HEIGHT as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let body = root.margin(8, 4, 0, 0).titled(caption, (FONT, 26))?;
        let areas = body.split_evenly((panels.len().max(1), 1));
        let (t0, t1) = padded(finite_range(samples.iter().map(|s| s.t)), 0.0);
        for (i, (panel, area)) in panels.iter().zip(&areas).enumerate() {
            draw_panel(
                &root,
                area,
                panel,
                samples,
                (t0, t1),
                phases,
                i == 0,
                i + 1 == panels.len(),
            )?;
        }
        root.present()?;
    }
    encode_png(path, &rgb)
}

#[allow(clippy::too_many_arguments)]
fn draw_panel(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    panel: &PanelSpec,
    samples: &[Sample],
    (t0, t1): (f64, f64),
    phases: &PhaseMarks,
    top: bool,
    bottom: bool,
) -> DrawResult<()> {
    let runs: Vec<_> = panel
        .series
        .iter()
        .map(|s| finite_runs(samples, s.value, MAX_LINE_POINTS))
        .collect();
    let y_data = finite_range(runs.iter().flatten().flatten().map(|p| p.1));
    let (y0, y1) = padded(y_data, 0.06);

    let mut chart = ChartBuilder::on(area)
        .margin_left(10)
        .margin_right(25)
        .margin_top(if top { 26 } else { 6 })
        .margin_bottom(4)
        .x_label_area_size(if bottom { 48 } else { 26 })
        .y_label_area_size(86)
        .build_cartesian_2d(t0..t1, y0..y1)?;

    // Phase shading (every other phase), under the grid and the data.
    for (k, (a, b, _)) in phases.intervals.iter().enumerate() {
        if k % 2 == 1 {
            chart.draw_series(std::iter::once(Rectangle::new(
                [(*a, y0), (*b, y1)],
                SHADE_COLOR.filled(),
            )))?;
        }
    }

    let x_fmt = |v: &f64| tick_label(*v, t1 - t0, X_TICKS);
    let y_fmt = |v: &f64| tick_label(*v, y1 - y0, Y_TICKS);
    let mut mesh = chart.configure_mesh();
    mesh.y_desc(panel.y_label)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(0xf4, 0xf4, 0xf4))
        .bold_line_style(RGBColor(0xdc, 0xdc, 0xdc))
        .max_light_lines(1)
        .x_labels(X_TICKS)
        .y_labels(Y_TICKS)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt);
    if bottom {
        mesh.x_desc("t [s]");
    }
    mesh.draw()?;

    if y_data.is_none() {
        let style = TextStyle::from((FONT, 18).into_font())
            .color(&PHASE_LINE_COLOR)
            .pos(Pos::new(HPos::Center, VPos::Center));
        chart.draw_series(std::iter::once(Text::new(
            "no data",
            (0.5 * (t0 + t1), 0.5 * (y0 + y1)),
            style,
        )))?;
    }

    // Phase change lines, over the grid.
    for (a, _, _) in phases.intervals.iter().skip(1) {
        chart.draw_series(DashedLineSeries::new(
            [(*a, y0), (*a, y1)],
            6,
            4,
            PHASE_LINE_COLOR.stroke_width(1),
        ))?;
    }

    let labelled = draw_series(&mut chart, panel, &runs)?;
    if labelled {
        let corner = legend_corner(&chart, panel, &runs, LEGEND_FONT_PX);
        chart
            .configure_series_labels()
            .position(corner)
            .margin(LEGEND_MARGIN as u32)
            .legend_area_size(LEGEND_SAMPLE as u32)
            .label_font((FONT, LEGEND_FONT_PX))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .draw()?;
    }

    // Phase names, in the top margin of the first panel, where they fit.
    if top {
        draw_phase_names(root, &chart, phases, y1)?;
    }
    Ok(())
}

/// A panel's chart: time against the panel's values.
type PanelChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws each series' finite runs in its style, the first run of each labelled for the
/// legend; whether any series was labelled.
fn draw_series<'a, 'b: 'a>(
    chart: &mut PanelChart<'a, 'b>,
    panel: &PanelSpec,
    runs: &[Vec<Vec<(f64, f64)>>],
) -> DrawResult<bool> {
    let mut labelled = false;
    for (spec, runs) in panel.series.iter().zip(runs) {
        let color = spec.color;
        for (k, run) in runs.iter().enumerate() {
            let pts = distinct_pixels(chart, run);
            let line = color.stroke_width(2);
            let anno = match spec.style {
                // A lone point (a run between NaNs, or a one-sample log) is drawn as a dot.
                _ if pts.len() < 2 => {
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 2, color.filled())))?
                }
                // One element per segment: plotters joins wide polylines with spikes at
                // sharp corners (e.g. the flip's rate steps); separate segments have no joins.
                Style::Line => chart.draw_series(
                    pts.windows(2)
                        .map(move |w| PathElement::new(w.to_vec(), line)),
                )?,
                Style::Dashed => chart.draw_series(DashedLineSeries::new(pts, 8, 5, line))?,
                Style::Points => {
                    chart.draw_series(run.iter().map(|&p| Circle::new(p, 2, color.filled())))?
                }
            };
            if k == 0 {
                labelled = true;
                let style = spec.style;
                anno.label(spec.label).legend(move |(x, y)| match style {
                    Style::Line => {
                        PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2))
                            .into_dyn()
                    }
                    Style::Dashed => DashedPathElement::new(
                        vec![(x, y), (x + 24, y)],
                        6,
                        4,
                        color.stroke_width(2),
                    )
                    .into_dyn(),
                    Style::Points => Circle::new((x + 12, y), 3, color.filled()).into_dyn(),
                });
            }
        }
    }
    Ok(labelled)
}

/// Writes each phase's name above the chart's top edge (at `y1`) where the phase is wide
/// enough for it.
fn draw_phase_names(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    chart: &PanelChart<'_, '_>,
    phases: &PhaseMarks,
    y1: f64,
) -> DrawResult<()> {
    let label_font_px = 15;
    let style = TextStyle::from((FONT, label_font_px).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Bottom));
    for (a, b, name) in &phases.intervals {
        let (xa, ya) = chart.backend_coord(&(*a, y1));
        let (xb, _) = chart.backend_coord(&(*b, y1));
        let width = (name.chars().count() as f64 * MONO_ADVANCE_EM * f64::from(label_font_px))
            .ceil() as i32;
        if xb - xa >= width + 6 {
            root.draw(&Text::new(name.as_str(), (xa + 3, ya - 4), style.clone()))?;
        }
    }
    Ok(())
}

/// A tick label with as many decimals as the axis span needs, and no "-0".
///
/// plotters places at most `ticks` ticks at steps of 1, 2 or 5 times a power of ten, so the
/// step is at least the smallest such number above `span / ticks`, and the decimals of that
/// number resolve every tick.
fn tick_label(v: f64, span: f64, ticks: usize) -> String {
    let min_step = (span.abs() / ticks.max(1) as f64).max(1e-12);
    let decade = 10f64.powf(min_step.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * decade)
        .find(|s| *s >= min_step * (1.0 - 1e-9))
        .unwrap_or(10.0 * decade);
    let decimals = (-(step * (1.0 + 1e-9)).log10().floor()).clamp(0.0, 9.0) as usize;
    let text = format!("{v:.decimals$}");
    match text.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => text,
    }
}

/// The plot corner whose legend box would cover the fewest data points.
fn legend_corner<DB: DrawingBackend>(
    chart: &ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    panel: &PanelSpec,
    runs: &[Vec<Vec<(f64, f64)>>],
    font_px: u32,
) -> SeriesLabelPosition {
    let font = f64::from(font_px);
    let chars = panel
        .series
        .iter()
        .map(|s| s.label.chars().count())
        .max()
        .unwrap_or(0);
    let lines = panel.series.len().max(1);
    let w = (chars as f64 * MONO_ADVANCE_EM * font).ceil() as i32
        + LEGEND_SAMPLE
        + 2 * LEGEND_MARGIN
        + 10;
    let h = ((lines - 1) as f64 * 1.25 * font + font).ceil() as i32 + 2 * LEGEND_MARGIN + 10;
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let boxes = [
        (SeriesLabelPosition::UpperRight, xr.end - w, yr.start),
        (SeriesLabelPosition::UpperLeft, xr.start, yr.start),
        (SeriesLabelPosition::LowerRight, xr.end - w, yr.end - h),
        (SeriesLabelPosition::LowerLeft, xr.start, yr.end - h),
    ];
    let mut best = (SeriesLabelPosition::UpperRight, usize::MAX);
    for (pos, bx, by) in boxes {
        let covered = runs
            .iter()
            .flatten()
            .flatten()
            .filter(|p| {
                let (px, py) = chart.backend_coord(p);
                (bx..bx + w).contains(&px) && (by..by + h).contains(&py)
            })
            .count();
        if covered < best.1 {
            best = (pos, covered);
        }
    }
    best.0
}

/// The points of `run` whose pixel differs from the previous kept point's pixel.
///
/// plotters polygonizes lines wider than one pixel and produces spikes at zero-length
/// segments, so consecutive points on the same pixel are dropped (the last one is kept).
fn distinct_pixels<DB: DrawingBackend>(
    chart: &ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    run: &[(f64, f64)],
) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(run.len());
    let mut last_px = None;
    for p in run {
        let px = chart.backend_coord(p);
        if last_px == Some(px) {
            if let Some(last) = out.last_mut() {
                *last = *p;
            }
        } else {
            out.push(*p);
            last_px = Some(px);
        }
    }
    out
}

/// What [`write_throw_plot`] draws: the side view (x along the throw, z up) of one
/// flip-and-throw trial.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ThrowView {
    /// The probe's path, (horizontal distance along the throw, height) \[m\].
    pub probe: Vec<(f64, f64)>,
    /// The vehicle's path, same axes \[m\].
    pub vehicle: Vec<(f64, f64)>,
    /// Where the probe was released.
    pub release: Option<(f64, f64)>,
    /// Where the probe came down.
    pub landing: Option<f64>,
    /// The target on the ground.
    pub target: f64,
    /// The landing tolerance around the target \[m\] (drawn as a band).
    pub tolerance: f64,
}

/// Draws the side view of a throw (probe and vehicle paths, release point, target with its
/// tolerance band, landing point) into `path` ([`WIDTH`] x [`HEIGHT`] PNG).
///
/// # Errors
/// [`PlotError::Empty`] if the probe path is empty; [`PlotError::CreateDir`],
/// [`PlotError::Font`] or [`PlotError::Draw`] if the figure cannot be drawn or written.
pub fn write_throw_plot(path: &Path, title: &str, view: &ThrowView) -> Result<(), PlotError> {
    if view.probe.is_empty() {
        return Err(PlotError::Empty {
            path: path.to_path_buf(),
        });
    }
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir).map_err(|source| PlotError::CreateDir {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    register_embedded_font()?;
    draw_throw(path, title, view).map_err(|source| PlotError::Draw {
        path: path.to_path_buf(),
        source,
    })
}

fn draw_throw(path: &Path, title: &str, v: &ThrowView) -> DrawResult<()> {
    let mut rgb = vec![0u8; WIDTH as usize * HEIGHT as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let pts = v.probe.iter().chain(&v.vehicle).copied();
        let (x0, x1) = padded(
            finite_range(pts.clone().map(|p| p.0).chain([
                v.target + v.tolerance,
                v.target - v.tolerance,
                0.0,
            ])),
            0.03,
        );
        let (_, z1) = padded(finite_range(pts.map(|p| p.1).chain([0.0])), 0.05);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 26))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, 0.0..z1.max(1.0))?;
        chart
            .configure_mesh()
            .x_desc("distance along the throw [m]")
            .y_desc("height [m]")
            .label_style((FONT, 16))
            .draw()?;
        let band = [
            (v.target - v.tolerance, 0.0),
            (v.target + v.tolerance, 0.06 * z1),
        ];
        chart
            .draw_series(std::iter::once(Rectangle::new(
                band,
                RGBColor(0xf4, 0xc4, 0xc4).filled(),
            )))?
            .label(format!("target ± {:.1} m", v.tolerance))
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], REF_COLOR.filled()));
        chart.draw_series(std::iter::once(Cross::new(
            (v.target, 0.0),
            10,
            REF_COLOR.stroke_width(3),
        )))?;
        chart
            .draw_series(LineSeries::new(
                v.vehicle.iter().copied(),
                TRUE_COLOR.stroke_width(2),
            ))?
            .label("vehicle")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], TRUE_COLOR.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(
                v.probe.iter().copied(),
                EXTRA_COLOR.stroke_width(2),
            ))?
            .label("probe")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], EXTRA_COLOR.stroke_width(2)));
        if let Some(r) = v.release {
            chart
                .draw_series(std::iter::once(Circle::new(r, 6, BLACK.filled())))?
                .label("release")
                .legend(|(x, y)| Circle::new((x + 10, y), 5, BLACK.filled()));
        }
        if let Some(l) = v.landing {
            chart
                .draw_series(std::iter::once(TriangleMarker::new(
                    (l, 0.0),
                    9,
                    EXTRA_COLOR.filled(),
                )))?
                .label(format!("landing ({l:.2} m)"))
                .legend(|(x, y)| TriangleMarker::new((x + 10, y), 6, EXTRA_COLOR.filled()));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 16))
            .draw()?;
        root.present()?;
    }
    encode_png(path, &rgb)
}

/// Encodes a [`WIDTH`] x [`HEIGHT`] RGB buffer as PNG with the `png` crate.
fn encode_png(path: &Path, rgb: &[u8]) -> DrawResult<()> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut enc = png::Encoder::new(file, WIDTH, HEIGHT);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(())
}
