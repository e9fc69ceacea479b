//! Any bytes as a scene file, RON and JSON: parsing either refuses it with an error or gives a scene
//! that builds and steps (`bevy_marble::scene::fuzz_scene_file`, which the regression test
//! `tests/fuzz_corpus.rs` runs on every file of the corpus). A panic, a hang (libFuzzer's
//! `-timeout`) or an out-of-memory is a finding.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bevy_marble::scene::fuzz_scene_file(data);
});
