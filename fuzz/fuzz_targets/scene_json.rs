//! Any bytes as a JSON scene file, or (after a leading 0xFF byte) a scene built from the bytes
//! and written as JSON, so that meshes, height fields and compounds are reached at any depth
//! (`bevy_marble_fuzz::run`). A panic, a hang (libFuzzer's `-timeout`) or an out-of-memory
//! is a finding.
#![no_main]

use bevy_marble_fuzz::{Format, run};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| run(Format::Json, data));
