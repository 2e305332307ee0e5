//! `looming batch` through the real CLI on a small fleet: two planted near
//! misses, a safe drive, a truncated log, a log without LiDAR and a file of
//! random bytes.

mod common;

use std::path::{Path, PathBuf};

use common::{looming, scratch, stderr};

fn sample(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("sample_logs")
        .join(name)
}

/// A log with an IMU channel and no LiDAR.
fn imu_only_log() -> Vec<u8> {
    let mut log = looming::testkit::LogBuilder::new(looming::testkit::Layout::indexed(), "ros2");
    log.schema(1, "sensor_msgs/msg/Imu", "ros2msg", b"");
    log.channel(1, 1, "/imu/data", "cdr");
    for i in 0..10u64 {
        log.message(
            1,
            i as u32,
            1_000 + i * 10_000_000,
            1_000 + i * 10_000_000,
            &[0; 8],
        );
    }
    log.finish()
}

/// The fleet folder: `day1/cut-in.mcap`, `day1/crossing.mcap`, `safe.mcap`,
/// `truncated.mcap`, `no-lidar.mcap`, `garbage.mcap`.
fn fleet(dir: &Path) -> PathBuf {
    let input = dir.join("in");
    std::fs::create_dir_all(input.join("day1")).unwrap();
    for name in ["cut-in.mcap", "crossing.mcap"] {
        std::fs::copy(sample(name), input.join("day1").join(name)).unwrap();
    }
    let safe = std::fs::read(sample("straight-road.mcap")).unwrap();
    std::fs::write(input.join("safe.mcap"), &safe).unwrap();
    std::fs::write(input.join("truncated.mcap"), &safe[..safe.len() * 2 / 3]).unwrap();
    std::fs::write(input.join("no-lidar.mcap"), imu_only_log()).unwrap();
    let garbage: Vec<u8> = (0..50_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(input.join("garbage.mcap"), garbage).unwrap();
    input
}

fn batch(input: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "batch",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    looming(&args)
}

fn fleet_entries(out: &Path) -> Vec<serde_json::Value> {
    serde_json::from_slice(&std::fs::read(out.join("fleet.json")).unwrap()).unwrap()
}

fn entry<'a>(entries: &'a [serde_json::Value], log: &str) -> &'a serde_json::Value {
    entries
        .iter()
        .find(|e| e["input"].as_str().unwrap().ends_with(log))
        .unwrap_or_else(|| panic!("{log} not in fleet.json"))
}

fn fleet_files(out: &Path) -> Vec<Vec<u8>> {
    [
        "fleet.json",
        "near_misses.jsonl",
        "near_misses.csv",
        "near_miss_events.jsonl",
        "report.html",
    ]
    .iter()
    .map(|f| std::fs::read(out.join(f)).unwrap())
    .collect()
}

