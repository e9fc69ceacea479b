//! The replay page in a real browser: it loads without errors, draws, and scrubbed to the
//! last frame places every marble where the CSV says. Runs when `MARBLE_BROWSER` names a
//! Chromium (`.ci/run` installs Debian's and sets it); without it the test says so and
//! passes.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use bevy_marble::output::{speed_colour, write_csv_rows};
use bevy_marble::prelude::*;
use bevy_marble::replay::{Recorder, ReplayOptions};
use bevy_marble::scenes;

/// Chromium's flags for a closed machine: headless, no sandbox (root in CI), no GPU, no
/// background network traffic, a fresh profile.
fn chromium(browser: &str, profile: &std::path::Path) -> Command {
    let mut c = Command::new(browser);
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--hide-scrollbars",
        "--window-size=1400,900",
        "--virtual-time-budget=5000",
    ])
    .arg(format!("--user-data-dir={}", profile.display()))
    .stdin(Stdio::null());
    c
}

/// Runs `c`, killing it after `limit`; its stdout.
fn run(mut c: Command, limit: Duration) -> String {
    let mut child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("the browser starts");
    let mut stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stdout, &mut s).unwrap();
        s
    });
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "the browser failed: {status}");
            break;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("the browser took more than {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    reader.join().unwrap()
}

fn unescape(html: &str) -> String {
    html.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&amp;", "&")
}

#[test]
fn the_page_loads_draws_and_places_the_marbles_where_the_csv_says() {
    let Some(browser) = std::env::var_os("MARBLE_BROWSER") else {
        eprintln!("skipped: set MARBLE_BROWSER to a Chromium to run the replay page in a browser");
        return;
    };
    let browser = browser.to_string_lossy().into_owned();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("replay_browser");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();

    // Five marbles dropped onto the tilting labyrinth for 0.6 s.
    let mut scene = scenes::labyrinth(5);
    scene.duration = 0.6;
    let steps = scene.default_steps();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mut recorder = Recorder::new(&mut sim, steps, ReplayOptions::default());
    for step in 1..=steps {
        sim.step();
        recorder.after_step(&sim, step);
    }
    let rec = recorder.finish("browser test");
    let page = dir.join("replay.html");
    let mut html = Vec::new();
    rec.write_html(&mut html).unwrap();
    std::fs::write(&page, html).unwrap();
    let mut csv = Vec::new();
    write_csv_rows(&mut csv, &sim, steps, scene.dt).unwrap();
    let csv: Vec<[f32; 6]> = String::from_utf8(csv)
        .unwrap()
        .lines()
        .map(|l| {
            let f: Vec<f32> = l.split(',').skip(3).map(|x| x.parse().unwrap()).collect();
            std::array::from_fn(|k| f[k])
        })
        .collect();

    let url = format!("file://{}", page.display());
    let mut dump = chromium(&browser, &dir.join("profile"));
    dump.arg("--dump-dom").arg(format!("{url}#selftest"));
    let dom = run(dump, Duration::from_secs(120));
    let open = r#"<pre id="selftest">"#;
    let start = dom.find(open).expect("the page's self-test element") + open.len();
    let end = start + dom[start..].find("</pre>").unwrap();
    let report: serde_json::Value = serde_json::from_str(&unescape(&dom[start..end]))
        .unwrap_or_else(|e| panic!("the page reported no result ({e}): {}", &dom[start..end]));

    assert_eq!(
        report["errors"],
        serde_json::json!([]),
        "errors in the page"
    );
    assert_eq!(report["frames"].as_u64().unwrap() as usize, rec.frames());
    for view in ["top", "persp"] {
        let drawn = report["drawn"][view].as_f64().unwrap();
        assert!(drawn > 0.005, "the {view} view is blank ({drawn})");
    }
    let v = &report["topView"];
    let (vx, vz, scale) = (
        v["x"].as_f64().unwrap(),
        v["z"].as_f64().unwrap(),
        v["scale"].as_f64().unwrap(),
    );
    let (w, h) = (v["width"].as_f64().unwrap(), v["height"].as_f64().unwrap());
    let vmax = report["vmax"].as_f64().unwrap() as f32;
    let marbles = report["marbles"].as_array().unwrap();
    assert_eq!(marbles.len(), csv.len());
    for (i, (m, row)) in marbles.iter().zip(&csv).enumerate() {
        // The state the page shows at the last frame is the CSV's, to the bit.
        let state: Vec<f32> = m["state"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect();
        assert_eq!(state, row.to_vec(), "marble {i}");
        // It is drawn where the top view's map puts the CSV's position…
        let screen: Vec<f64> = m["screen"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let want = [
            w / 2.0 + (row[0] as f64 - vx) * scale,
            h / 2.0 + (row[2] as f64 - vz) * scale,
        ];
        assert!(
            (screen[0] - want[0]).abs() < 1e-6 && (screen[1] - want[1]).abs() < 1e-6,
            "marble {i} at {screen:?}, want {want:?}"
        );
        assert!(
            (0.0..w).contains(&screen[0]) && (0.0..h).contains(&screen[1]),
            "marble {i} in view"
        );
        // …in the colour of its speed (the same scale as the plots').
        let pixel: Vec<u8> = m["pixel"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as u8)
            .collect();
        let speed = glam::Vec3::new(row[3], row[4], row[5]).length();
        let colour = speed_colour(speed / vmax);
        for c in 0..3 {
            assert!(
                (pixel[c] as i32 - colour[c] as i32).abs() <= 2,
                "marble {i}: pixel {pixel:?}, its speed's colour {colour:?}"
            );
        }
    }

    // Hovering over marble 0 shows its index, position and velocity (4 decimals).
    let hover = report["hover"].as_str().expect("a tooltip over marble 0");
    assert!(hover.starts_with("marble 0\n"), "{hover:?}");
    let numbers = |label: &str| -> Vec<f32> {
        let line = hover.lines().find(|l| l.starts_with(label)).expect(label);
        line.split_whitespace()
            .filter_map(|w| w.parse().ok())
            .collect()
    };
    let shown = [numbers("position"), numbers("velocity")].concat();
    assert_eq!(shown.len(), 6, "{hover:?}");
    for (k, (s, v)) in shown.iter().zip(&csv[0]).enumerate() {
        // Rounded to 4 decimals.
        assert!(
            (s - v).abs() <= 5e-5 + 1e-7,
            "component {k}: shown {s}, the CSV's {v}"
        );
    }

    // A screenshot of the page half way through, for people to look at.
    let shot = dir.join("replay.png");
    let mut capture = chromium(&browser, &dir.join("profile"));
    capture
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("{url}#t=0.3"));
    run(capture, Duration::from_secs(120));
    let size = std::fs::metadata(&shot).map(|m| m.len()).unwrap_or(0);
    assert!(size > 10_000, "a screenshot of {size} bytes");
    eprintln!("screenshot: {}", shot.display());
}
