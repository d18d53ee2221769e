//! PNG plots of an identification (plotters, pure-Rust bitmap backend with an embedded DejaVu
//! font, so no system font library is needed):
//! * `response_<file>.png`: measured vs free-run simulated v and ω against time;
//! * `regression.png`: the regression of Fig. 4.15 as partial-residual plots — for channel c
//!   and regressor j, y − Σ_{i≠j} θ_i x_i against x_j, with the fitted line of slope θ_j.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::diagnose::Diagnosis;
use crate::identify::Identification;
use wheelid_robots::TrackResult;

const MAX_POINTS: usize = 4000;

fn register_font() {
    use std::sync::Once;
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // Only fails for a malformed font, and DejaVu is well formed.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

fn range(xs: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad, hi + pad)
}

fn stem(p: &Path, i: usize) -> String {
    let s = p
        .file_stem()
        .map_or_else(|| format!("{i}"), |s| s.to_string_lossy().into_owned());
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// One line of a time-series panel: values, colour, width, legend name.
type Line<'a> = (&'a [f64], RGBColor, u32, &'a str);

/// Draws a panel of `lines` against `t` with a legend; samples where `shade` is true are
/// drawn on a grey band (validation blocks).
fn time_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    caption: &str,
    y_desc: &str,
    t: &[f64],
    lines: &[Line<'_>],
    shade: Option<&[bool]>,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let step = (t.len() / MAX_POINTS).max(1);
    let (y0, y1) = range(lines.iter().flat_map(|l| l.0.iter().copied()));
    let (t0, t1) = (t[0], t[t.len() - 1]);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("t [s]")
        .y_desc(y_desc)
        .draw()?;
    if let Some(flags) = shade {
        let mut k = 0;
        while k < t.len() {
            if flags[k] {
                let start = k;
                while k < t.len() && flags[k] {
                    k += 1;
                }
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(t[start], y0), (t[k - 1], y1)],
                    RGBColor(230, 230, 230).filled(),
                )))?;
            }
            k += 1;
        }
    }
    for &(y, color, width, name) in lines {
        chart
            .draw_series(LineSeries::new(
                t.iter().zip(y).step_by(step).map(|(a, b)| (*a, *b)),
                color.stroke_width(width),
            ))?
            .label(name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Writes the plots into `dir` (created if needed); returns the files written.
///
/// # Errors
/// If the directory cannot be created or a PNG cannot be written.
pub fn write_plots(id: &Identification, dir: &Path) -> Result<Vec<PathBuf>> {
    register_font();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut out = Vec::new();
    let labels = [("v [m/s]", "v"), ("ω [rad/s]", "ω")];
    for (i, s) in id.series.iter().enumerate() {
        let path = dir.join(format!("response_{}.png", stem(&s.source, i)));
        {
            let root = BitMapBackend::new(&path, (1200, 800)).into_drawing_area();
            root.fill(&WHITE)?;
            let panels = root.split_evenly((2, 1));
            for (ch, area) in panels.iter().enumerate() {
                let fit = id.files[i].fit_percent[ch];
                time_panel(
                    area,
                    &format!(
                        "{} — {}: measured vs free-run simulation (fit {fit:.1} %)",
                        s.source.display(),
                        labels[ch].1
                    ),
                    labels[ch].0,
                    &s.t,
                    &[
                        (&s.measured[ch], BLUE, 1, "measured"),
                        (&s.simulated[ch], RED, 2, "simulated"),
                    ],
                    None,
                )?;
            }
            root.present()?;
        }
        out.push(path);
    }
    let path = dir.join("regression.png");
    {
        let root = BitMapBackend::new(&path, (1500, 900)).into_drawing_area();
        root.fill(&WHITE)?;
        let xnames = [
            ["v̇ [m/s²]", "−ω² [rad²/s²]", "v [m/s]"],
            ["ω̇ [rad/s²]", "v·ω [m·rad/s²]", "ω [rad/s]"],
        ];
        let ynames = ["v_ref partial residual", "ω_ref partial residual"];
        let cells = root.split_evenly((2, 3));
        for (ch, reg) in id.regressions.iter().enumerate().take(2) {
            let n = reg.y.len();
            let step = (n / MAX_POINTS).max(1);
            let th: Vec<f64> = reg.params.iter().map(|&i| id.theta[i]).collect();
            for j in 0..reg.x.ncols() {
                let pts: Vec<(f64, f64)> = (0..n)
                    .step_by(step)
                    .map(|r| {
                        let others: f64 = (0..reg.x.ncols())
                            .filter(|&i| i != j)
                            .map(|i| reg.x[(r, i)] * th[i])
                            .sum();
                        (reg.x[(r, j)], reg.y[r] - others)
                    })
                    .collect();
                let (x0, x1) = range(pts.iter().map(|p| p.0));
                let (y0, y1) = range(pts.iter().map(|p| p.1).chain([x0 * th[j], x1 * th[j]]));
                let mut chart = ChartBuilder::on(&cells[ch * 3 + j])
                    .caption(
                        format!("{} = {:.4}", id.param_names[reg.params[j]], th[j]),
                        ("sans-serif", 18),
                    )
                    .margin(8)
                    .x_label_area_size(35)
                    .y_label_area_size(55)
                    .build_cartesian_2d(x0..x1, y0..y1)?;
                chart
                    .configure_mesh()
                    .x_desc(xnames[ch][j])
                    .y_desc(ynames[ch])
                    .draw()?;
                chart.draw_series(
                    pts.iter()
                        .map(|p| Circle::new(*p, 1, BLUE.mix(0.4).filled())),
                )?;
                chart.draw_series(LineSeries::new(
                    [(x0, x0 * th[j]), (x1, x1 * th[j])],
                    RED.stroke_width(2),
                ))?;
            }
        }
        root.present()?;
    }
    out.push(path);
    Ok(out)
}

/// Writes the plots of a tracking run into `dir` (created if needed), in the style of the
/// thesis's Figs 4.12–4.30, and returns the files written:
/// * `trajectory.png`: desired vs actual path (x, y);
/// * `error.png`: distance error against time;
/// * `theta.png`: θ̂1…θ̂6 against time, one panel each.
///
/// # Errors
/// If the directory cannot be created or a PNG cannot be written.
pub fn write_track_plots(r: &TrackResult, dir: &Path) -> Result<Vec<PathBuf>> {
    register_font();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let step = (r.t.len() / MAX_POINTS).max(1);
    Ok(vec![
        trajectory_plot(r, dir, step)?,
        error_plot(r, dir, step)?,
        theta_plot(r, dir, step)?,
    ])
}

/// `trajectory.png`: the desired and actual paths (x, y) \[m\], every `step`-th point.
fn trajectory_plot(r: &TrackResult, dir: &Path, step: usize) -> Result<PathBuf> {
    let path = dir.join("trajectory.png");
    {
        let root = BitMapBackend::new(&path, (900, 900)).into_drawing_area();
        root.fill(&WHITE)?;
        let xs = r.desired.iter().chain(&r.actual).map(|p| p[0]);
        let ys = r.desired.iter().chain(&r.actual).map(|p| p[1]);
        let ((x0, x1), (y0, y1)) = (range(xs), range(ys));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{}: desired vs actual trajectory", r.robot),
                ("sans-serif", 20),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("x [m]")
            .y_desc("y [m]")
            .draw()?;
        for (pts, color, label) in [(&r.desired, BLUE, "desired"), (&r.actual, RED, "actual")] {
            chart
                .draw_series(LineSeries::new(
                    pts.iter().step_by(step).map(|p| (p[0], p[1])),
                    color.stroke_width(if label == "actual" { 1 } else { 2 }),
                ))?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    Ok(path)
}

/// `error.png`: the distance error \[m\] against time \[s\], every `step`-th point.
fn error_plot(r: &TrackResult, dir: &Path, step: usize) -> Result<PathBuf> {
    let (t0, t1) = (r.t[0], r.t[r.t.len() - 1]);
    let path = dir.join("error.png");
    {
        let root = BitMapBackend::new(&path, (1200, 500)).into_drawing_area();
        root.fill(&WHITE)?;
        let (_, e1) = range(r.error.iter().copied());
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "{}: distance error (RMS {:.4} m, final {:.4} m, max {:.4} m)",
                    r.robot, r.summary.rms, r.summary.last, r.summary.max
                ),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, 0.0..e1)?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc("error [m]")
            .draw()?;
        chart.draw_series(LineSeries::new(
            r.t.iter()
                .zip(&r.error)
                .step_by(step)
                .map(|(a, b)| (*a, *b)),
            RED.stroke_width(1),
        ))?;
        root.present()?;
    }
    Ok(path)
}

/// `theta.png`: θ̂1…θ̂6 of the adaptive law against time \[s\], every `step`-th point.
fn theta_plot(r: &TrackResult, dir: &Path, step: usize) -> Result<PathBuf> {
    let (t0, t1) = (r.t[0], r.t[r.t.len() - 1]);
    let path = dir.join("theta.png");
    {
        let root = BitMapBackend::new(&path, (1500, 800)).into_drawing_area();
        root.fill(&WHITE)?;
        let cells = root.split_evenly((2, 3));
        for (i, area) in cells.iter().enumerate() {
            let (y0, y1) = range(r.theta_hat.iter().map(|th| th[i]));
            let mut chart = ChartBuilder::on(area)
                .caption(format!("θ̂{}", i + 1), ("sans-serif", 18))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(t0..t1, y0..y1)?;
            chart.configure_mesh().x_desc("t [s]").draw()?;
            chart.draw_series(LineSeries::new(
                r.t.iter()
                    .zip(&r.theta_hat)
                    .step_by(step)
                    .map(|(a, th)| (*a, th[i])),
                BLUE.stroke_width(2),
            ))?;
        }
        root.present()?;
    }
    Ok(path)
}

/// Writes the plots of a diagnosis into `dir` (created if needed) and returns the files:
/// * `diagnosis_response_<file>.png`: measured vs nominal vs extended (final) free-run v and
///   ω, validation blocks shaded;
/// * `diagnosis_correlation.png`: residual–command cross-correlations of the nominal and the
///   final model against lag, with their 99 % bounds (Ljung §16.6);
/// * `diagnosis_location.png`: where the nominal misfit lives — residual RMS per operating
///   region over the RMS everywhere, nominal vs final, per channel.
///
/// # Errors
/// If the directory cannot be created or a PNG cannot be written.
pub fn write_diagnosis_plots(d: &Diagnosis, dir: &Path) -> Result<Vec<PathBuf>> {
    register_font();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut out = diagnosis_response_plots(d, dir)?;
    out.push(diagnosis_correlation_plot(d, dir)?);
    out.push(diagnosis_location_plot(d, dir)?);
    Ok(out)
}

/// Axis labels and short names of the two channels.
const CHANNEL_LABELS: [(&str, &str); 2] = [("v [m/s]", "v"), ("ω [rad/s]", "ω")];

/// `diagnosis_response_<file>.png`, one per recording: measured, nominal and extended
/// responses, validation blocks shaded.
fn diagnosis_response_plots(d: &Diagnosis, dir: &Path) -> Result<Vec<PathBuf>> {
    let labels = CHANNEL_LABELS;
    let mut out = Vec::new();
    for (i, s) in d.series.iter().enumerate() {
        let path = dir.join(format!("diagnosis_response_{}.png", stem(&s.source, i)));
        {
            let root = BitMapBackend::new(&path, (1400, 800)).into_drawing_area();
            root.fill(&WHITE)?;
            let panels = root.split_evenly((2, 1));
            for (ch, area) in panels.iter().enumerate() {
                time_panel(
                    area,
                    &format!(
                        "{} — {}: measured, nominal, {} (grey: validation)",
                        s.source.display(),
                        labels[ch].1,
                        d.final_stage.model
                    ),
                    labels[ch].0,
                    &s.t,
                    &[
                        (&s.measured[ch], BLUE, 1, "measured"),
                        (&s.nominal[ch], RGBColor(230, 120, 0), 1, "nominal"),
                        (&s.extended[ch], RGBColor(200, 0, 0), 2, "extended"),
                    ],
                    Some(&s.validation),
                )?;
            }
            root.present()?;
        }
        out.push(path);
    }
    Ok(out)
}

/// `diagnosis_correlation.png`: each residual's cross-correlation with each command, nominal
/// and final, with the independence bounds.
fn diagnosis_correlation_plot(d: &Diagnosis, dir: &Path) -> Result<PathBuf> {
    let labels = CHANNEL_LABELS;
    let path = dir.join("diagnosis_correlation.png");
    {
        let root = BitMapBackend::new(&path, (1400, 900)).into_drawing_area();
        root.fill(&WHITE)?;
        let cells = root.split_evenly((2, 2));
        let lag = d.location.max_lag as isize;
        let dt = d.location.dt;
        for ch in 0..2 {
            for u in 0..2 {
                let before = &d.location.channels[ch].independence[u];
                let after = &d.final_location.channels[ch].independence[u];
                let (y0, y1) = range(
                    before
                        .r
                        .iter()
                        .chain(&after.r)
                        .copied()
                        .chain(before.band.iter().flat_map(|b| [*b, -*b])),
                );
                let x = |i: usize| (i as isize - lag) as f64 * dt;
                let (x0, x1) = (x(0), x(before.r.len().saturating_sub(1)).max(x(0) + dt));
                let mut chart = ChartBuilder::on(&cells[2 * ch + u])
                    .caption(
                        format!(
                            "{} residual vs {} (p = {:.1e} → {:.1e})",
                            labels[ch].1,
                            ["v_ref", "ω_ref"][u],
                            before.p_value,
                            after.p_value
                        ),
                        ("sans-serif", 18),
                    )
                    .margin(8)
                    .x_label_area_size(35)
                    .y_label_area_size(55)
                    .build_cartesian_2d(x0..x1, y0..y1)?;
                chart
                    .configure_mesh()
                    .x_desc("lag [s] (> 0: residual after command)")
                    .y_desc("cross-correlation")
                    .draw()?;
                for (t, color, name) in [
                    (before, RGBColor(230, 120, 0), "nominal"),
                    (after, RGBColor(200, 0, 0), "final"),
                ] {
                    chart
                        .draw_series(LineSeries::new(
                            t.r.iter().enumerate().map(|(i, r)| (x(i), *r)),
                            color.stroke_width(2),
                        ))?
                        .label(name)
                        .legend(move |(a, b)| {
                            PathElement::new(vec![(a, b), (a + 20, b)], color.stroke_width(2))
                        });
                    for sign in [1.0, -1.0] {
                        chart.draw_series(LineSeries::new(
                            t.band.iter().enumerate().map(|(i, b)| (x(i), sign * b)),
                            color.mix(0.6).stroke_width(1),
                        ))?;
                    }
                }
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .draw()?;
            }
        }
        root.present()?;
    }
    Ok(path)
}

/// `diagnosis_location.png`: each residual's RMS by region of the commands, nominal and final.
fn diagnosis_location_plot(d: &Diagnosis, dir: &Path) -> Result<PathBuf> {
    let labels = CHANNEL_LABELS;
    let path = dir.join("diagnosis_location.png");
    {
        let root = BitMapBackend::new(&path, (1400, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let cells = root.split_evenly((1, 2));
        for ch in 0..2 {
            let before = &d.location.channels[ch].regions;
            let after = &d.final_location.channels[ch].regions;
            let names: Vec<String> = before.iter().map(|r| r.name.clone()).collect();
            let after_of = |n: &str| {
                after
                    .iter()
                    .find(|r| r.name == n)
                    .map_or(0.0, |r| r.rms_ratio * d.final_location.channels[ch].rms)
                    / d.location.channels[ch].rms.max(1e-300)
            };
            let top = before
                .iter()
                .map(|r| r.rms_ratio)
                .chain(names.iter().map(|n| after_of(n)))
                .fold(1.0f64, f64::max)
                * 1.1;
            // Horizontal bars, two rows per region (nominal, then final), names on the left.
            let rows = 2 * names.len() as i32;
            let mut chart = ChartBuilder::on(&cells[ch])
                .caption(
                    format!(
                        "{}: residual RMS by region / nominal RMS overall (orange: nominal, red: final)",
                        labels[ch].1
                    ),
                    ("sans-serif", 16),
                )
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(170)
                .build_cartesian_2d(0.0..top, 0..rows.max(1))?;
            chart
                .configure_mesh()
                .disable_y_mesh()
                .y_labels(rows.max(1) as usize + 1)
                .y_label_formatter(&|y| {
                    if y % 2 == 1 {
                        names.get((y / 2) as usize).cloned().unwrap_or_default()
                    } else {
                        String::new()
                    }
                })
                .x_desc("RMS ratio")
                .draw()?;
            for (i, r) in before.iter().enumerate() {
                let y = 2 * i as i32;
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(0.0, y), (r.rms_ratio, y + 1)],
                    RGBColor(230, 120, 0).filled(),
                )))?;
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(0.0, y + 1), (after_of(&r.name), y + 2)],
                    RGBColor(200, 0, 0).filled(),
                )))?;
            }
        }
        root.present()?;
    }
    Ok(path)
}

