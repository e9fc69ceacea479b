//! Output files of the CLI: the contract's CSV and an SVG plot, written so that a failed
//! or interrupted run never leaves a file that looks complete.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::simulation::Simulation;

/// The CSV header of the contract.
pub const CSV_HEADER: &str = "step,time,marble,x,y,z,vx,vy,vz,wx,wy,wz";

/// A file written under a temporary name and renamed into place by [`AtomicFile::commit`];
/// dropped without commit, it is removed.
pub struct AtomicFile {
    tmp: PathBuf,
    dest: PathBuf,
    writer: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Starts writing `dest` (as `dest.partial` until committed). A `dest` that is a
    /// directory is refused at once (it could not be replaced at the commit).
    pub fn create(dest: &Path) -> io::Result<AtomicFile> {
        if dest.is_dir() {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                "is a directory",
            ));
        }
        let mut name = dest.as_os_str().to_owned();
        name.push(".partial");
        let tmp = PathBuf::from(name);
        let writer = BufWriter::new(File::create(&tmp)?);
        Ok(AtomicFile {
            tmp,
            dest: dest.to_path_buf(),
            writer: Some(writer),
        })
    }

    /// The writer.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        self.writer.as_mut().expect("not committed")
    }

    /// Flushes and moves the file into place; on failure the temporary file is removed
    /// (nothing is left behind, as when dropped).
    pub fn commit(mut self) -> io::Result<()> {
        let w = self.writer.take().expect("not committed");
        let done = w
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_all())
            .and_then(|()| std::fs::rename(&self.tmp, &self.dest));
        if done.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
        }
        done
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.writer.is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Writes one CSV row per marble for the simulation's current state, labelled `step`.
/// Numbers use Rust's shortest round-trip formatting, so they parse back to the same f32.
/// A marble the program despawned has `NaN` for its state.
pub fn write_csv_rows(w: &mut impl Write, sim: &Simulation, step: u64, dt: f32) -> io::Result<()> {
    let time = (step as f64 * dt as f64) as f32;
    for i in 0..sim.marbles().len() {
        let (x, v) = sim
            .try_marble_world_state(i)
            .unwrap_or((glam::Vec3::NAN, glam::Vec3::NAN));
        let s = sim.marble_world_spin(i);
        writeln!(
            w,
            "{step},{time},{i},{},{},{},{},{},{},{},{},{}",
            x.x, x.y, x.z, v.x, v.y, v.z, s.x, s.y, s.z
        )?;
    }
    Ok(())
}

/// The header of a board-pose file (`marble run --poses`): for each row, the pose board
/// `board` (its index in the scene) reaches at the end of step `step` (1 for the first
/// step), as a [`NextPose`](crate::components::NextPose).
pub const POSES_HEADER: &str = "step,board,x,y,z,qx,qy,qz,qw";

/// One row of a board-pose file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRow {
    /// The step at whose end the board is there (≥ 1).
    pub step: u64,
    /// The board's index in the scene.
    pub board: usize,
    /// Its position, m.
    pub position: glam::Vec3,
    /// Its orientation (a unit quaternion).
    pub rotation: glam::Quat,
}

/// Writes one board-pose row (numbers that parse back to the same f32).
pub fn write_pose_row(w: &mut impl Write, row: &PoseRow) -> io::Result<()> {
    let (p, q) = (row.position, row.rotation);
    writeln!(
        w,
        "{},{},{},{},{},{},{},{},{}",
        row.step, row.board, p.x, p.y, p.z, q.x, q.y, q.z, q.w
    )
}

