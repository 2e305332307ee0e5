//! `looming quality` as text: one line per scan, then the totals and the
//! diagnoses.

use std::fmt::Write as _;

use super::report::{Diagnosis, QualityReport, QualityTotals, ScanLine};

/// A fraction as a percentage with one decimal, "-" when there is none.
fn percent(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{:.1} %", 100.0 * v))
}

/// A rate in 1/s with four decimals, "-" when there is none.
fn per_s(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.4}"))
}

/// A signed rate in 1/s with three decimals, "-" when there is none.
pub(super) fn signed(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:+.3}"))
}

/// A length in metres with three decimals, "-" when there is none.
fn metres(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.3}"))
}

/// An angle in degrees, signed, with one decimal, "-" when there is none.
fn signed_deg(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:+.1}"))
}

impl QualityReport {
    /// The report as text: one line per scan, then the totals and diagnoses;
    /// on a log with several LiDARs, each sensor's in turn and a line per
    /// sensor at the end.
    pub fn to_text(&self) -> String {
        if self.sensors.is_empty() {
            return self.one_sensor_text();
        }
        let mut out = String::new();
        for sensor in &self.sensors {
            out.push_str(&sensor.one_sensor_text());
            out.push('\n');
        }
        let _ = writeln!(out, "sensors");
        for sensor in &self.sensors {
            let t = &sensor.totals;
            let codes: Vec<&str> = sensor.diagnoses.iter().map(|d| d.code.as_str()).collect();
            let _ = writeln!(
                out,
                "  {:<16} {} pairs, trusted {}, ground median |fused| {}{}",
                sensor.sensor.as_deref().unwrap_or("lidar"),
                t.pairs,
                t.trusted_fraction
                    .map_or("-".into(), |f| format!("{:.1} %", 100.0 * f)),
                t.ground_median_abs_fused_per_s
                    .map_or("-".into(), |v| format!("{v:.4} 1/s")),
                if codes.is_empty() {
                    String::new()
                } else {
                    format!("; {}", codes.join(", "))
                }
            );
        }
        out
    }

    fn one_sensor_text(&self) -> String {
        let mut out = String::new();
        let title = match &self.sensor {
            Some(sensor) => format!("{} (sensor {sensor})", self.input),
            None => self.input.clone(),
        };
        write_scans(&mut out, &title, &self.scans);
        let t = &self.totals;
        let _ = writeln!(out, "\ntotal");
        write_trust(&mut out, t);
        write_range(&mut out, t);
        write_ground(&mut out, t);
        write_motion(&mut out, t);
        write_diagnoses(&mut out, &self.diagnoses);
        out
    }
}

/// The title and the per-scan table.
fn write_scans(out: &mut String, input: &str, scans: &[ScanLine]) {
    let _ = writeln!(out, "quality of {input}");
    let _ = writeln!(
        out,
        "{:>5}  {:>22}  {:>8}  {:>11}  {:>11}  {:>7}  layout",
        "pair", "log time", "trusted", "ground |F|", "|D| static", "moving"
    );
    for s in scans {
        let _ = writeln!(
            out,
            "{:>5}  {:>22}  {:>8}  {:>11}  {:>11}  {:>7}  {}",
            s.index,
            crate::model::format_log_time(s.log_time_ns),
            percent(s.trusted_fraction),
            per_s(s.ground_median_abs_fused_per_s),
            per_s(s.median_abs_d_static_per_s),
            percent(s.moving_fraction),
            s.layout
        );
    }
}

/// Pairs, trusted points and cells, masks and layouts.
fn write_trust(out: &mut String, t: &QualityTotals) {
    let _ = writeln!(
        out,
        "  pairs                  {} ({} with quality figures, {} with ego velocity)",
        t.pairs, t.pairs_with_quality, t.pairs_with_ego_velocity
    );
    let _ = writeln!(
        out,
        "  trusted                {} of {} points ({} of {} occupied cells)",
        percent(t.trusted_fraction),
        t.points,
        percent(t.trusted_cell_fraction),
        t.cells
    );
    let masks: Vec<String> = t
        .masked_cells
        .named()
        .iter()
        .map(|(name, _)| {
            format!(
                "{name} {}",
                percent(t.masked_cell_fractions.get(*name).copied())
            )
        })
        .collect();
    let _ = writeln!(
        out,
        "  masked cells           {} (of occupied cells; a cell may carry several)",
        masks.join(", ")
    );
    let layouts: Vec<String> = t
        .layouts
        .iter()
        .map(|(layout, n)| format!("{layout} ({n} pairs)"))
        .collect();
    let _ = writeln!(out, "  layout                 {}", layouts.join("; "));
}

/// Range noise and per-laser range offsets over the rings.
fn write_range(out: &mut String, t: &QualityTotals) {
    let noise = &t.range_noise;
    let _ = writeln!(
        out,
        "  range noise per ring   min {} / median {} / max {} m ({} rings)",
        metres(noise.min_m),
        metres(noise.median_m),
        metres(noise.max_m),
        noise.rings
    );
    let offsets = &t.range_offsets;
    let offsets_text = match (offsets.rms_m, offsets.max_abs_m) {
        (Some(rms), Some(max)) if max > 0.0 => format!(
            "rms {rms:.3} / max {max:.3} m, taken out ({} rings)",
            offsets.rings
        ),
        (Some(_), _) => format!("none found ({} rings)", offsets.rings),
        _ => "-".into(),
    };
    let _ = writeln!(out, "  range offset per ring  {offsets_text}");
}

/// The static ground: its cells, pose, |fused| and its two halves.
fn write_ground(out: &mut String, t: &QualityTotals) {
    let _ = writeln!(
        out,
        "  ground                 {} cells, {} trusted static; sensor {} m above it, \
         roll {} deg, pitch {} deg; {} flagged moving",
        t.ground_cells,
        t.ground_trusted_static_cells,
        metres(t.ground_height_m),
        signed_deg(t.ground_roll_deg),
        signed_deg(t.ground_pitch_deg),
        percent(t.ground_moving_fraction),
    );
    let _ = writeln!(
        out,
        "  ground |fused|         median {} 1/s, p90 {} (trusted static ground, pooled)",
        per_s(t.ground_median_abs_fused_per_s),
        per_s(t.ground_p90_abs_fused_per_s)
    );
    let _ = writeln!(
        out,
        "  ground left / right    fused {} / {} 1/s, D {} / {} 1/s (medians of per-pair medians)",
        signed(t.ground_fused.left_median_per_s),
        signed(t.ground_fused.right_median_per_s),
        signed(t.ground_d.left_median_per_s),
        signed(t.ground_d.right_median_per_s),
    );
}

/// |D| on static cells, moving and threat cells, near-miss events.
fn write_motion(out: &mut String, t: &QualityTotals) {
    let _ = writeln!(
        out,
        "  |D| static             median {} 1/s (trusted static cells, pooled)",
        per_s(t.median_abs_d_static_per_s)
    );
    let _ = writeln!(
        out,
        "  moving                 {} of trusted cells; {} threat cells",
        percent(t.moving_fraction),
        t.threat_cells
    );
    let _ = writeln!(out, "  near-miss events       {}", t.near_miss_events);
}

fn write_diagnoses(out: &mut String, diagnoses: &[Diagnosis]) {
    let _ = writeln!(out, "\ndiagnosis");
    if diagnoses.is_empty() {
        let _ = writeln!(out, "  nothing to report");
    }
    for d in diagnoses {
        let _ = writeln!(out, "  - {}", d.message);
    }
}
