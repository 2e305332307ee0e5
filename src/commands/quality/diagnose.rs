//! The findings drawn from a log's totals, each with a stable code
//! (`docs/quality.md`): ground patterns (split, offset, moving), missing
//! figures, laser offsets, low trust.

use super::report::{Diagnosis, GroundSides, QualityReport, QualityTotals};
use super::text::signed;
use super::{
    CONSISTENT_SHARE, GROUND_MOVING_LIMIT, GROUND_SIDE_THRESHOLD_PER_S, MIN_SIDE_CELLS,
    MIN_TRUSTED_FRACTION,
};

/// At least two pairs and `CONSISTENT_SHARE` of those judged.
fn consistent(count: u64, judged: u64) -> bool {
    count >= 2 && count as f64 >= CONSISTENT_SHARE * judged as f64
}

/// Ground patterns of one quantity: split (opposite signs) or offset.
fn ground_diagnoses(sides: &GroundSides, what: &str, code_suffix: &str, out: &mut Vec<Diagnosis>) {
    let n = sides.pairs_judged;
    let figures = format!(
        "{what} median {} 1/s on the left, {} on the right",
        signed(sides.left_median_per_s),
        signed(sides.right_median_per_s)
    );
    let t = GROUND_SIDE_THRESHOLD_PER_S;
    let split = |count: u64, left: &str, right: &str| Diagnosis {
        code: format!("ground_split{code_suffix}"),
        message: format!(
            "the ground reads {left} on the left and {right} on the right \
             ({figures}; beyond {t} 1/s with opposite signs in {count} of {n} pairs): \
             a tilted extrinsic (roll) or a wrong LiDAR frame: a rotation about the LiDAR's \
             x axis is wrong (a roll rate the gyro reports but the LiDAR does not have, or \
             misses: a gyro axis misassigned or biased, or an IMU extrinsic whose tilt turns \
             the yaw rate of turns into roll)"
        ),
    };
    if consistent(sides.left_approaching_right_receding, n) {
        out.push(split(
            sides.left_approaching_right_receding,
            "approaching",
            "receding",
        ));
    } else if consistent(sides.left_receding_right_approaching, n) {
        out.push(split(
            sides.left_receding_right_approaching,
            "receding",
            "approaching",
        ));
    }
    let offset = |count: u64, how: &str| Diagnosis {
        code: format!("ground_offset{code_suffix}"),
        message: format!(
            "the whole ground reads {how} ({figures}; beyond {t} 1/s with the same sign \
             on both sides in {count} of {n} pairs): points to a vertical velocity / \
             pitch error (extrinsic) or a time offset between the LiDAR and the motion source"
        ),
    };
    if consistent(sides.both_approaching, n) {
        out.push(offset(sides.both_approaching, "approaching"));
    } else if consistent(sides.both_receding, n) {
        out.push(offset(sides.both_receding, "receding"));
    }
}

/// What each mask bit usually means when it dominates.
fn mask_hint(name: &str) -> &'static str {
    match name {
        "no_previous" => {
            "the previous scan has no surface along the rays: scans far apart, fields of view \
             that do not overlap, or rows (rings) that differ between scans"
        }
        "edge" => {
            "plane fits see neighbours on other surfaces: a sparse or noisy sensor, a range \
             noise set too low for it, or rings assigned to the wrong rows"
        }
        "grazing" => "surfaces seen at grazing incidence: mostly far ground on a low mount",
        "no_ego" => {
            "the ego-motion prediction has no surface: the motion moves the previous scan off \
             the current rays (a wrong velocity, extrinsic or time base)"
        }
        "occlusion" => {
            "ranges change faster than any plausible motion: wrong per-point times or scan \
             period, wrong ego motion, or rings that do not match between scans"
        }
        _ => "",
    }
}

