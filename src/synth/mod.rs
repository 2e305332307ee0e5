//! `looming synth`: deterministic synthetic drives with analytic ground truth.
//!
//! A scenario ([`scene`]) is simulated by a rolling-sweep LiDAR ([`sensor`]) ray
//! cast ([`geometry`]) against a scene moving with exact kinematics
//! ([`kinematics`]), or by several, each on its own ([`rig`]); `encode` turns
//! the result into ROS 2 CDR messages and truth records, written with the
//! same MCAP writer as `looming process`.

mod encode;
pub mod geometry;
pub mod kinematics;
pub mod rig;
pub mod scene;
pub mod sensor;
mod truth;

use std::path::PathBuf;
use std::time::Instant;

use crate::output::{OutputError, OutputOptions, OutputWriter, check_overwrite};

pub use encode::{CloudShape, Slot};
pub use encode::{START_NS, topics};
pub use scene::{CloudFrame, CloudLayout, Realism, Scenario, ScenarioError};
pub use truth::{TruthEvent, TruthScan};

/// What `looming synth` was asked for.
#[derive(Debug, Clone)]
pub struct SynthOptions {
    /// Built-in scenario name or a JSON file.
    pub scenario: String,
    pub output: PathBuf,
    pub seed: u64,
    /// Write only the drive from this time on (the scenario still starts at 0).
    pub start_s: Option<f64>,
    pub duration_s: Option<f64>,
    pub beams: Option<u16>,
    pub columns: Option<u32>,
    pub output_options: OutputOptions,
}

/// Overrides of the scenario's LiDAR beyond [`SynthOptions`] (`--layout`,
/// `--lidars`).
#[derive(Debug, Clone, Default)]
pub struct LidarOverrides {
    pub layout: Option<CloudLayout>,
    pub realism: Option<Realism>,
    /// LiDARs on the vehicle (1 to 3): the scenario's (the roof one) and the
    /// first `lidars - 1` of the `"left"`, `"right"` presets, replacing the
    /// scenario's `extra_lidars` [default: the scenario's].
    pub lidars: Option<u8>,
    /// The frame the clouds are published in (`--frame`) [default: the
    /// scenario's, the sensor's].
    pub frame: Option<CloudFrame>,
    /// Every LiDAR's clouds on one topic, tagged per point (`--one-topic`,
    /// [`rig::on_one_topic`]); needs several LiDARs.
    pub one_topic: bool,
}

/// What a synth run made.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SynthSummary {
    pub scenario: String,
    pub output: String,
    pub scans: u64,
    pub points: u64,
    pub messages: u64,
    pub events: Vec<TruthEvent>,
    pub output_bytes: u64,
    pub elapsed_s: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("internal error: {0}")]
    Internal(String),
}

/// The scenario with the command-line and LiDAR overrides applied, validated.
pub(crate) fn resolve_scenario_with(
    options: &SynthOptions,
    lidar: &LidarOverrides,
) -> Result<Scenario, SynthError> {
    let mut scenario = scene::load(&options.scenario)?;
    if let Some(layout) = lidar.layout {
        scenario.lidar.layout = layout;
    }
    if let Some(frame) = lidar.frame {
        scenario.lidar.cloud_frame = frame;
    }
    if let Some(realism) = &lidar.realism {
        scenario.lidar.realism = realism.clone();
    }
    if let Some(duration_s) = options.duration_s {
        scenario.duration_s = duration_s;
    }
    if let Some(beams) = options.beams {
        scenario.lidar.beams = beams;
    }
    if let Some(columns) = options.columns {
        scenario.lidar.columns = columns;
    }
    if let Some(lidars) = lidar.lidars {
        if !(1..=3).contains(&lidars) {
            return Err(ScenarioError::Invalid {
                name: scenario.name.clone(),
                what: format!("--lidars {lidars} must be 1, 2 or 3"),
            }
            .into());
        }
        scenario.extra_lidars = scene::ExtraLidar::presets_for(lidars);
    }
    scenario.validate()?;
    if let Some(start_s) = options.start_s
        && !(start_s.is_finite() && start_s >= 0.0 && start_s < scenario.duration_s)
    {
        return Err(ScenarioError::Invalid {
            name: scenario.name.clone(),
            what: format!(
                "--start {start_s} must be within the drive (0 to {} s)",
                scenario.duration_s
            ),
        }
        .into());
    }
    Ok(scenario)
}

/// Simulate the scenario and write the MCAP.
pub fn synthesize(options: &SynthOptions) -> Result<SynthSummary, SynthError> {
    synthesize_with(options, &LidarOverrides::default())
}