/// Reads a board-pose file for a scene of `boards` boards: the header, then rows in order
/// of step, at most one per board and step. An error names the line, the field and the
/// value.
pub fn parse_poses(text: &str, boards: usize) -> Result<Vec<PoseRow>, String> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == POSES_HEADER => {}
        other => {
            return Err(format!(
                "line 1: the header must be {POSES_HEADER:?}, got {:?}",
                other.map_or("", |(_, h)| h)
            ));
        }
    }
    let mut rows: Vec<PoseRow> = Vec::new();
    for (i, line) in lines {
        let n = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 9 {
            return Err(format!(
                "line {n}: 9 fields ({POSES_HEADER}), got {}",
                fields.len()
            ));
        }
        let names = ["step", "board", "x", "y", "z", "qx", "qy", "qz", "qw"];
        let step: u64 = fields[0].parse().ok().filter(|&s| s >= 1).ok_or_else(|| {
            format!(
                "line {n}: step must be a whole number >= 1, got {:?}",
                fields[0]
            )
        })?;
        let board: usize = fields[1]
            .parse()
            .ok()
            .filter(|&b| b < boards)
            .ok_or_else(|| {
                format!(
                    "line {n}: board must be the index of one of the {boards} boards, got {:?}",
                    fields[1]
                )
            })?;
        let mut v = [0f32; 7];
        for k in 0..7 {
            let x: f32 = fields[2 + k]
                .parse()
                .ok()
                .filter(|x: &f32| x.is_finite())
                .ok_or_else(|| {
                    format!(
                        "line {n}: {} must be a finite number, got {:?}",
                        names[2 + k],
                        fields[2 + k]
                    )
                })?;
            if k < 3 && x.abs() > crate::validate::MAX_COORDINATE {
                return Err(format!(
                    "line {n}: {} must be within {:e} m of the origin, got {x}",
                    names[2 + k],
                    crate::validate::MAX_COORDINATE
                ));
            }
            v[k] = x;
        }
        let rotation = glam::Quat::from_xyzw(v[3], v[4], v[5], v[6]);
        let length = rotation.length();
        if (length - 1.0).abs() > 1e-3 {
            return Err(format!(
                "line {n}: qx, qy, qz, qw must be a unit quaternion (length within 1e-3 of 1), got length {length}"
            ));
        }
        if let Some(last) = rows.last()
            && (step < last.step || (step == last.step && board <= last.board))
        {
            return Err(format!(
                "line {n}: rows must be in order of step, then board, one per board and step; got step {step} board {board} after step {} board {}",
                last.step, last.board
            ));
        }
        rows.push(PoseRow {
            step,
            board,
            position: glam::Vec3::new(v[0], v[1], v[2]),
            rotation,
        });
    }
    Ok(rows)
}

/// The speed colours of the plots and the replay page: blue (still) through teal and
/// yellow to red (fast), `x` from 0 to 1.
pub fn speed_colour(x: f32) -> [u8; 3] {
    const STOPS: [(f32, [f32; 3]); 5] = [
        (0.0, [59.0, 111.0, 182.0]),
        (0.35, [43.0, 179.0, 163.0]),
        (0.6, [231.0, 211.0, 74.0]),
        (0.8, [240.0, 140.0, 46.0]),
        (1.0, [232.0, 65.0, 60.0]),
    ];
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    for w in STOPS.windows(2) {
        let ((x0, c0), (x1, c1)) = (w[0], w[1]);
        if x <= x1 {
            let s = (x - x0) / (x1 - x0);
            return [0, 1, 2].map(|i| (c0[i] + s * (c1[i] - c0[i])).round() as u8);
        }
    }
    [232, 65, 60]
}

/// Most marbles whose trails the top view draws (every k-th beyond), and most points per
/// trail: the file stays well under a megabyte.
#[cfg(feature = "cli")]
const TRAILS: usize = 300;
#[cfg(feature = "cli")]
const TRAIL_POINTS: usize = 240;

