//! The layout the code promises (`docs/ARCHITECTURE.md`), checked on the
//! source trees of both crates: no file over 500 lines of non-test code, no
//! module importing a stage above it, no I/O in the pure modules, and no log
//! tooling among the core crate's dependencies.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Most lines of non-test code in one file (blank lines and `//` comments
/// not counted).
const MAX_CODE_LINES: usize = 500;

/// Each top-level module of the library and its layer: a module may use
/// modules of its own layer or below, never above. Siblings in a layer may
/// use each other only where listed in `SIBLING_USES`.
const LAYERS: &[(&str, u32)] = &[
    // Plain data every stage shares.
    ("model", 0),
    // The looming math.
    ("engine", 1),
    // Pure stages and readers of bytes into the model.
    ("objects", 2),
    ("pairing", 2),
    ("quality", 2),
    ("ros", 2),
    ("decode", 2),
    ("input", 2),
    ("budget", 2),
    // Near misses, judged on the objects in the swept path.
    ("events", 3),
    // The `/truth/*` layout (a point cloud of the ROS messages), and MCAP
    // writing.
    ("truth", 3),
    ("output", 3),
    // Our channels, built from the engine's and the detector's results.
    ("annotate", 4),
    // Which input topics to read (ours are never inputs).
    ("topics", 5),
    // `process`: the stages wired together; the shared decode-and-pair loop.
    ("pipeline", 6),
    // Commands and tools beside the pipeline.
    ("commands", 7),
    ("synth", 7),
    ("kitti", 7),
    // MCAP logs built in memory, for tests.
    ("testkit", 8),
    ("fuzzing", 8),
];

/// Uses between modules of the same layer that are part of the design.
const SIBLING_USES: &[(&str, &str)] = &[
    // The CDR and ROS 1 readers report the decoder's errors; the decoder
    // calls the readers.
    ("ros", "decode"),
    ("decode", "ros"),
    // Per-pair quality figures are measured on the ground the objects stand
    // on.
    ("quality", "objects"),
];

/// Modules that must do no I/O: the math and the plain data.
const PURE: &[&str] = &["model", "engine", "events", "objects", "pairing", "quality"];

/// What I/O looks like in code.
const IO_MARKERS: &[&str] = &[
    "std::fs",
    "std::io",
    "std::net",
    "std::process",
    "File::",
    "mcap::",
    "println!",
    "eprintln!",
    "print!(",
];

fn source_files(dir: &Path, files: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            source_files(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}

/// The source folders: the core crate's and this crate's.
fn src_dirs() -> [PathBuf; 2] {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    [root.join("crates/looming-core/src"), root.join("src")]
}

fn all_source_files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in src_dirs() {
        source_files(&dir, &mut files);
    }
    files
}

/// The file's code outside `#[cfg(test)]` items, without comment or blank
/// lines. Test modules in files of their own (`tests.rs`) count as tests.
fn non_test_code(path: &Path) -> Vec<String> {
    if path.file_name().is_some_and(|n| n == "tests.rs") {
        return Vec::new();
    }
    let text = std::fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut code = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim();
        if line.starts_with("#[cfg(test)]") {
            i = skip_item(&lines, i + 1);
            continue;
        }
        if !line.is_empty() && !line.starts_with("//") {
            code.push(line.to_owned());
        }
        i += 1;
    }
    code
}

/// The index after the item starting at `start` (after its attributes): a
/// `mod x;` line, or everything up to its braces' balance.
fn skip_item(lines: &[&str], start: usize) -> usize {
    let mut i = start;
    while i < lines.len() && lines[i].trim().starts_with("#[") {
        i += 1;
    }
    if i < lines.len() && lines[i].trim_end().ends_with(';') {
        return i + 1;
    }
    let mut depth = 0i64;
    let mut opened = false;
    while i < lines.len() {
        for c in lines[i].chars() {
            match c {
                '{' => {
                    depth += 1;
                    opened = true;
                }
                '}' => depth -= 1,
                _ => {}
            }
        }
        i += 1;
        if opened && depth <= 0 {
            break;
        }
    }
    i
}

/// The top-level module a file of `src/` belongs to (`None`: lib.rs,
/// main.rs and the binary's `cli/`).
fn top_module(path: &Path) -> Option<String> {
    let relative = src_dirs()
        .iter()
        .find_map(|dir| path.strip_prefix(dir).ok())?;
    let first = relative.components().next()?.as_os_str().to_str()?;
    let name = first.trim_end_matches(".rs");
    (!matches!(name, "lib" | "main" | "cli" | "test_rng")).then(|| name.to_owned())
}

fn layer(module: &str) -> u32 {
    LAYERS
        .iter()
        .find(|(name, _)| *name == module)
        .unwrap_or_else(|| panic!("module `{module}` has no layer in tests/structure.rs"))
        .1
}

/// `crate::x` paths used by the file's non-test code.
fn crate_uses(code: &[String]) -> Vec<String> {
    let mut used = Vec::new();
    for line in code {
        let mut rest = line.as_str();
        while let Some(at) = rest.find("crate::") {
            rest = &rest[at + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            used.push(name);
        }
    }
    used
}

#[test]
fn no_file_holds_more_than_500_lines_of_non_test_code() {
    let files = all_source_files();
    let too_long: BTreeMap<String, usize> = files
        .iter()
        .map(|path| (path.display().to_string(), non_test_code(path).len()))
        .filter(|(_, lines)| *lines > MAX_CODE_LINES)
        .collect();
    assert!(
        too_long.is_empty(),
        "over {MAX_CODE_LINES} lines: {too_long:?}"
    );
}

#[test]
fn no_module_uses_a_stage_above_it() {
    let files = all_source_files();
    let mut wrong = Vec::new();
    for path in &files {
        let Some(module) = top_module(path) else {
            continue;
        };
        for used in crate_uses(&non_test_code(path)) {
            if used == module || used == "test_rng" {
                continue;
            }
            let upward = layer(&used) > layer(&module);
            let sibling = layer(&used) == layer(&module)
                && !SIBLING_USES.contains(&(module.as_str(), used.as_str()));
            if upward || sibling {
                wrong.push(format!("{}: {module} uses {used}", path.display()));
            }
        }
    }
    wrong.dedup();
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn the_pure_modules_do_no_io() {
    let files = all_source_files();
    let mut wrong = Vec::new();
    for path in &files {
        let Some(module) = top_module(path) else {
            continue;
        };
        if !PURE.contains(&module.as_str()) {
            continue;
        }
        for line in non_test_code(path) {
            if let Some(marker) = IO_MARKERS.iter().find(|m| line.contains(*m)) {
                wrong.push(format!("{}: `{marker}` in `{line}`", path.display()));
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn the_core_crate_has_no_log_tooling_among_its_dependencies() {
    let manifest = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/looming-core/Cargo.toml"),
    )
    .unwrap();
    let dependencies = manifest
        .split("[dependencies]")
        .nth(1)
        .and_then(|rest| rest.split("\n[").next())
        .unwrap();
    let names: Vec<&str> = dependencies
        .lines()
        .filter_map(|line| line.split('=').next())
        .map(str::trim)
        .filter(|name| !name.is_empty() && !name.starts_with('#'))
        .collect();
    assert_eq!(names, ["nalgebra", "rayon", "serde", "thiserror"]);
}
