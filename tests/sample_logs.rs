//! The committed sample logs are exactly what the generators make: regenerate
//! each in memory and compare bytes. Set `LOOMING_REGENERATE_SAMPLES=1` to
//! rewrite them after a deliberate change of a generator.

use std::path::Path;

fn check(file: &str, bytes: Vec<u8>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("sample_logs")
        .join(file);
    if std::env::var_os("LOOMING_REGENERATE_SAMPLES").is_some() {
        std::fs::write(&path, &bytes).unwrap();
    }
    let committed = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(bytes.len() <= 5_000_000, "{file} must stay under 5 MB");
    assert!(
        committed == bytes,
        "{file} differs from what its generator makes now; see sample_logs/README.md"
    );
}

#[test]
fn drive_ros2_matches_its_generator() {
    check(
        "drive-ros2.mcap",
        looming::fixtures::drive_log(&looming::fixtures::sample_drive_spec()),
    );
}
