//! `looming synth`: deterministic synthetic drives with analytic ground truth.
//!
//! A scenario ([`scene`]) is simulated by a rolling-sweep LiDAR ([`sensor`]) ray
//! cast ([`geometry`]) against a scene moving with exact kinematics
//! ([`kinematics`]); `encode` turns the result into ROS 2 CDR messages and
//! truth records, written with the same MCAP writer as `looming process`.

mod encode;
pub mod geometry;
pub mod kinematics;
pub mod scene;
pub mod sensor;
mod truth;

use std::path::PathBuf;
use std::time::Instant;

use crate::output::{OutputError, OutputOptions, OutputWriter, check_overwrite};

pub use encode::{CloudShape, Slot};
pub use encode::{START_NS, topics};
pub use scene::{CloudLayout, Realism, Scenario, ScenarioError};
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

/// Overrides of the scenario's LiDAR beyond [`SynthOptions`] (`--layout`).
#[derive(Debug, Clone, Default)]
pub struct LidarOverrides {
    pub layout: Option<CloudLayout>,
    pub realism: Option<Realism>,
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
    let world = sensor::World::new(scenario.clone());
    let first_scan = world.first_scan_at(options.start_s.unwrap_or(0.0));
    let mut log = encode::SynthLog::new(&mut writer, &world, first_scan)?;
    let mut sequenced = encode::SequencedWriter::new(&mut writer);
    sequenced.write_metadata(&scenario, options.seed, options.start_s.unwrap_or(0.0))?;
    // Simulation and encoding on one thread, writing (zstd) on this one.
    let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<encode::Encoded>>(2);
    let (points, events) =
        std::thread::scope(|scope| -> Result<(u64, Vec<TruthEvent>), SynthError> {
            let producer = scope.spawn(|| {
                let mut events = truth::EventTracker::new(&scenario);
                let mut points = 0;
                for index in first_scan..world.scan_count() {
                    let scan = world.scan(index, options.seed);
                    points += scan.points.len() as u64;
                    events.observe(&world, &scan);
                    log.encode_interval(&world, &scan, options.seed);
                    if tx.send(log.take()).is_err() {
                        break;
                    }
                }
                let events = events.finish(&world);
                log.encode_events(&events);
                let _ = tx.send(log.take());
                drop(tx);
                (points, events)
            });
            for batch in rx {
                sequenced.write_all(batch)?;
            }
            producer
                .join()
                .map_err(|_| SynthError::Internal("the simulation thread panicked".into()))
                .map(Ok)?
        })?;
    let messages = sequenced.messages_written();
    let output_bytes = writer.finish()?;
    Ok(SynthSummary {
        scenario: scenario.name.clone(),
        output: options.output.display().to_string(),
        scans: world.scan_count().saturating_sub(first_scan),
        points,
        messages,
        events,
        output_bytes,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// A scan pair straight from the simulator, with the exact LiDAR motion as its
/// motion series (no MCAP round trip): for benchmarks and engine tests.
pub fn simulated_pair(world: &sensor::World, index: u64, seed: u64) -> crate::model::ScanPair {
    use std::sync::Arc;

    use crate::model::{AngularSource, PairMotion, TimeSeries};
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
        previous_log_time_ns: 0,
        current_log_time_ns: 0,
        index,
        motion: PairMotion {
            velocity: Some(TimeSeries::new(velocity, 0.2)),
            angular: Some(TimeSeries::new(angular, 0.2)),
            angular_source: AngularSource::Imu,
            velocity_extrinsic: None,
            imu_extrinsic: None,
            velocity_unavailable: false,
            imu_unavailable: false,
            coverage_complete: true,
        },
        previous: Arc::new(to_scan(&previous)),
        current: Arc::new(to_scan(&current)),
    }
}