/// The run's pictures as one SVG: a top view of the boards and sensors (as at the
/// start) with each marble's trail coloured by its speed and its last position marked,
/// and beside it the marbles' energy and their fastest and mean speed over time.
#[cfg(feature = "cli")]
pub fn plot_svg(rec: &crate::replay::Recording) -> io::Result<String> {
    let mut svg = String::new();
    {
        use plotters::prelude::*;
        let root = SVGBackend::with_string(&mut svg, (1400, 720)).into_drawing_area();
        let draw = || -> Result<(), Box<dyn std::error::Error + '_>> {
            root.fill(&WHITE)?;
            let root = root.titled(&rec.title, ("sans-serif", 20))?;
            let (left, right) = root.split_horizontally(700);
            top_view(rec, &left)?;
            let (upper, lower) = right.split_vertically(340);
            let times: Vec<f32> = (0..rec.frames()).map(|f| rec.time(f)).collect();
            let line = |values: &mut dyn Iterator<Item = f64>| -> Vec<(f32, f64)> {
                times.iter().copied().zip(values).collect()
            };
            time_panel(
                &upper,
                ("energy of the marbles", "energy (J)"),
                &[
                    (
                        "total (kinetic + potential)",
                        BLUE,
                        line(&mut rec.energy.iter().copied()),
                    ),
                    (
                        "kinetic",
                        RGBColor(240, 140, 46),
                        line(&mut rec.kinetic.iter().copied()),
                    ),
                ],
                false,
            )?;
            time_panel(
                &lower,
                ("speed of the marbles", "speed (m/s)"),
                &[
                    (
                        "fastest",
                        RGBColor(232, 65, 60),
                        line(&mut rec.speed_max.iter().map(|&v| v as f64)),
                    ),
                    (
                        "mean",
                        RGBColor(43, 150, 140),
                        line(&mut rec.speed_mean.iter().map(|&v| v as f64)),
                    ),
                ],
                true,
            )?;
            root.present()?;
            Ok(())
        };
        draw().map_err(|e| io::Error::other(e.to_string()))?;
    }
    Ok(svg)
}

/// One panel of series over time, `(caption, y axis)`, with a legend; from zero when
/// `from_zero`, else over the values' span.
#[cfg(feature = "cli")]
fn time_panel<DB: plotters::prelude::DrawingBackend>(
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    (caption, y_desc): (&str, &str),
    series: &[(&str, plotters::style::RGBColor, Vec<(f32, f64)>)],
    from_zero: bool,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let t1 = series
        .iter()
        .flat_map(|s| s.2.last().map(|p| p.0))
        .fold(0.0f32, f32::max)
        .max(1e-6);
    let (lo, hi) = span(series.iter().flat_map(|s| s.2.iter().map(|p| p.1)));
    let lo = if from_zero { 0.0 } else { lo };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .build_cartesian_2d(0f32..t1, lo..hi.max(lo + 1e-6))?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_desc)
        .draw()?;
    for &(label, colour, ref points) in series {
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                colour.stroke_width(2),
            ))?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

/// The least and greatest finite value, padded by 5% (a flat series gets a unit span).
#[cfg(feature = "cli")]
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        0.5 * hi.abs().max(1e-9)
    };
    (lo - pad, hi + pad)
}

