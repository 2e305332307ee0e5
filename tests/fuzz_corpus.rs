//! Replays every committed fuzz input (the seeds in `fuzz/corpus/<target>/`
//! and the findings kept in `fuzz/regressions/<target>/`) through the same
//! entry points the fuzz targets call (`looming::fuzzing`): none may panic.
//! The fuzzing itself runs outside CI (`scripts/fuzz.sh`, `docs/fuzzing.md`).

use std::path::Path;

use looming::decode::MessageKind;
use looming::fuzzing;

/// A target's name and what it calls.
type Target = (&'static str, fn(&[u8]));

/// Each target with what it calls.
const TARGETS: &[Target] = &[
    ("mcap_indexed", |d| fuzzing::mcap_input(d, false)),
    ("mcap_linear", |d| fuzzing::mcap_input(d, true)),
    ("pointcloud2", |d| {
        fuzzing::message(MessageKind::PointCloud2, d)
    }),
    ("foxglove_pointcloud", |d| {
        fuzzing::message(MessageKind::FoxglovePointCloud, d)
    }),
    ("imu", |d| fuzzing::message(MessageKind::Imu, d)),
    ("twist", |d| fuzzing::message(MessageKind::TwistStamped, d)),
    ("odometry", |d| fuzzing::message(MessageKind::Odometry, d)),
    ("tf", |d| fuzzing::message(MessageKind::TfMessage, d)),
    ("kitti", fuzzing::kitti),
    ("scenario_json", fuzzing::scenario_json),
];

fn inputs(dir: &Path) -> Vec<Vec<u8>> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .map(|e| std::fs::read(e.unwrap().path()).unwrap())
        .collect()
}

#[test]
fn every_committed_fuzz_input_goes_through_without_a_panic() {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut total = 0;
    for (target, run) in TARGETS {
        let seeds = inputs(&fuzz.join("corpus").join(target));
        assert!(!seeds.is_empty(), "no seeds for {target}");
        let regressions = inputs(&fuzz.join("regressions").join(target));
        for input in seeds.iter().chain(&regressions) {
            run(input);
            // Every prefix of a seed too: truncation is the commonest damage.
            for cut in [
                1,
                input.len() / 3,
                input.len() / 2,
                input.len().saturating_sub(1),
            ] {
                run(&input[..cut.min(input.len())]);
            }
        }
        total += seeds.len() + regressions.len();
    }
    println!("{total} fuzz inputs replayed");
}

/// Every fuzz target in `fuzz/Cargo.toml` is replayed here.
#[test]
fn every_fuzz_target_is_replayed() {
    let manifest = include_str!("../fuzz/Cargo.toml");
    let declared: Vec<&str> = manifest
        .lines()
        .filter_map(|l| l.strip_prefix("name = \""))
        .filter_map(|rest| rest.strip_suffix('"'))
        .filter(|name| *name != "looming-fuzz")
        .collect();
    let replayed: Vec<&str> = TARGETS.iter().map(|(name, _)| *name).collect();
    assert_eq!(declared, replayed);
}