/// Per-laser range offsets worth saying (metres): RMS over the lasers, or
/// one laser's. The engine takes them out either way; above these the
/// sensor's own calibration deserves a look (KITTI's HDL-64E: 2.1 cm RMS).
const OFFSETS_RMS_LIMIT_M: f64 = 0.015;
const OFFSETS_MAX_LIMIT_M: f64 = 0.05;

/// Every finding, in report order; `no_quality` alone when there are no
/// figures to judge.
pub(super) fn diagnose(t: &QualityTotals) -> Vec<Diagnosis> {
    if t.pairs_with_quality == 0 {
        return vec![no_quality(t)];
    }
    let mut out = Vec::new();
    ground_pattern_diagnoses(t, &mut out);
    if t.ground_fused.pairs_judged == 0 {
        out.push(no_ground(t));
    }
    out.extend(ground_moving(t));
    out.extend(range_offsets(t));
    out.extend(low_trust(t));
    out
}

fn no_quality(t: &QualityTotals) -> Diagnosis {
    Diagnosis {
        code: "no_quality".into(),
        message: if t.pairs == 0 {
            "no scan pairs in the log".into()
        } else {
            "no pair carries quality figures (processed by an older looming, or no range \
             image could be made): re-process with `looming process --replace`"
                .into()
        },
    }
}

/// The ground patterns of the fused value, then those of D that the fused
/// value does not already show.
fn ground_pattern_diagnoses(t: &QualityTotals, out: &mut Vec<Diagnosis>) {
    ground_diagnoses(&t.ground_fused, "fused", "", out);
    // D on the ground is the static prediction's error itself: a pattern in it
    // alone (the fused value leaning on the prediction) is worth saying too.
    let mut in_d = Vec::new();
    ground_diagnoses(&t.ground_d, "D", "_d", &mut in_d);
    for d in in_d {
        let plain = d.code.trim_end_matches("_d");
        if !out.iter().any(|o| o.code == plain) {
            out.push(d);
        }
    }
}

fn no_ground(t: &QualityTotals) -> Diagnosis {
    Diagnosis {
        code: "no_ground".into(),
        message: format!(
            "no pair has {MIN_SIDE_CELLS} trusted ground cells on both sides: the ground \
             checks could not be made ({} ground cells, {} trusted)",
            t.ground_cells,
            t.ground_trusted_static_cells + t.ground_moving_cells
        ),
    }
}

fn ground_moving(t: &QualityTotals) -> Option<Diagnosis> {
    let fraction = t.ground_moving_fraction?;
    (fraction > GROUND_MOVING_LIMIT).then(|| Diagnosis {
        code: "ground_moving".into(),
        message: format!(
            "{:.1} % of the trusted ground is flagged moving (its D is significant): the \
             static-world prediction is wrong on the ground: check the ego motion (velocity, \
             extrinsic, times)",
            100.0 * fraction
        ),
    })
}

fn range_offsets(t: &QualityTotals) -> Option<Diagnosis> {
    let (Some(rms), Some(max)) = (t.range_offsets.rms_m, t.range_offsets.max_abs_m) else {
        return None;
    };
    (rms > OFFSETS_RMS_LIMIT_M || max > OFFSETS_MAX_LIMIT_M).then(|| Diagnosis {
        code: "range_offsets".into(),
        message: format!(
            "the lasers read ranges offset from each other by {:.1} cm RMS, up to {:.1} cm \
             (taken out by the engine, estimated from the scans): the sensor's per-laser \
             calibration is off by that much",
            100.0 * rms,
            100.0 * max
        ),
    })
}

fn low_trust(t: &QualityTotals) -> Option<Diagnosis> {
    let fraction = t.trusted_fraction?;
    (fraction < MIN_TRUSTED_FRACTION).then(|| {
        let dominant = t.dominant_mask.clone().unwrap_or_else(|| "none".into());
        let share = t
            .masked_cell_fractions
            .get(&dominant)
            .copied()
            .unwrap_or(0.0);
        Diagnosis {
            code: "low_trust".into(),
            message: format!(
                "only {:.1} % of the points are trusted (below {:.0} %); the dominant mask is \
                 `{dominant}` ({:.1} % of occupied cells): {}",
                100.0 * fraction,
                100.0 * MIN_TRUSTED_FRACTION,
                100.0 * share,
                mask_hint(&dominant)
            ),
        }
    })
}

