//! The speed tables and the scaling plot of the README, from criterion's saved results:
//!
//! ```text
//! cargo bench --bench step                       # this engine and the fused loop
//! (cd bench-rapier && cargo bench --bench rapier) # rapier3d on the same scenes
//! cargo run --release --example scaling_report    # tables on stdout, docs/scaling.svg
//! ```
//!
//! Reads the median time per step of every benchmark from `target/criterion` and
//! `bench-rapier/target/criterion`, divides by the number of marbles, prints a markdown
//! table per bench scene (ns per marble-step; rapier's time over this engine's), with
//! the pour at the pile bar (`pour_box_bar`, against rapier's default) and the labyrinth from where it is after 5 s (`labyrinth_steady`) as rows of its own, and
//! draws ns per marble-step against N, log–log, for both engines and the fused loop.

use std::path::Path;

use plotters::prelude::*;

const SIZES: [u64; 4] = [1_000, 10_000, 100_000, 1_000_000];

/// Median nanoseconds per marble-step of the benchmark at `dir/<id>/<n>`, if it ran.
fn per_marble(dir: &Path, id: &str, n: u64) -> Option<f64> {
    let path = dir.join(id).join(n.to_string()).join("new/estimates.json");
    let text = std::fs::read_to_string(path).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    Some(json["median"]["point_estimate"].as_f64()? / n as f64)
}

struct Series {
    label: &'static str,
    points: Vec<(u64, f64)>,
    colour: RGBColor,
    dashed: bool,
}

fn series(label: &'static str, dir: &Path, id: &str, colour: RGBColor, dashed: bool) -> Series {
    Series {
        label,
        points: SIZES
            .iter()
            .filter_map(|&n| per_marble(dir, id, n).map(|t| (n, t)))
            .collect(),
        colour,
        dashed,
    }
}

/// Rapier's time over this engine's, "–" when either did not run.
fn ratio(them: Option<f64>, us: Option<f64>) -> String {
    match (them, us) {
        (Some(t), Some(u)) => format!("{:.1}×", t / u),
        _ => "–".into(),
    }
}

fn cell(v: Option<f64>) -> String {
    v.map_or("–".into(), |t| format!("{t:.0}"))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let ours = Path::new("target/criterion");
    let rapier = Path::new("bench-rapier/target/criterion/rapier");
    // Title, this engine's id, rapier's id: (b) at the pile bar is this engine at
    // `scenes::POUR_BOX_BAR_SUBSTEPS` against rapier at its default.
    let scenes = [
        ("(a) walled board", "walled_board", "walled_board"),
        ("(b) pour box, 8 substeps", "pour_box", "pour_box"),
        (
            "(b) pour box, 3 substeps (the pile bar)",
            "pour_box_bar",
            "pour_box",
        ),
        ("(c) labyrinth", "labyrinth", "labyrinth"),
    ];
    println!(
        "ns per marble-step (median of one criterion run each; ratio = rapier / this engine)\n"
    );
    println!("| scene | N | this engine | rapier3d | ratio | fused loop |");
    println!("| --- | --- | --- | --- | --- | --- |");
    for (title, name, rapier_name) in scenes {
        for n in SIZES {
            let us = per_marble(&ours.join("marble_collisions"), name, n);
            let off = (name == "walled_board")
                .then(|| per_marble(ours, "walled_board", n))
                .flatten();
            let them = per_marble(rapier, rapier_name, n);
            let fused = (name == "walled_board")
                .then(|| per_marble(ours, "fused_loop", n))
                .flatten();
            if us.is_none() && them.is_none() && off.is_none() {
                continue;
            }
            let engine = match off {
                Some(off) => format!("{} ({off:.0} collisions off)", cell(us)),
                // A step of the pour at this size takes over a second, so criterion's
                // samples time a stretch of its first second, not the whole of it.
                None if name == "pour_box" && n >= 100_000 && us.is_some() => format!(
                    "{} (criterion times only part of the pour at this size: \
                     docs/performance.md, \"Why (b) grows\")",
                    cell(us)
                ),
                None => cell(us),
            };
            let ratio = ratio(them, us);
            println!(
                "| {title} | {n} | {engine} | {} | {ratio} | {} |",
                cell(them),
                cell(fused)
            );
        }
    }
    // (c) from where it is after 5 s (`scenes::labyrinth_steady`; not drawn).
    let rapier_steady = Path::new("bench-rapier/target/criterion");
    for n in SIZES {
        let us = per_marble(ours, "labyrinth_steady", n);
        let them = per_marble(rapier_steady, "rapier_labyrinth_steady", n);
        if us.is_none() && them.is_none() {
            continue;
        }
        let ratio = ratio(them, us);
        println!(
            "| (c) labyrinth after 5 s | {n} | {} | {} | {ratio} | – |",
            cell(us),
            cell(them)
        );
    }

    let all = [
        series(
            "this engine (a), collisions off",
            ours,
            "walled_board",
            BLUE,
            true,
        ),
        series(
            "this engine (a)",
            &ours.join("marble_collisions"),
            "walled_board",
            BLUE,
            false,
        ),
        series(
            "this engine (b)",
            &ours.join("marble_collisions"),
            "pour_box",
            GREEN,
            false,
        ),
        series(
            "this engine (c)",
            &ours.join("marble_collisions"),
            "labyrinth",
            MAGENTA,
            false,
        ),
        series("rapier3d (a)", rapier, "walled_board", RED, false),
        series(
            "rapier3d (b)",
            rapier,
            "pour_box",
            RGBColor(200, 120, 0),
            false,
        ),
        series(
            "rapier3d (c)",
            rapier,
            "labyrinth",
            RGBColor(120, 0, 0),
            false,
        ),
        series("fused loop (a)", ours, "fused_loop", BLACK, true),
    ];
    let (lo, hi) = all
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .fold((f64::MAX, 0.0f64), |(lo, hi), t| (lo.min(t), hi.max(t)));
    if hi <= 0.0 {
        return Err("no criterion results found: run the benches first".into());
    }
    let out = Path::new("docs/scaling.svg");
    std::fs::create_dir_all("docs")?;
    let root = SVGBackend::new(out, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "ns per marble-step against N (one thread, dt = scene dt)",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (500.0f64..2_000_000.0).log_scale(),
            (lo * 0.5..hi * 2.0).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("marbles")
        .y_desc("ns per marble-step")
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()?;
    for s in &all {
        if s.points.is_empty() {
            continue;
        }
        let pts: Vec<(f64, f64)> = s.points.iter().map(|&(n, t)| (n as f64, t)).collect();
        let style = ShapeStyle::from(&s.colour).stroke_width(if s.dashed { 1 } else { 2 });
        let colour = s.colour;
        chart
            .draw_series(LineSeries::new(pts.clone(), style))?
            .label(s.label)
            .legend(move |(x, y)| PathElement::new([(x - 8, y), (x + 8, y)], colour));
        chart.draw_series(
            pts.into_iter()
                .map(|p| Circle::new(p, 3, s.colour.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
