//! A scan made ready for pairing: moved about its sensor's origin
//! (`origin`, `origin_track`; the scan held before it turned too when a
//! per-scan track starts) and its rings and times completed with the
//! period the stamps give (`engine::layout`).

use std::sync::Arc;

use super::{
    LAYOUT_PERIOD_RANGE_S, LAYOUT_PERIOD_WINDOW_LEN, PairerState, ScanPairer, median, origin,
};
use crate::engine::layout;
use crate::model::{OriginSource, Scan, StampNs};

impl ScanPairer {
    /// Moves the scan's points about its sensor's origin, found on the first
    /// scan with points ([`origin::locate`]) and followed over the log
    /// ([`origin_track`]); the warnings that gave.
    pub(super) fn place_sensor(&mut self, scan: &mut Scan, period_s: f64) -> Vec<String> {
        let sensor_frame = self.cfg.sensor_frame.as_deref();
        let placed = self
            .placement
            .place(scan, &self.transforms, sensor_frame, period_s);
        if let Some(found) = placed.found {
            // Placed at every scan from now on: the report's layout (its
            // first scan's, found before) says so.
            if let Some(layout) = self
                .stats
                .layout
                .as_mut()
                .filter(|_| found.source == OriginSource::RingsPerScan)
            {
                layout.origin = Some(found.clone());
            }
            self.stats.sensor_origin = Some(found);
        }
        if let Some(track) = self.placement.track_stats() {
            self.stats.sensor_track = Some(track.clone());
        }
        if let Some((stamp_ns, yaw_rad)) = placed.turn_previous {
            self.turn_previous(stamp_ns, yaw_rad);
        }
        placed.warnings
    }

    /// The last scan held, stamped `stamp_ns`, turned into the axes of a
    /// track that started with the scan after it (`origin_track`): the
    /// pair of the two is then made in axes that turn as the sensor does.
    fn turn_previous(&mut self, stamp_ns: StampNs, yaw_rad: f64) {
        let last = match &mut self.state {
            PairerState::HavePrevious(entry) | PairerState::PairPending { current: entry, .. } => {
                entry
            }
            PairerState::NoScan => return,
        };
        if last.stamp_ns() == stamp_ns {
            origin::turn(Arc::make_mut(&mut last.scan), yaw_rad);
        }
    }

    /// Recovers the scan's rings and times (`engine::layout::complete`) with
    /// the scan period (`period_s`, from the stamps), and records the layout.
    pub(super) fn complete_layout(&mut self, scan: &mut Scan, period_s: f64) {
        layout::complete(scan, period_s);
        let kind = format!(
            "{} / {}",
            scan.layout.rings.kind(),
            scan.layout.times.kind()
        );
        *self.stats.layout_kinds.entry(kind).or_default() += 1;
        if scan.layout.ring_field_dropped.is_some() {
            self.stats.ring_fields_dropped += 1;
        }
        if self.stats.layout.is_none() {
            self.stats.layout = Some(scan.layout.clone());
        }
    }

    /// The median of recent stamp differences (this scan's included), else
    /// the nominal period, else `layout::DEFAULT_PERIOD_S`; clamped to
    /// 0.02-0.5 s.
    pub(super) fn layout_period_s(&mut self, stamp_ns: StampNs) -> f64 {
        if let Some(last) = self.last_scan_stamp_ns {
            let dt_s = (stamp_ns - last) as f64 * 1e-9;
            if dt_s > 0.0 {
                if self.recent_scan_dts_s.len() == LAYOUT_PERIOD_WINDOW_LEN {
                    self.recent_scan_dts_s.pop_front();
                }
                self.recent_scan_dts_s.push_back(dt_s);
            }
        }
        self.last_scan_stamp_ns = Some(stamp_ns);
        let (lo, hi) = LAYOUT_PERIOD_RANGE_S;
        median(&self.recent_scan_dts_s)
            .or(self.nominal_period_override_s)
            .unwrap_or(layout::DEFAULT_PERIOD_S)
            .clamp(lo, hi)
    }
}
