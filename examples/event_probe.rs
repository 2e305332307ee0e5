//! Run the near-miss detector over a synthetic scenario and print, per pair,
//! the clusters near the ego path (any size, corridor widened to 2.5 m), then
//! the events found and the planted truth:
//! `cargo run --release --example event_probe -- SCENARIO BEAMS COLUMNS [START END]`
//! (`PROBE_SEED=N` sets the noise seed, default 7).

use looming::engine::{EngineCache, EngineConfig, compute_with_cache};
use looming::events::{
    Corridor, EventConfig, EventDetector, FacingLooming, PairFrame, default_min_cells, hot_clusters,
};
use looming::output::OutputOptions;
use looming::synth::{SynthOptions, synthesize};

/// `looming synth` stamps its drives from here.
const START_NS: i64 = 1_700_000_000_000_000_000;

/// Writes the scenario named by the arguments to `path`; returns its summary.
fn synthesize_from_args(args: &[String], path: &std::path::Path) -> looming::synth::SynthSummary {
    let arg = |i: usize| args.get(i).map(|a| a.parse::<f64>().expect("a number"));
    let scenario = args.get(1).cloned().unwrap_or_else(|| "cut-in".into());
    synthesize(&SynthOptions {
        scenario,
        output: path.to_path_buf(),
        seed: std::env::var("PROBE_SEED").map_or(7, |s| s.parse().expect("a seed")),
        start_s: arg(4),
        duration_s: arg(5),
        beams: arg(2).map(|b| b as u16),
        columns: arg(3).map(|c| c as u32),
        output_options: OutputOptions {
            force: true,
            ..OutputOptions::default()
        },
    })
    .unwrap()
}

/// One cluster near the ego path, as a bracketed line item.
fn describe_cluster(c: &looming::events::Cluster) -> String {
    let (az, el) = c.bearing_deg();
    format!(
        "[{} cells L {:.2} r {:.1} az {:.1} el {:.1} lateral {:.2} moving {}]",
        c.cells, c.looming_per_s, c.range_m, az, el, c.lateral_offset_m, c.moving_cells
    )
}

/// Seconds from the drive's start to `stamp_ns`.
fn drive_time_s(stamp_ns: i64) -> f64 {
    (stamp_ns - START_NS) as f64 * 1e-9
}

fn print_event(e: &looming::events::NearMissEvent) {
    println!(
        "EVENT {} {:.2}-{:.2} s pairs {} min TTC {:.2} range {:.1} az {:.1} moving {:.2} cells {}",
        e.id,
        drive_time_s(e.start_ns),
        drive_time_s(e.end_ns),
        e.hot_pairs,
        e.min_time_to_contact_s,
        e.peak.range_m,
        e.peak.azimuth_deg,
        e.moving_fraction,
        e.max_cluster_cells
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = std::env::temp_dir().join(format!("looming-event-probe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("drive.mcap");
    let summary = synthesize_from_args(&args, &path);
    for e in &summary.events {
        println!(
            "TRUTH {} {:.2}-{:.2} s min TTC {:.2}",
            e.label, e.start_s, e.end_s, e.min_time_to_contact_s
        );
    }
    let engine = EngineConfig::default();
    let config = EventConfig::default();
    // The clusters printed are sought a metre wider than the events.
    let wide = EventConfig {
        path_margin_m: config.path_margin_m + 1.0,
        ..config.clone()
    };
    let mut tracker = looming::objects::ObjectTracker::default();
    let object_config = looming::objects::ObjectConfig::default();
    let mut cache = EngineCache::default();
    let mut detector = EventDetector::new(config.clone());
    let mut events = Vec::new();
    looming::pipeline::replay(
        &path,
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            let Some(mut looming) = compute_with_cache(&pair, &engine, &mut cache) else {
                return;
            };
            // As `process` does: the objects, tracked, fed back into the cells.
            let (objects, _) = looming::objects::PairObjects::find_tracked_fused(
                &pair.current,
                &mut looming,
                (&object_config, &engine.threat_ttc_s),
                &mut tracker,
                pair.step_s,
            );
            let t_s = drive_time_s(pair.current.stamp_ns);
            let stamp = pair.current.stamp_ns;
            let corridor = Corridor::new(
                pair.motion.velocity_at(stamp),
                pair.motion.angular_velocity_at(stamp),
                wide.corridor_half_width_m(),
            );
            let facing = FacingLooming::of(&looming, &wide);
            let clusters: Vec<String> = hot_clusters(
                &looming,
                (&pair.current, Some(&objects)),
                (&corridor, &facing),
                &wide,
                2,
            )
            .iter()
            .map(describe_cluster)
            .collect();
            if !clusters.is_empty() {
                let min_cells = default_min_cells(&looming.geometry);
                println!("{t_s:5.2} (min {min_cells}) {}", clusters.join(" "));
            }
            events.extend(detector.observe(&PairFrame {
                pair: &pair,
                looming: &looming,
                objects: Some(&objects),
            }));
        },
    )
    .unwrap();
    events.extend(detector.finish());
    for e in &events {
        print_event(e);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
