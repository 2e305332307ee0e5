//! [`Scenario::validate`]: what serde cannot check.

use super::{LidarSpec, Profile, ROOF_NAME, Scenario, ScenarioError, StaticObject};

impl Scenario {
    /// Check what serde cannot: positive sizes and rates, actor motion given once.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        self.check_rates()?;
        self.check_lidar_spec(&self.lidar, "lidar")?;
        self.check_extra_lidars()?;
        self.check_ego_and_events()?;
        self.check_static_objects()?;
        self.check_actors()
    }

    fn invalid(&self, what: String) -> ScenarioError {
        ScenarioError::Invalid {
            name: self.name.clone(),
            what,
        }
    }

    fn positive(&self, value: f64, what: &str) -> Result<(), ScenarioError> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(self.invalid(format!("{what} must be a positive number, got {value}")))
        }
    }

    /// The drive's length and every sensor's rate.
    fn check_rates(&self) -> Result<(), ScenarioError> {
        self.positive(self.duration_s, "duration_s")?;
        self.positive(self.lidar.rate_hz, "lidar.rate_hz")?;
        self.positive(self.lidar.max_range_m, "lidar.max_range_m")?;
        self.positive(self.imu.rate_hz, "imu.rate_hz")?;
        self.positive(self.velocity_rate_hz, "velocity_rate_hz")
    }

    /// Beams, columns, elevations and the realism fractions of the LiDAR
    /// `what` (`lidar`, `extra_lidars[i].lidar`).
    fn check_lidar_spec(&self, lidar: &LidarSpec, what: &str) -> Result<(), ScenarioError> {
        if lidar.beams < 1 || lidar.columns < 8 {
            return Err(self.invalid(format!("{what} needs at least 1 beam and 8 columns")));
        }
        if lidar.elevation_min_deg >= lidar.elevation_max_deg && lidar.beams > 1 {
            return Err(self.invalid(format!(
                "{what}.elevation_min_deg must be below elevation_max_deg"
            )));
        }
        let realism = &lidar.realism;
        for (value, field) in [
            (realism.dropout_fraction, "dropout_fraction"),
            (realism.speck_fraction, "speck_fraction"),
        ] {
            if !(0.0..=0.25).contains(&value) {
                return Err(self.invalid(format!(
                    "{what}.realism.{field} must be within 0 to 0.25, got {value}"
                )));
            }
        }
        Ok(())
    }

    /// The LiDARs beside the roof one: names usable as frames and topics and
    /// unique, rates, the spec, a phase within the first period.
    fn check_extra_lidars(&self) -> Result<(), ScenarioError> {
        let mut names = std::collections::BTreeSet::from(["lidar", ROOF_NAME]);
        for (i, extra) in self.extra_lidars.iter().enumerate() {
            let what = format!("extra_lidars[{i}]");
            let name = extra.name.as_str();
            let well_formed = name.len() <= 64
                && name.starts_with(|c: char| c.is_ascii_lowercase())
                && name
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
            if !well_formed {
                return Err(self.invalid(format!(
                    "{what}.name `{name}` must be lower-case letters, digits and `_`, \
                     starting with a letter"
                )));
            }
            if !names.insert(name) {
                return Err(self.invalid(format!(
                    "{what}.name `{name}` is taken (`lidar`, `{ROOF_NAME}` and every \
                     extra LiDAR's name must differ)"
                )));
            }
            self.positive(extra.lidar.rate_hz, &format!("{what}.lidar.rate_hz"))?;
            self.positive(
                extra.lidar.max_range_m,
                &format!("{what}.lidar.max_range_m"),
            )?;
            self.check_lidar_spec(&extra.lidar, &format!("{what}.lidar"))?;
            let period_s = 1.0 / extra.lidar.rate_hz;
            if !(extra.phase_s.is_finite() && extra.phase_s >= 0.0 && extra.phase_s < period_s) {
                return Err(self.invalid(format!(
                    "{what}.phase_s must be within 0 to its period ({period_s} s), got {}",
                    extra.phase_s
                )));
            }
        }
        Ok(())
    }

    /// The ego's profiles and the near-miss timing.
    fn check_ego_and_events(&self) -> Result<(), ScenarioError> {
        let invalid = |what: String| self.invalid(what);
        if self.ego.speed_mps.is_empty() {
            return Err(invalid(
                "ego.speed_mps needs at least one [time_s, value] knot".into(),
            ));
        }
        check_profile(&self.ego.speed_mps).map_err(|e| invalid(format!("ego.speed_mps: {e}")))?;
        check_profile(&self.ego.yaw_rate_dps)
            .map_err(|e| invalid(format!("ego.yaw_rate_dps: {e}")))?;
        self.positive(self.events.ttc_threshold_s, "events.ttc_threshold_s")?;
        if self.events.min_points < 1 {
            return Err(invalid("events.min_points must be at least 1".into()));
        }
        Ok(())
    }

    /// Every static object's sizes are positive.
    fn check_static_objects(&self) -> Result<(), ScenarioError> {
        for object in &self.static_objects {
            let sizes: Vec<f64> = match object {
                StaticObject::Box { size_m, .. } => size_m.to_vec(),
                StaticObject::Car { .. } => Vec::new(),
                StaticObject::Pole {
                    radius_m, height_m, ..
                } => vec![*radius_m, *height_m],
            };
            if sizes.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(
                    self.invalid(format!("static object {object:?}: sizes must be positive"))
                );
            }
        }
        Ok(())
    }

    /// Unique ids > 0, motion given once (velocity or trajectory), positive sizes.
    fn check_actors(&self) -> Result<(), ScenarioError> {
        let invalid = |what: String| self.invalid(what);
        let mut ids = std::collections::BTreeSet::new();
        for actor in &self.actors {
            if actor.id == 0 || !ids.insert(actor.id) {
                return Err(invalid(format!(
                    "actor ids must be unique and > 0 (id {})",
                    actor.id
                )));
            }
            let by_velocity = actor.start_xy_m.is_some() || actor.velocity_mps.is_some();
            match (&actor.trajectory, by_velocity) {
                (Some(points), false) if !points.is_empty() => {
                    if points.windows(2).any(|w| w[1][0] <= w[0][0]) {
                        return Err(invalid(format!(
                            "actor {}: trajectory times must increase",
                            actor.id
                        )));
                    }
                }
                (None, true) if actor.start_xy_m.is_some() => {}
                _ => {
                    return Err(invalid(format!(
                        "actor {}: give either start_xy_m (+ velocity_mps) or a non-empty trajectory",
                        actor.id
                    )));
                }
            }
            if actor.size_m.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(invalid(format!(
                    "actor {}: sizes must be positive",
                    actor.id
                )));
            }
        }
        Ok(())
    }
}

fn check_profile(profile: &Profile) -> Result<(), String> {
    if profile
        .iter()
        .any(|[t, v]| !t.is_finite() || !v.is_finite())
    {
        return Err("knots must be finite numbers".into());
    }
    if profile.windows(2).any(|w| w[1][0] <= w[0][0]) {
        return Err("knot times must increase".into());
    }
    Ok(())
}