/// The top view: looking down −Y, x to the right and z down the page, one metre the same
/// length both ways.
#[cfg(feature = "cli")]
fn top_view<DB: plotters::prelude::DrawingBackend>(
    rec: &crate::replay::Recording,
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let (area, legend) = area.split_vertically(area.dim_in_pixel().1 - 56);
    // Bounds: the bounded boards' lines at the start and every marble's path.
    let (mut lo, mut hi) = (
        glam::Vec2::splat(f32::INFINITY),
        glam::Vec2::splat(f32::NEG_INFINITY),
    );
    let mut add = |p: glam::Vec3| {
        if p.is_finite() {
            lo = lo.min(glam::Vec2::new(p.x, p.z));
            hi = hi.max(glam::Vec2::new(p.x, p.z));
        }
    };
    let at_start = |tracks: &[crate::replay::BoardTrack]| -> Vec<[glam::Vec3; 2]> {
        tracks
            .iter()
            .filter_map(|b| b.poses.first().map(|pose| (b, pose)))
            .flat_map(|(b, &(p, q))| b.segments.iter().map(move |s| s.map(|x| p + q * x)))
            .collect()
    };
    let (lines, sensor_lines) = (at_start(&rec.boards), at_start(&rec.sensors));
    lines.iter().flatten().for_each(|&p| add(p));
    for f in 0..rec.frames() {
        rec.positions(f).iter().for_each(|&p| add(p));
    }
    if lo.x.is_nan() || lo.x > hi.x {
        (lo, hi) = (glam::Vec2::splat(-0.5), glam::Vec2::splat(0.5));
    }
    let (w, h) = area.dim_in_pixel();
    let (w, h) = (w as f32 - 90.0, h as f32 - 70.0);
    let half = 0.5 * ((hi - lo) * 1.04).max(glam::Vec2::splat(1e-3));
    let mid = 0.5 * (lo + hi);
    // One metre the same length on both axes: widen the narrower span.
    let scale = (w / (2.0 * half.x)).min(h / (2.0 * half.y));
    let half = glam::Vec2::new(w, h) / (2.0 * scale);
    let mut chart = ChartBuilder::on(&area)
        .caption("top view: trails coloured by speed", ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (mid.x - half.x)..(mid.x + half.x),
            (mid.y + half.y)..(mid.y - half.y),
        )?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (m)")
        .y_desc("z (m)")
        .draw()?;
    // Boards in grey, sensors (goals, holes) in amber.
    for (set, colour) in [
        (&lines, RGBColor(120, 128, 140)),
        (&sensor_lines, RGBColor(220, 170, 30)),
    ] {
        chart
            .draw_series(set.iter().map(|[a, b]| {
                PathElement::new([(a.x, a.z), (b.x, b.z)], colour.stroke_width(1))
            }))?;
    }
    // The colour scale: the 98th percentile of the recorded speeds.
    let mut speeds: Vec<f32> = (0..rec.frames())
        .flat_map(|f| rec.velocities(f).iter().map(|v| v.length()))
        .filter(|s| s.is_finite())
        .collect();
    let vmax = if speeds.is_empty() {
        0.01
    } else {
        let k = (0.98 * (speeds.len() - 1) as f32) as usize;
        *speeds.select_nth_unstable_by(k, f32::total_cmp).1
    }
    .max(0.01);
    let colour = |s: f32| {
        let [r, g, b] = speed_colour(s / vmax);
        RGBColor(r, g, b)
    };
    let n = rec.radii.len();
    let every = n.div_ceil(TRAILS).max(1);
    let frame_step = rec.frames().div_ceil(TRAIL_POINTS).max(1);
    let mut frames: Vec<usize> = (0..rec.frames()).step_by(frame_step).collect();
    if frames.last() != Some(&(rec.frames() - 1)) {
        frames.push(rec.frames() - 1);
    }
    for i in (0..n).step_by(every) {
        // Runs of segments in one of 16 colour bands, each one path.
        let mut run: Vec<(f32, f32)> = Vec::new();
        let mut band = usize::MAX;
        for w in frames.windows(2) {
            let (a, b) = (rec.positions(w[0])[i], rec.positions(w[1])[i]);
            if !(a.is_finite() && b.is_finite()) {
                continue;
            }
            let s = 0.5 * (rec.velocities(w[0])[i].length() + rec.velocities(w[1])[i].length());
            let k = ((s / vmax).clamp(0.0, 1.0) * 15.0).round() as usize;
            if k != band || run.is_empty() {
                if run.len() > 1 {
                    chart.draw_series(std::iter::once(PathElement::new(
                        std::mem::take(&mut run),
                        colour(band as f32 / 15.0 * vmax).stroke_width(2),
                    )))?;
                }
                run.clear();
                run.push((a.x, a.z));
                band = k;
            }
            run.push((b.x, b.z));
        }
        if run.len() > 1 {
            chart.draw_series(std::iter::once(PathElement::new(
                run,
                colour(band as f32 / 15.0 * vmax).stroke_width(2),
            )))?;
        }
    }
    if let Some(last) = rec.frames().checked_sub(1) {
        chart.draw_series(
            (0..n)
                .filter(|&i| rec.positions(last)[i].is_finite())
                .map(|i| {
                    let p = rec.positions(last)[i];
                    let px = (rec.radii[i] * scale).max(2.0) as i32;
                    Circle::new((p.x, p.z), px, BLACK.mix(0.75).stroke_width(1))
                }),
        )?;
    }
    // The legend: a colour bar from 0 to vmax.
    let (lw, _) = legend.dim_in_pixel();
    let (x0, x1) = (80i32, lw as i32 - 40);
    for k in 0..100 {
        let xa = x0 + (x1 - x0) * k / 100;
        let xb = x0 + (x1 - x0) * (k + 1) / 100;
        let [r, g, b] = speed_colour(k as f32 / 99.0);
        legend.draw(&Rectangle::new(
            [(xa, 8), (xb, 22)],
            RGBColor(r, g, b).filled(),
        ))?;
    }
    let text = ("sans-serif", 13).into_font().color(&BLACK);
    legend.draw(&Text::new("0", (x0 - 4, 28), text.clone()))?;
    legend.draw(&Text::new(
        format!("{vmax:.3} m/s and faster"),
        (x1 - 120, 28),
        text.clone(),
    ))?;
    legend.draw(&Text::new(
        format!(
            "speed; {} of {} marbles' trails; circles: where they are at the end",
            n.div_ceil(every),
            rec.marbles
        ),
        (x0, 44),
        text,
    ))?;
    Ok(())
}

