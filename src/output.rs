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
    /// Starts writing `dest` (as `dest.partial` until committed).
    pub fn create(dest: &Path) -> io::Result<AtomicFile> {
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

    /// Flushes and moves the file into place.
    pub fn commit(mut self) -> io::Result<()> {
        let w = self.writer.take().expect("not committed");
        w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&self.tmp, &self.dest)
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
pub fn write_csv_rows(w: &mut impl Write, sim: &Simulation, step: u64, dt: f32) -> io::Result<()> {
    let time = (step as f64 * dt as f64) as f32;
    for i in 0..sim.marbles().len() {
        let (x, v) = sim.marble_world_state(i);
        let s = sim.marble_spin(i);
        writeln!(
            w,
            "{step},{time},{i},{},{},{},{},{},{},{},{},{}",
            x.x, x.y, x.z, v.x, v.y, v.z, s.x, s.y, s.z
        )?;
    }
    Ok(())
}

/// Heights of the first [`HeightTrace::MAX_MARBLES`] marbles over time, for `--plot`.
pub struct HeightTrace {
    enabled: bool,
    series: Vec<Vec<(f32, f32)>>,
}

impl HeightTrace {
    /// Most marbles drawn.
    pub const MAX_MARBLES: usize = 16;

    /// A trace for `marbles` marbles; records nothing unless `enabled`.
    pub fn new(enabled: bool, marbles: usize) -> Self {
        let n = if enabled {
            marbles.min(Self::MAX_MARBLES)
        } else {
            0
        };
        HeightTrace {
            enabled,
            series: vec![Vec::new(); n],
        }
    }

    /// Records the current heights at `time`.
    pub fn record(&mut self, sim: &Simulation, time: f32) {
        if !self.enabled {
            return;
        }
        for (i, s) in self.series.iter_mut().enumerate() {
            s.push((time, sim.marble_world_state(i).0.y));
        }
    }

    /// Writes the plot as SVG (atomically).
    #[cfg(feature = "cli")]
    pub fn write_svg(&self, path: &Path, title: &str) -> io::Result<()> {
        use plotters::prelude::*;
        let (mut t1, mut y0, mut y1) = (0.0f32, f32::INFINITY, f32::NEG_INFINITY);
        for &(t, y) in self.series.iter().flatten() {
            t1 = t1.max(t);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !y0.is_finite() || !y1.is_finite() {
            (y0, y1) = (0.0, 1.0);
        }
        let pad = ((y1 - y0) * 0.05).max(1e-6);
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (900, 500)).into_drawing_area();
            let draw = || -> Result<(), Box<dyn std::error::Error + '_>> {
                root.fill(&WHITE)?;
                let mut chart = ChartBuilder::on(&root)
                    .caption(format!("{title}: marble heights"), ("sans-serif", 18))
                    .margin(10)
                    .x_label_area_size(40)
                    .y_label_area_size(60)
                    .build_cartesian_2d(0f32..t1.max(1e-6), (y0 - pad)..(y1 + pad))?;
                chart
                    .configure_mesh()
                    .x_desc("time (s)")
                    .y_desc("y (m)")
                    .draw()?;
                for (i, s) in self.series.iter().enumerate() {
                    chart.draw_series(LineSeries::new(s.iter().copied(), &Palette99::pick(i)))?;
                }
                root.present()?;
                Ok(())
            };
            draw().map_err(|e| io::Error::other(e.to_string()))?;
        }
        write_atomically(path, svg.as_bytes())
    }
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
