//! Prints the scene text a fuzz input stands for: `cargo run --bin built_scene -- ron|json FILE`.
//! A raw input prints as it is; a built one (first byte 0xFF) as the scene it builds, written
//! in that format: the file to keep in `corpus/scene_file/` once its finding is fixed.
use arbitrary::Unstructured;
use bevy_marble_fuzz::{BUILT, Format, scene, text};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(format), Some(path)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: built_scene ron|json FILE");
        std::process::exit(2);
    };
    let format = match format.as_str() {
        "ron" => Format::Ron,
        "json" => Format::Json,
        other => {
            eprintln!("format: {other:?} is neither ron nor json");
            std::process::exit(2);
        }
    };
    let data = std::fs::read(path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
    match data.split_first() {
        Some((&BUILT, rest)) => match scene(&mut Unstructured::new(rest)) {
            Ok(scene) => println!("{}", text(format, &scene)),
            Err(e) => {
                eprintln!("{path}: builds no scene: {e}");
                std::process::exit(1);
            }
        },
        _ => print!("{}", String::from_utf8_lossy(&data)),
    }
}