/// Writes `bytes` to `path` through an [`AtomicFile`].
#[cfg(feature = "cli")]
fn write_atomically(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.writer().write_all(bytes)?;
    f.commit()
}

/// Writes the error-versus-cost plot of one reference scene of the study (log–log, one
/// colour per integrator, filled marks for CCD on, the Pareto front joined by a line).
/// Errors of exactly 0 are drawn at the bottom of the axis.
#[cfg(feature = "cli")]
pub fn write_tradeoff_svg(
    rows: &[crate::study::Row],
    reference: crate::study::Reference,
    path: &Path,
) -> io::Result<()> {
    use crate::config::Integrator;
    use crate::study::pareto_front;
    use plotters::prelude::*;

    let floor = 1e-7f64;
    let point = |r: &crate::study::Row| (r.us_per_second(), (r.error(reference) as f64).max(floor));
    let (mut x0, mut x1, mut y1) = (f64::INFINITY, 0.0f64, floor * 10.0);
    for r in rows {
        let (x, y) = point(r);
        x0 = x0.min(x);
        x1 = x1.max(x);
        y1 = y1.max(y);
    }
    if !x0.is_finite() || x1 <= x0 {
        (x0, x1) = (1.0, 10.0);
    }
    let colour = |i: Integrator| match i {
        Integrator::SemiImplicitEuler => BLUE,
        Integrator::VelocityVerlet => RED,
        Integrator::Rk4 => GREEN,
        Integrator::ExplicitEuler => MAGENTA,
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 600)).into_drawing_area();
        let draw = || -> Result<(), Box<dyn std::error::Error + '_>> {
            root.fill(&WHITE)?;
            let mut chart = ChartBuilder::on(&root)
                .caption(
                    format!("{}: {}", reference.name(), reference.description()),
                    ("sans-serif", 16),
                )
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(70)
                .build_cartesian_2d(
                    (x0 * 0.8..x1 * 1.25).log_scale(),
                    (floor * 0.5..y1 * 2.0).log_scale(),
                )?;
            chart
                .configure_mesh()
                .x_desc("cost: µs per marble per simulated second")
                .y_desc("error")
                .x_label_formatter(&|x| format!("{x:.0}"))
                .y_label_formatter(&|y| format!("{y:.0e}"))
                .draw()?;
            for integrator in Integrator::ALL {
                let c = colour(integrator);
                chart
                    .draw_series(
                        rows.iter()
                            .filter(|r| r.setting.integrator == integrator)
                            .map(|r| {
                                let style = if r.setting.ccd {
                                    c.filled()
                                } else {
                                    c.stroke_width(1)
                                };
                                Circle::new(point(r), 4, style)
                            }),
                    )?
                    .label(format!("{integrator:?}"))
                    .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
            }
            let front: Vec<(f64, f64)> = pareto_front(rows, reference)
                .into_iter()
                .map(|i| point(&rows[i]))
                .collect();
            chart
                .draw_series(LineSeries::new(front, BLACK.stroke_width(2)))?
                .label("Pareto front (filled: CCD on)")
                .legend(|(x, y)| PathElement::new([(x - 8, y), (x + 8, y)], BLACK));
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerLeft)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
            root.present()?;
            Ok(())
        };
        draw().map_err(|e| io::Error::other(e.to_string()))?;
    }
    write_atomically(path, svg.as_bytes())
}
