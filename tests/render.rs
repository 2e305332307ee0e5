//! `looming render`'s library entry on a synthetic drive (the cut-in at 32
//! beams x 512 columns): every channel's range image holds, pixel for pixel,
//! the colours of what the engine computes on the same pair; the top view of
//! the threat channel shows the sensor and the equal-looming circles; `--time`
//! picks the first pair logged at or after the time asked for.

use std::path::{Path, PathBuf};

use looming::annotate::colour;
use looming::commands::render::{
    RenderAt, RenderChannel, RenderError, RenderOptions, RenderView, render,
};
use looming::engine::{self, EngineConfig, NO_POINT, PairLooming};
use looming::input::{InputFile, InputOptions};
use looming::model::ScanPair;
use looming::output::OutputOptions;
use looming::synth::{SynthOptions, synthesize};

const ROWS_PER_BEAM: u32 = 4;

/// The cut-in from 2.8 s to 3.3 s (five scans, four pairs), 32 x 512, in a
/// fresh temporary directory.
fn synth_log() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut-in.mcap");
    synthesize(&SynthOptions {
        scenario: "cut-in".into(),
        output: path.clone(),
        seed: 7,
        start_s: Some(2.8),
        duration_s: Some(3.3),
        beams: Some(32),
        columns: Some(512),
        output_options: OutputOptions {
            force: true,
            ..OutputOptions::default()
        },
    })
    .unwrap();
    (dir, path)
}

/// Every pair of the log, by replay.
fn pairs(path: &Path) -> Vec<ScanPair> {
    let mut pairs = Vec::new();
    looming::pipeline::replay(
        path,
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| pairs.push(pair),
    )
    .unwrap();
    pairs
}

fn options(input: &Path, output: PathBuf, channel: RenderChannel, at: RenderAt) -> RenderOptions {
    RenderOptions {
        input: input.to_path_buf(),
        output,
        channel,
        at,
        view: RenderView::Range,
        row_height_px: ROWS_PER_BEAM,
        top_extent_m: 40.0,
        top_size_px: 800,
        force: false,
        scans: looming::pipeline::ScanOptions::default(),
        engine: looming::engine::EngineConfig::default(),
    }
}

fn rgb(c: colour::Rgba) -> [u8; 3] {
    [c[0], c[1], c[2]]
}

/// What a cell should show, written out from the channel's definition.
fn expected(looming: &PairLooming, channel: RenderChannel, cell: usize) -> [u8; 3] {
    let point = looming.image.point[cell];
    if point == NO_POINT {
        return rgb(colour::EMPTY);
    }
    let masked = looming.mask[cell] != 0;
    rgb(match channel {
        RenderChannel::Fused => {
            if masked {
                colour::MASKED
            } else {
                colour::looming(looming.fused[cell])
            }
        }
        RenderChannel::Lidar => {
            if looming.l_lidar[cell].is_finite() {
                colour::looming(looming.l_lidar[cell])
            } else {
                colour::MASKED
            }
        }
        RenderChannel::Ego => colour::looming(looming.l_ego[point as usize]),
        RenderChannel::Disagreement => {
            if masked {
                colour::MASKED
            } else {
                colour::looming(looming.disagreement[cell])
            }
        }
        RenderChannel::Threat => {
            if masked {
                colour::MASKED
            } else {
                colour::threat(looming.threat[cell])
            }
        }
    })
}

#[test]
fn the_range_image_of_every_channel_holds_the_engine_colours() {
    let (dir, log) = synth_log();
    let pair = pairs(&log).into_iter().find(|p| p.index == 2).unwrap();
    let looming = engine::compute(&pair, &EngineConfig::default()).unwrap();
    let (rows, cols) = (looming.geometry.rows, looming.geometry.cols);
    assert_eq!((rows, cols), (32, 512));
    for channel in [
        RenderChannel::Fused,
        RenderChannel::Lidar,
        RenderChannel::Ego,
        RenderChannel::Disagreement,
        RenderChannel::Threat,
    ] {
        let output = dir.path().join(format!("{channel:?}.png"));
        let summary = render(&options(&log, output.clone(), channel, RenderAt::Frame(2))).unwrap();
        assert_eq!(summary.pair_index, 2);
        assert_eq!(summary.stamp_ns, pair.current.stamp_ns);
        assert_eq!(summary.log_time_ns, pair.current_log_time_ns);
        let png = image::open(&output).unwrap().to_rgb8();
        assert_eq!(png.dimensions(), (cols as u32, rows as u32 * ROWS_PER_BEAM));
        assert_eq!(
            (summary.width_px, summary.height_px),
            png.dimensions(),
            "{channel:?}"
        );
        // Every cell, on each of its pixel rows: image row 0 is the highest beam.
        let mut coloured = 0;
        for row in 0..rows {
            for col in 0..cols {
                let cell = row * cols + col;
                let want = expected(&looming, channel, cell);
                let top = (rows - 1 - row) as u32 * ROWS_PER_BEAM;
                for y in top..top + ROWS_PER_BEAM {
                    assert_eq!(
                        png.get_pixel(col as u32, y).0,
                        want,
                        "{channel:?}: cell row {row} column {col}"
                    );
                }
                coloured += usize::from(want != rgb(colour::EMPTY) && want != rgb(colour::MASKED));
            }
        }
        assert!(
            coloured > 1000,
            "{channel:?}: only {coloured} coloured cells"
        );
        if channel == RenderChannel::Ego {
            // The road just ahead (lowest beam, forward column) approaches fast.
            let [r, g, b] = png
                .get_pixel(cols as u32 / 2, png.height() - 1)
                .0
                .map(i32::from);
            assert!(r > g + 80 && r > b + 80, "road ahead {:?}", [r, g, b]);
        }
    }
    // An existing output is refused without --force, replaced with it.
    let output = dir.path().join(format!("{:?}.png", RenderChannel::Fused));
    let mut again = options(&log, output, RenderChannel::Fused, RenderAt::Frame(2));
    let error = render(&again).unwrap_err();
    assert!(
        matches!(error, RenderError::Exists { .. }) && error.is_usage(),
        "{error}"
    );
    again.force = true;
    render(&again).unwrap();
}

