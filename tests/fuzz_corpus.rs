//! The fuzz corpus as a regression test: every file in `fuzz/corpus/scene_file/` (the
//! built-in scenes, hand-written edge cases, and every finding of `fuzz/`'s `scene_ron` and
//! `scene_json` targets once fixed) goes through the fuzz harness as RON and as JSON
//! (`scene::fuzz_scene_file`), on stable Rust: refused with an error, or built and stepped
//! with every marble finite or quarantined. Without a panic, and without a hang: each file
//! gets 60 s in the debug build (the whole corpus takes under a second; the hangs found
//! took minutes for 30 steps in release).

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

#[test]
fn every_corpus_file_is_refused_or_steps() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/scene_file");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.unwrap().path())
        .collect();
    files.sort();
    assert!(files.len() >= 12, "{} corpus files", files.len());
    for path in &files {
        let data = std::fs::read(path).unwrap();
        let (done, finished) = mpsc::channel();
        std::thread::spawn(move || {
            let run = std::panic::catch_unwind(|| bevy_marble::scene::fuzz_scene_file(&data));
            let _ = done.send(run.is_ok());
        });
        match finished.recv_timeout(Duration::from_secs(60)) {
            Ok(ok) => assert!(ok, "{} panicked", path.display()),
            Err(_) => panic!("{} still running after 60 s: a hang", path.display()),
        }
    }
}
