//! The committed sample logs are exactly what `looming synth` makes with the
//! arguments in `sample_logs/README.md`: regenerate each and compare bytes.
//! Set `LOOMING_REGENERATE_SAMPLES=1` to rewrite them after a deliberate change.

use std::path::Path;

use looming::output::OutputOptions;
use looming::synth::{SynthOptions, synthesize};

/// (file, scenario, --start, --duration): 32 beams x 512 columns, zstd level 19.
/// Only these are compared: `ouster-os0-8.mcap` is a real recording (see
/// sample_logs/README.md), not generated.
const SAMPLES: &[(&str, &str, Option<f64>, f64)] = &[
    ("straight-road.mcap", "straight-road", None, 2.0),
    ("urban-turn.mcap", "urban-turn", None, 2.0),
    ("cut-in.mcap", "cut-in", Some(2.0), 4.0),
    ("crossing.mcap", "crossing", Some(1.0), 3.0),
];

#[test]
fn sample_logs_match_their_generator() {
    let dir = std::env::temp_dir().join(format!("looming-samples-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (file, scenario, start_s, duration_s) in SAMPLES {
        let generated = dir.join(file);
        let options = SynthOptions {
            scenario: scenario.to_string(),
            output: generated.clone(),
            seed: 1,
            start_s: *start_s,
            duration_s: Some(*duration_s),
            beams: Some(32),
            columns: Some(512),
            output_options: OutputOptions {
                compression_level: 19,
                force: true,
                ..OutputOptions::default()
            },
        };
        synthesize(&options).unwrap();
        let bytes = std::fs::read(&generated).unwrap();
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("sample_logs")
            .join(file);
        if std::env::var_os("LOOMING_REGENERATE_SAMPLES").is_some() {
            std::fs::write(&path, &bytes).unwrap();
        }
        assert!(
            bytes.len() <= 5_000_000,
            "{file} must stay under 5 MB ({} bytes)",
            bytes.len()
        );
        let committed = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(
            committed == bytes,
            "{file} differs from what `looming synth` makes now; see sample_logs/README.md"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