/// [`synthesize`] with the LiDAR overrides too.
pub fn synthesize_with(
    options: &SynthOptions,
    lidar: &LidarOverrides,
) -> Result<SynthSummary, SynthError> {
    let started = Instant::now();
    let scenario = resolve_scenario_with(options, lidar)?;
    check_overwrite(&options.output, options.output_options.force)?;
    let output_options = OutputOptions {
        profile: "ros2".into(),
        ..options.output_options.clone()
    };
    let mut writer = OutputWriter::create(&options.output, &output_options, &Default::default())?;
    let start_s = options.start_s.unwrap_or(0.0);
    let mut rig = rig::rig(&scenario, options.seed);
    if lidar.one_topic {
        let what = if rig.len() < 2 {
            Some("--one-topic merges several LiDARs: give --lidars 2 or 3")
        } else if scenario.lidar.layout != CloudLayout::RingTime {
            Some("--one-topic concatenates clouds of one point layout: ring-time (no --layout)")
        } else {
            None
        };
        if let Some(what) = what {
            return Err(ScenarioError::Invalid {
                name: scenario.name.clone(),
                what: what.into(),
            }
            .into());
        }
        rig::on_one_topic(&mut rig);
    }
    let schedule = rig::schedule(&rig, start_s);
    let mut log = encode::SynthLog::new(&mut writer, &rig, rig::first_stamp_s(&rig, start_s))?;
    let mut sequenced = encode::SequencedWriter::new(&mut writer);
    sequenced.write_metadata(&scenario, options.seed, start_s)?;
    // Simulation and encoding on one thread, writing (zstd) on this one.
    let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<encode::Encoded>>(2);
    let (points, events) =
        std::thread::scope(|scope| -> Result<(u64, Vec<TruthEvent>), SynthError> {
            // `tx` moves into the producer: the channel closes when it ends.
            let producer =
                scope.spawn(|| simulate(&scenario, &rig, &schedule, &mut log, options.seed, tx));
            for batch in rx {
                sequenced.write_all(batch)?;
            }
            producer
                .join()
                .map_err(|_| SynthError::Internal("the simulation thread panicked".into()))
        })?;
    let messages = sequenced.messages_written();
    let output_bytes = writer.finish()?;
    Ok(SynthSummary {
        scenario: scenario.name.clone(),
        output: options.output.display().to_string(),
        scans: schedule.len() as u64,
        points,
        messages,
        events,
        output_bytes,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// Simulate and encode the scans of `schedule` (LiDAR, scan index) in order,
/// each batch of messages to `tx`, then the planted near misses: the points
/// written and the events. The events are the vehicle's, timed from the roof
/// LiDAR's truth (the first of the rig: it sees all around).
fn simulate(
    scenario: &Scenario,
    rig: &[rig::RigLidar],
    schedule: &[(usize, u64)],
    log: &mut encode::SynthLog,
    seed: u64,
    tx: std::sync::mpsc::SyncSender<Vec<encode::Encoded>>,
) -> (u64, Vec<TruthEvent>) {
    let roof = &rig[0].world;
    let mut events = truth::EventTracker::new(scenario);
    let mut points = 0;
    for &(k, index) in schedule {
        let lidar = &rig[k];
        let scan = lidar.world.scan(index, lidar.seed);
        points += scan.points.len() as u64;
        if k == 0 {
            events.observe(roof, &scan);
        }
        log.encode_interval(roof, (k, lidar), &scan, seed);
        if tx.send(log.take()).is_err() {
            break;
        }
    }
    let events = events.finish(roof);
    log.encode_events(&events);
    let _ = tx.send(log.take());
    (points, events)
}

/// A scan pair straight from the simulator, with the exact LiDAR motion as its
/// motion series (no MCAP round trip): for benchmarks and engine tests.
pub fn simulated_pair(world: &sensor::World, index: u64, seed: u64) -> crate::model::ScanPair {
    use std::sync::Arc;

    use crate::model::{PairMotion, TimeSeries};
    let to_scan = |scan: &sensor::SimScan| crate::model::Scan {
        stamp_ns: encode::stamp_ns(scan.stamp_s),
        frame_id: encode::LIDAR_FRAME.into(),
        sensor_pose: nalgebra::Isometry3::identity(),
        points_m: scan.points.iter().map(|p| p.point_m).collect(),
        intensity: Some(scan.points.iter().map(|p| p.intensity).collect()),
        ring: Some(scan.points.iter().map(|p| p.ring).collect()),
        time_offset_s: Some(scan.points.iter().map(|p| p.time_s).collect()),
        source_index: (0..scan.points.len() as u32).collect(),
        input_point_count: scan.points.len() as u32,
        skipped_invalid_points: 0,
        organized: None,
        layout: crate::model::ScanLayout::from_fields(Some("ring"), Some("time")),
        sensor_ids: None,
    };
    let (previous, current) = (world.scan(index, seed), world.scan(index + 1, seed));
    let (from_s, to_s) = (
        previous.stamp_s - 0.05,
        current.stamp_s + 2.0 * world.period_s,
    );
    let steps = ((to_s - from_s) / 0.005) as usize;
    let (mut velocity, mut angular) = (Vec::new(), Vec::new());
    for k in 0..=steps {
        let t_s = from_s + k as f64 * 0.005;
        let lidar = world.lidar_state(t_s);
        velocity.push((
            encode::stamp_ns(t_s),
            lidar.to_lidar(&lidar.velocity_world_mps),
        ));
        angular.push((
            encode::stamp_ns(t_s),
            lidar.to_lidar(&lidar.angular_velocity_world_radps),
        ));
    }
    crate::model::ScanPair {
        dt_s: world.period_s,
        step_s: world.period_s,
        previous_log_time_ns: 0,
        current_log_time_ns: 0,
        index,
        motion: PairMotion::in_lidar_frame(
            Some(TimeSeries::new(velocity, 0.2)),
            Some(TimeSeries::new(angular, 0.2)),
        ),
        previous: Arc::new(to_scan(&previous)),
        current: Arc::new(to_scan(&current)),
    }
}