/// The runs of a migration check side by side (`wheelid migrate --plot DIR`):
/// * `migrate_paths.png`: the desired figure eight and each run's path (x, y) \[m\];
/// * `migrate_error.png`: each run's distance error \[m\] against time \[s\].
///
/// `runs`: (label, result) in the order of [`crate::migrate::Migration::runs`].
///
/// # Errors
/// If the directory cannot be created or a PNG cannot be written.
pub fn write_migration_plots(runs: &[(&str, &TrackResult)], dir: &Path) -> Result<Vec<PathBuf>> {
    register_font();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let Some((_, first)) = runs.first() else {
        return Ok(Vec::new());
    };
    let colors = [RED, GREEN, MAGENTA, CYAN];
    let path = dir.join("migrate_paths.png");
    {
        let root = BitMapBackend::new(&path, (900, 900)).into_drawing_area();
        root.fill(&WHITE)?;
        let all = || {
            runs.iter()
                .flat_map(|(_, r)| r.desired.iter().chain(&r.actual))
        };
        let ((x0, x1), (y0, y1)) = (range(all().map(|p| p[0])), range(all().map(|p| p[1])));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{}: the migrated figure eight", first.robot),
                ("sans-serif", 20),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("x [m]")
            .y_desc("y [m]")
            .draw()?;
        let step = (first.t.len() / MAX_POINTS).max(1);
        chart
            .draw_series(LineSeries::new(
                first.desired.iter().step_by(step).map(|p| (p[0], p[1])),
                BLUE.stroke_width(3),
            ))?
            .label("desired")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        for ((label, r), color) in runs.iter().zip(colors) {
            let step = (r.t.len() / MAX_POINTS).max(1);
            chart
                .draw_series(LineSeries::new(
                    r.actual.iter().step_by(step).map(|p| (p[0], p[1])),
                    color.stroke_width(1),
                ))?
                .label(format!("{label} (RMS {:.4} m)", r.summary.rms))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    let mut out = vec![path];
    let path = dir.join("migrate_error.png");
    {
        let root = BitMapBackend::new(&path, (1200, 500)).into_drawing_area();
        root.fill(&WHITE)?;
        let (t0, t1) = range(runs.iter().flat_map(|(_, r)| r.t.iter().copied()));
        let (_, e1) = range(runs.iter().flat_map(|(_, r)| r.error.iter().copied()));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{}: distance error", first.robot),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, (1e-4f64..e1.max(1e-3)).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc("error [m]")
            .draw()?;
        for ((label, r), color) in runs.iter().zip(colors) {
            let step = (r.t.len() / MAX_POINTS).max(1);
            chart
                .draw_series(LineSeries::new(
                    r.t.iter()
                        .zip(&r.error)
                        .step_by(step)
                        .map(|(a, b)| (*a, b.max(1e-4))),
                    color.stroke_width(1),
                ))?
                .label(*label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    out.push(path);
    Ok(out)
}

/// Writes `online.png` into `dir`: θ̂1…θ̂6 of an online run against time, each with the batch
/// answer as a dashed line, the axis held to ±30 % around the batch value (the estimate
/// starts far off); change alarms as red ticks on the time axis.
///
/// # Errors
/// If the PNG cannot be written.
pub fn write_online_plot(
    trace: &crate::run::OnlineTrace,
    batch: &[f64],
    dir: &Path,
) -> Result<PathBuf> {
    register_font();
    let path = dir.join("online.png");
    let t = &trace.t;
    if t.len() < 2 || batch.len() < 6 {
        anyhow::bail!("an online trace of {} samples has nothing to plot", t.len());
    }
    let step = (t.len() / MAX_POINTS).max(1);
    {
        let root = BitMapBackend::new(&path, (1500, 800)).into_drawing_area();
        root.fill(&WHITE)?;
        for (i, area) in root.split_evenly((2, 3)).iter().enumerate() {
            let b = batch[i];
            let half = (0.3 * b.abs()).max(1e-3);
            let (y0, y1) = (b - half, b + half);
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!("θ̂{} online (batch dashed)", i + 1),
                    ("sans-serif", 18),
                )
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(t[0]..t[t.len() - 1], y0..y1)?;
            chart.configure_mesh().x_desc("t [s]").draw()?;
            chart.draw_series(LineSeries::new(
                t.iter()
                    .zip(&trace.theta)
                    .step_by(step)
                    .filter(|(_, th)| th[i].is_finite())
                    .map(|(a, th)| (*a, th[i].clamp(y0, y1))),
                BLUE.stroke_width(2),
            ))?;
            chart.draw_series(DashedLineSeries::new(
                [(t[0], b), (t[t.len() - 1], b)],
                6,
                4,
                BLACK.stroke_width(1),
            ))?;
            chart.draw_series(
                t.iter()
                    .zip(&trace.change)
                    .filter(|(_, c)| c[0] || c[1])
                    .map(|(a, _)| PathElement::new(vec![(*a, y0), (*a, y0 + 0.1 * half)], RED)),
            )?;
        }
        root.present()?;
    }
    Ok(path)
}

/// Writes `design.png` into `dir`: a designed experiment's v_ref and ω_ref over the drive,
/// and the pose path the model predicts from its start (the floor space as a box).
///
/// # Errors
/// If the PNG cannot be written.
pub fn write_design_plot(
    d: &crate::design::Design,
    space_m: [f64; 2],
    dir: &Path,
) -> Result<PathBuf> {
    register_font();
    let path = dir.join("design.png");
    let n = d.path_m.len().max(2);
    let dt = d.duration_s / (n - 1) as f64;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let (v, w): (Vec<f64>, Vec<f64>) = t.iter().map(|&x| d.excitation.at(x)).unzip();
    {
        let root = BitMapBackend::new(&path, (1500, 700)).into_drawing_area();
        root.fill(&WHITE)?;
        let (left, right) = root.split_horizontally(900);
        let rows = left.split_evenly((2, 1));
        time_panel(
            &rows[0],
            "v_ref (designed)",
            "m/s",
            &t,
            &[(&v, BLUE, 2, "v_ref")],
            None,
        )?;
        time_panel(
            &rows[1],
            "ω_ref (designed)",
            "rad/s",
            &t,
            &[(&w, RED, 2, "ω_ref")],
            None,
        )?;
        let (hx, hy) = (0.5 * space_m[0], 0.5 * space_m[1]);
        let mut chart = ChartBuilder::on(&right)
            .caption("predicted pose (floor space)", ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(50)
            .build_cartesian_2d(-hx * 1.1..hx * 1.1, -hy * 1.1..hy * 1.1)?;
        chart
            .configure_mesh()
            .x_desc("x [m]")
            .y_desc("y [m]")
            .draw()?;
        chart.draw_series(std::iter::once(Rectangle::new(
            [(-hx, -hy), (hx, hy)],
            BLACK.stroke_width(1),
        )))?;
        chart.draw_series(LineSeries::new(
            d.path_m.iter().map(|p| (p[0], p[1])),
            BLUE.stroke_width(2),
        ))?;
        root.present()?;
    }
    Ok(path)
}