#[test]
fn a_fleet_gets_a_status_per_log_and_its_near_misses_ranked() {
    let dir = scratch("batch-fleet");
    let input = fleet(&dir);
    let out = dir.join("out");
    let run = batch(&input, &out, &[]);
    assert_eq!(
        run.status.code(),
        Some(1),
        "the garbage log fails: {}",
        stderr(&run)
    );
    let entries = fleet_entries(&out);
    assert_eq!(entries.len(), 6);
    for log in ["cut-in.mcap", "crossing.mcap", "safe.mcap"] {
        assert_eq!(entry(&entries, log)["status"], "processed", "{log}");
    }
    assert!(out.join("logs/day1/cut-in.mcap").exists());
    let truncated = entry(&entries, "truncated.mcap");
    assert_eq!(truncated["status"], "processed");
    assert!(truncated["reason"].as_str().unwrap().contains("truncated"));
    let quality = &entry(&entries, "cut-in.mcap")["quality"];
    assert!(
        quality["trusted_fraction"].as_f64().unwrap() > 0.5,
        "{quality}"
    );
    assert!(quality["diagnoses"].is_array());
    let no_lidar = entry(&entries, "no-lidar.mcap");
    assert_eq!(no_lidar["status"], "skipped");
    assert!(
        no_lidar["reason"]
            .as_str()
            .unwrap()
            .contains("no LiDAR topic")
    );
    let garbage = entry(&entries, "garbage.mcap");
    assert_eq!(garbage["status"], "failed");
    assert!(
        garbage["reason"]
            .as_str()
            .unwrap()
            .contains("not an MCAP file")
    );

    let jsonl = std::fs::read_to_string(out.join("near_misses.jsonl")).unwrap();
    let ranked: Vec<serde_json::Value> = jsonl
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let logs: Vec<&str> = ranked.iter().map(|n| n["log"].as_str().unwrap()).collect();
    assert_eq!(logs.len(), 2, "{jsonl}");
    assert!(logs[0].ends_with("cut-in.mcap") && logs[1].ends_with("crossing.mcap"));
    let ttc = |n: &serde_json::Value| n["min_time_to_contact_s"].as_f64().unwrap();
    assert!(ttc(&ranked[0]) <= ttc(&ranked[1]));
    let csv = std::fs::read_to_string(out.join("near_misses.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    assert_pictures_exist(&out, &ranked);
    assert_foxglove_events(&out, &ranked);
    assert_report(&out);
}

/// Each ranked near miss names its two pictures, relative to OUT_DIR, and
/// they are PNG images of its log.
fn assert_pictures_exist(out: &Path, ranked: &[serde_json::Value]) {
    for near_miss in ranked {
        let log = Path::new(near_miss["log"].as_str().unwrap());
        let stem = log.file_name().unwrap().to_str().unwrap();
        for key in ["range_picture", "top_picture"] {
            let relative = near_miss[key].as_str().unwrap();
            assert!(
                relative.starts_with("logs/day1/") && relative.contains(stem),
                "{relative}"
            );
            let png = image::open(out.join(relative)).unwrap_or_else(|e| panic!("{relative}: {e}"));
            assert!(png.width() >= 256 && png.height() >= 64, "{relative}");
        }
    }
}

/// `near_miss_events.jsonl`: the ranking as `foxglove.Event` records.
fn assert_foxglove_events(out: &Path, ranked: &[serde_json::Value]) {
    let text = std::fs::read_to_string(out.join("near_miss_events.jsonl")).unwrap();
    let events: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(events.len(), ranked.len());
    for (event, near_miss) in events.iter().zip(ranked) {
        let metadata: std::collections::BTreeMap<&str, &str> = event["metadata"]
            .as_array()
            .unwrap()
            .iter()
            .map(|kv| (kv["key"].as_str().unwrap(), kv["value"].as_str().unwrap()))
            .collect();
        assert_eq!(metadata["log"], near_miss["log"].as_str().unwrap());
        assert_eq!(metadata["rank"], near_miss["rank"].to_string());
        assert_eq!(metadata["kind"], "near_miss");
        let seconds = |t: &serde_json::Value| {
            t["sec"].as_i64().unwrap() as f64 + t["nsec"].as_i64().unwrap() as f64 * 1e-9
        };
        assert!(seconds(&event["end_time"]) > seconds(&event["start_time"]));
    }
}

/// `report.html`: the ranked near misses with their pictures, a plot per
/// log with near misses, every log's status; nothing fetched from a network.
fn assert_report(out: &Path) {
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("Near misses in 6 logs"), "{html}");
    assert_eq!(html.matches("<img ").count(), 4);
    assert_eq!(
        html.matches("<svg ").count(),
        2,
        "a plot per log with near misses"
    );
    let cut_in = html.find("near-miss-1").unwrap();
    let crossing = html.find("near-miss-2").unwrap();
    assert!(html[cut_in..crossing].contains("cut-in.mcap"));
    assert!(html[crossing..].contains("crossing.mcap"));
    for status in [
        "processed",
        "skipped",
        "failed",
        "not an MCAP file",
        "truncated",
    ] {
        assert!(html.contains(status), "{status}");
    }
    assert_eq!(
        html.matches("http://").count(),
        html.matches("http://www.w3.org/2000/svg").count(),
        "no address but the SVG namespace"
    );
    assert!(!html.contains("https://"));
}

#[test]
fn a_second_run_redoes_nothing_and_writes_the_same_fleet_files() {
    let dir = scratch("batch-rerun");
    let input = fleet(&dir);
    let out = dir.join("out");
    batch(&input, &out, &["-q"]);
    let first = fleet_files(&out);
    let cut_in = std::fs::metadata(out.join("logs/day1/cut-in.mcap"))
        .unwrap()
        .modified()
        .unwrap();
    let run = batch(&input, &out, &[]);
    let text = stderr(&run);
    assert!(text.contains("0 processed, 6 up to date"), "{text}");
    assert_eq!(fleet_files(&out), first);
    let again = std::fs::metadata(out.join("logs/day1/cut-in.mcap"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(cut_in, again, "an up-to-date log is not rewritten");
    // --force redoes everything, with the same results.
    let run = batch(&input, &out, &["--force"]);
    assert!(
        stderr(&run).contains("4 processed, 0 up to date"),
        "{}",
        stderr(&run)
    );
    assert_eq!(fleet_files(&out)[1], first[1]);
}

#[test]
fn shards_split_the_fleet_and_merge_into_the_single_run_files() {
    let dir = scratch("batch-shards");
    let input = fleet(&dir);
    let single = dir.join("single");
    batch(&input, &single, &["-q"]);
    let out = dir.join("sharded");
    let mut done = Vec::new();
    for shard in ["0/2", "1/2"] {
        let run = batch(&input, &out, &["--shard", shard]);
        let text = stderr(&run);
        assert!(text.contains("--merge-only"), "{text}");
        done.push(text.lines().filter(|l| l.starts_with("  ")).count());
    }
    assert_eq!(
        done.iter().sum::<usize>(),
        6,
        "each log in exactly one shard: {done:?}"
    );
    assert!(
        !out.join("fleet.json").exists(),
        "a shard writes no fleet files"
    );
    let merged = looming(&["batch", "--merge-only", out.to_str().unwrap()]);
    assert_eq!(merged.status.code(), Some(1), "the garbage log failed");
    // The same tables as one run: the same bytes but for the output folder
    // and each run's seconds.
    let relative = |dir: &Path| -> Vec<String> {
        fleet_files(dir)
            .into_iter()
            .map(|bytes| {
                let text = String::from_utf8(bytes).unwrap();
                let text = text.replace(dir.to_str().unwrap(), "OUT");
                // Each run's seconds: a line of fleet.json, a row of the
                // report's log table.
                let lines = text.lines().filter(|l| {
                    !l.trim_start().starts_with("\"seconds\"") && !l.starts_with("<tr><td>")
                });
                lines.collect::<Vec<_>>().join("\n")
            })
            .collect()
    };
    assert_eq!(relative(&out), relative(&single));
    let bad = batch(&input, &dir.join("x"), &["--shard", "2/2"]);
    assert_eq!(bad.status.code(), Some(2));
}

#[test]
fn a_manifest_and_single_files_are_inputs_too() {
    let dir = scratch("batch-manifest");
    let input = fleet(&dir);
    std::fs::write(
        dir.join("list.txt"),
        "in/day1/cut-in.mcap\n# a comment\n\nin/safe.mcap\n",
    )
    .unwrap();
    let out = dir.join("out");
    let run = looming(&[
        "batch",
        dir.join("list.txt").to_str().unwrap(),
        input.join("day1/crossing.mcap").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--jobs",
        "2",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let entries = fleet_entries(&out);
    assert_eq!(entries.len(), 3);
    assert!(out.join("logs/cut-in.mcap").exists() && out.join("logs/crossing.mcap").exists());
}

#[test]
fn a_killed_batch_is_completed_by_the_next_run_without_partial_outputs() {
    let dir = scratch("batch-kill");
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    for i in 0..6 {
        std::fs::copy(sample("cut-in.mcap"), input.join(format!("drive-{i}.mcap"))).unwrap();
    }
    let out = dir.join("out");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_looming"))
        .args([
            "batch",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--jobs",
            "1",
            "-q",
        ])
        .spawn()
        .unwrap();
    // Kill it once the first log is done and before the last is.
    let first_record = out.join("logs/drive-0.mcap.batch.json");
    while !first_record.exists() {
        let ended = child.try_wait().unwrap();
        assert!(
            ended.is_none(),
            "the batch ended before its first record: {ended:?}"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let done_before = (0..6)
        .filter(|i| out.join(format!("logs/drive-{i}.mcap.batch.json")).exists())
        .count();
    assert!(done_before < 6, "the kill came after the last log");
    let run = batch(&input, &out, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let text = stderr(&run);
    assert!(
        text.contains(&format!(
            "{} processed, {done_before} up to date",
            6 - done_before
        )),
        "{text}"
    );
    let mut leftovers = Vec::new();
    files_below(&out, &mut leftovers);
    leftovers.retain(|name| name.ends_with(".tmp"));
    assert!(leftovers.is_empty(), "{leftovers:?}");
    assert_eq!(fleet_entries(&out).len(), 6);
}

fn files_below(dir: &Path, found: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files_below(&path, found);
        } else {
            found.push(path.display().to_string());
        }
    }
}

#[test]
fn list_names_the_logs_and_only_runs_some_of_them() {
    let dir = scratch("batch-only");
    let input = fleet(&dir);
    let out = dir.join("out");
    let listed = batch(&input, &out, &["--list"]);
    assert!(listed.status.success(), "{}", stderr(&listed));
    let logs: Vec<serde_json::Value> = String::from_utf8(listed.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(logs.len(), 6);
    assert_eq!(logs[0]["relative"], "day1/crossing.mcap");
    assert!(!out.exists(), "--list writes nothing");
    let run = batch(
        &input,
        &out,
        &["--only", "day1/cut-in.mcap", "--only", "safe.mcap"],
    );
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(out.join("logs/day1/cut-in.mcap.batch.json").exists());
    assert!(out.join("logs/safe.mcap.batch.json").exists());
    assert!(!out.join("logs/day1/crossing.mcap").exists());
    assert!(
        !out.join("fleet.json").exists(),
        "like a shard: no fleet files"
    );
    let merged = looming(&["batch", "--merge-only", out.to_str().unwrap()]);
    assert!(merged.status.success(), "{}", stderr(&merged));
    assert_eq!(fleet_entries(&out).len(), 2);
    let wrong = batch(&input, &out, &["--only", "nope.mcap"]);
    assert_eq!(wrong.status.code(), Some(2));
    assert!(stderr(&wrong).contains("nope.mcap"), "{}", stderr(&wrong));
}

/// The Chromium the report test drives: `$LOOMING_CHROMIUM`, else Debian's.
fn chromium() -> Option<PathBuf> {
    std::env::var_os("LOOMING_CHROMIUM")
        .map(PathBuf::from)
        .or_else(|| Some(PathBuf::from("/usr/bin/chromium")))
        .filter(|path| path.exists())
}

/// Run headless Chromium on `page` with `args`, killed after a minute.
fn run_chromium(
    browser: &Path,
    profile: &Path,
    args: &[&str],
    page: &Path,
) -> std::process::Output {
    let mut child = std::process::Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            &format!("--user-data-dir={}", profile.display()),
        ])
        .args(args)
        .arg(format!("file://{}", page.display()))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > std::time::Duration::from_secs(60) {
            let _ = child.kill();
            panic!("chromium did not finish in 60 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn the_report_opens_in_a_real_browser_with_every_picture() {
    let Some(browser) = chromium() else {
        eprintln!("skipped: no Chromium (apt-get install chromium, or set LOOMING_CHROMIUM)");
        return;
    };
    let dir = scratch("batch-browser");
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    for name in ["cut-in.mcap", "crossing.mcap", "straight-road.mcap"] {
        std::fs::copy(sample(name), input.join(name)).unwrap();
    }
    let out = dir.join("out");
    let run = batch(&input, &out, &["-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let page = out.join("report.html");
    // The page counts, once loaded, the pictures that did not load.
    let dom = run_chromium(&browser, &dir.join("profile-dom"), &["--dump-dom"], &page);
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert!(
        dom.contains("data-images=\"4\" data-broken-images=\"0\""),
        "{}",
        dom.lines()
            .find(|l| l.contains("<body"))
            .unwrap_or("no body")
    );
    let shot = dir.join("report.png");
    run_chromium(
        &browser,
        &dir.join("profile-shot"),
        &[
            "--window-size=1300,1700",
            &format!("--screenshot={}", shot.display()),
        ],
        &page,
    );
    let image = image::open(&shot).unwrap().to_rgb8();
    assert_eq!((image.width(), image.height()), (1300, 1700));
    // A page with its pictures drawn: the looming colours (red approaching)
    // are on it, not only text on white.
    let reddish = image
        .pixels()
        .filter(|p| p[0] > 180 && p[1] < 80 && p[2] < 80)
        .count();
    assert!(reddish > 100, "{reddish} red pixels in {}", shot.display());
}

#[test]
fn with_if_no_lidar_copy_a_log_without_lidar_is_copied_and_still_skipped() {
    let dir = scratch("batch-copy");
    let input = fleet(&dir);
    let out = dir.join("out");
    let run = batch(
        &input,
        &out,
        &["--if-no-lidar", "copy", "--only", "no-lidar.mcap"],
    );
    assert!(run.status.success(), "{}", stderr(&run));
    looming(&["batch", "--merge-only", out.to_str().unwrap()]);
    let entries = fleet_entries(&out);
    let no_lidar = entry(&entries, "no-lidar.mcap");
    assert_eq!(no_lidar["status"], "skipped");
    assert!(
        no_lidar["reason"]
            .as_str()
            .unwrap()
            .contains("every record copied"),
        "{no_lidar}"
    );
    let copy = std::fs::read(out.join("logs/no-lidar.mcap")).unwrap();
    let copied = common::read_all(&copy);
    assert_eq!(copied.messages.len(), 10);
}

#[test]
fn ctrl_c_stops_a_batch_cleanly_and_a_rerun_finishes_it() {
    let dir = scratch("batch-sigint");
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    for i in 0..6 {
        std::fs::copy(sample("cut-in.mcap"), input.join(format!("drive-{i}.mcap"))).unwrap();
    }
    let out = dir.join("out");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_looming"))
        .args([
            "batch",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--jobs",
            "1",
            "-q",
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let first_record = out.join("logs/drive-0.mcap.batch.json");
    let started = std::time::Instant::now();
    while !first_record.exists() {
        assert!(started.elapsed().as_secs() < 60, "no first record");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let run = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(run.status.code(), Some(130), "{text}");
    assert!(text.contains("interrupted"), "{text}");
    let mut files = Vec::new();
    files_below(&out, &mut files);
    assert!(!files.iter().any(|f| f.ends_with(".tmp")), "{files:?}");
    // Every log with a record has its whole output (a log interrupted after
    // its output was complete has no record yet: the next run redoes it).
    for i in 0..6 {
        let log = out.join(format!("logs/drive-{i}.mcap"));
        let record = out.join(format!("logs/drive-{i}.mcap.batch.json"));
        assert!(!record.exists() || log.exists(), "drive-{i}");
    }
    let done_before = (0..6)
        .filter(|i| out.join(format!("logs/drive-{i}.mcap.batch.json")).exists())
        .count();
    assert!(done_before < 6, "the interrupt came after the last log");
    let rerun = batch(&input, &out, &[]);
    assert!(rerun.status.success(), "{}", stderr(&rerun));
    assert!(
        stderr(&rerun).contains(&format!("{done_before} up to date")),
        "{}",
        stderr(&rerun)
    );
    assert_eq!(fleet_entries(&out).len(), 6);
}