#[test]
fn the_top_view_of_the_threat_channel_shows_the_sensor_and_the_zones() {
    let (dir, log) = synth_log();
    let pair = pairs(&log).into_iter().find(|p| p.index == 2).unwrap();
    let looming = engine::compute(&pair, &EngineConfig::default()).unwrap();
    let output = dir.path().join("top.png");
    let summary = render(&RenderOptions {
        view: RenderView::Top,
        ..options(
            &log,
            output.clone(),
            RenderChannel::Threat,
            RenderAt::Frame(2),
        )
    })
    .unwrap();
    let png = image::open(&output).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (800, 800));
    assert_eq!((summary.width_px, summary.height_px), (800, 800));
    assert_eq!(png.get_pixel(400, 400).0, [255, 255, 255]);
    // The high-threat circle: the sphere's section by z = 0, 10 px per metre,
    // x forward up, y left left; checked at its front and both sides.
    let spheres = looming.spheres.expect("the synthetic drive has a velocity");
    let high = spheres[2];
    let [cx, cy, cz] = high.center_m;
    assert!(cz.abs() < high.radius_m);
    let radius = (high.radius_m * high.radius_m - cz * cz).sqrt();
    assert!(radius > 2.0, "high-threat radius {radius} m");
    let high_colour = rgb(colour::threat(high.level));
    for angle in [
        0.0,
        std::f64::consts::FRAC_PI_2,
        3.0 * std::f64::consts::FRAC_PI_2,
    ] {
        let (x, y) = (cx + radius * angle.cos(), cy + radius * angle.sin());
        let (u, v) = (400.0 - y * 10.0, 400.0 - x * 10.0);
        assert_eq!(
            png.get_pixel(u.floor() as u32, v.floor() as u32).0,
            high_colour,
            "high-threat circle at angle {angle}"
        );
    }
    // The cloud is drawn: many pixels are neither background nor a circle.
    let drawn = png
        .pixels()
        .filter(|p| p.0 != [0, 0, 0] && p.0 != high_colour)
        .count();
    assert!(drawn > 5000, "{drawn} drawn pixels");
}

#[test]
fn time_picks_the_first_pair_logged_at_or_after_it_and_a_missing_frame_is_reported() {
    let (dir, log) = synth_log();
    let all = pairs(&log);
    assert!(all.len() >= 4, "{} pairs", all.len());
    let start_ns = InputFile::open(&log, InputOptions::default())
        .unwrap()
        .catalog()
        .start_ns
        .unwrap();
    let offset_s = |pair: &ScanPair| (pair.current_log_time_ns - start_ns) as f64 * 1e-9;
    // Just before pair 1's log time, and exactly at pair 3's.
    for (t, expected) in [(offset_s(&all[1]) - 0.01, 1), (offset_s(&all[3]), 3)] {
        let target = start_ns + (t * 1e9).round() as u64;
        let first = all
            .iter()
            .find(|p| p.current_log_time_ns >= target)
            .unwrap();
        assert_eq!(first.index, expected);
        let output = dir.path().join(format!("at-{t}.png"));
        let summary = render(&options(
            &log,
            output,
            RenderChannel::Fused,
            RenderAt::Time(t),
        ))
        .unwrap();
        assert_eq!(summary.pair_index, expected, "--time {t}");
        assert_eq!(summary.log_time_ns, first.current_log_time_ns);
    }
    let output = dir.path().join("missing.png");
    let error = render(&options(
        &log,
        output.clone(),
        RenderChannel::Fused,
        RenderAt::Frame(10_000),
    ))
    .unwrap_err();
    match &error {
        RenderError::NotFound { pairs, .. } => assert_eq!(*pairs, all.len() as u64),
        other => panic!("expected NotFound, got {other}"),
    }
    let message = error.to_string();
    assert!(
        message.contains("frame 10000")
            && message.contains(&format!("the log has {} pairs", all.len())),
        "{message}"
    );
    assert!(!output.exists());
}