/// A sensor whose latency sits this far from the other sensors' (log time
/// minus header stamp, medians, [`latency_s`]), or more, has its clock
/// named, s.
const SENSOR_CLOCK_OFFSET_S: f64 = 0.05;

/// On a log with several LiDARs, what sets one sensor apart: its stamps off
/// the others' (`sensor_clock`: a clock or a driver's stamping; its pairs
/// meet the motion samples at the wrong time) and no transform to the
/// vehicle (`sensor_extrinsic`, from `identity_assumed_pairs` per sensor:
/// its looming ignores its mounting and its near misses are not merged).
pub(super) fn diagnose_sensors(reports: &mut [QualityReport], identity_assumed_pairs: &[u64]) {
    let offsets: Vec<Option<f64>> = reports.iter().map(latency_s).collect();
    // The sensors' typical offset (the lower median: of two sensors, the one
    // stamped later against its log time is named).
    let typical = median_of(offsets.iter().flatten().copied().collect());
    for k in 0..reports.len() {
        let name = reports[k].sensor.clone().unwrap_or_default();
        if let (Some(own), Some(typical)) = (offsets[k], typical)
            && (own - typical).abs() >= SENSOR_CLOCK_OFFSET_S
        {
            reports[k].diagnoses.push(Diagnosis {
                code: "sensor_clock".into(),
                message: format!(
                    "sensor {name}'s scans are stamped {:.0} ms off the other sensors' \
                     (log time minus stamp {:.3} s against {:.3} s): its clock or its driver's \
                     stamping is off, so its pairs meet the motion samples at the wrong time",
                    (own - typical) * 1e3,
                    own,
                    typical
                ),
            });
        }
        let assumed = identity_assumed_pairs.get(k).copied().unwrap_or(0);
        if assumed > 0 {
            reports[k].diagnoses.push(Diagnosis {
                code: "sensor_extrinsic".into(),
                message: format!(
                    "sensor {name} has no transform to the motion sources' frame in {assumed} \
                     pairs (identity assumed): its mounting is ignored and its near misses \
                     stand apart from the other sensors'; give its transform in /tf_static"
                ),
            });
        }
    }
}

/// The median of `log time - stamp` over a report's pairs, s.
fn stamp_offset_s(report: &QualityReport) -> Option<f64> {
    median_of(
        report
            .scans
            .iter()
            .map(|s| (s.log_time_ns as i128 - i128::from(s.stamp_ns)) as f64 * 1e-9)
            .collect(),
    )
}

/// A sensor's latency from its stamps to its log times, s: the median of
/// `log time - stamp`, less one scan period where that is half a period or
/// more. A driver that stamps a scan when its sweep starts publishes it a
/// sweep later: a 10 Hz roof LiDAR so stamped reads 100 ms where a 20 Hz
/// side one reads 50, though both clocks agree (`synth --lidars 3`). A
/// clock a whole period off cannot be told from that convention.
fn latency_s(report: &QualityReport) -> Option<f64> {
    let offset_s = stamp_offset_s(report)?;
    let period_s = median_of(
        report
            .scans
            .windows(2)
            .map(|w| (w[1].stamp_ns - w[0].stamp_ns) as f64 * 1e-9)
            .filter(|dt_s| *dt_s > 0.0)
            .collect(),
    );
    Some(match period_s {
        Some(period_s) if offset_s >= 0.5 * period_s => offset_s - period_s,
        _ => offset_s,
    })
}

/// The lower median.
fn median_of(mut values: Vec<f64>) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    values.get(values.len().saturating_sub(1) / 2).copied()
}
