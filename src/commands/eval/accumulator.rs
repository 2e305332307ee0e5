//! The error accumulators of `looming eval`: every pair's cells, points and
//! objects against the truth, by quantity and class.

use std::collections::BTreeMap;

use super::{Detection, ErrorStats, OBSERVABLE_MOTION_PER_S, ScanTruth, Summary};
use crate::engine::{self, PairLooming};
use crate::model::Scan;
use crate::objects::PairObjects;

#[derive(Default)]
pub(super) struct Accumulator {
    errors: BTreeMap<String, BTreeMap<String, ErrorStats>>,
    detection: Detection,
    actor_cells: u64,
    actor_cells_flagged: u64,
}

impl Accumulator {
    fn add(&mut self, quantity: &str, class: &str, error: f64) {
        self.errors
            .entry(quantity.to_string())
            .or_default()
            .entry(class.to_string())
            .or_default()
            .add(error);
    }

    /// Per point: `L_ego` against the true point looming.
    fn add_points(&mut self, scan: &Scan, result: &PairLooming, truth: &ScanTruth) {
        for (point, &l_ego) in result.l_ego.iter().enumerate() {
            let Some(t) = truth.of(scan, point) else {
                continue;
            };
            if !l_ego.is_finite() {
                continue;
            }
            let error = f64::from(l_ego) - f64::from(t.point_looming);
            if t.moving {
                // L_ego treats moving objects as static: this is its blind spot.
                self.add("l_ego", "moving_points", error);
                continue;
            }
            self.add("l_ego", "static_points", error);
            if t.point_looming.abs() > 0.05 {
                self.add(
                    "l_ego_relative",
                    "static_points",
                    error / f64::from(t.point_looming),
                );
            }
        }
    }

    /// One pair: `result` after the object stage, `engine_mask` and
    /// `engine_fused` the engine's own (the classes of every quantity but
    /// `fused`, which is judged on the cells users see trusted; the engine's
    /// fused looming as `engine_fused`).
    pub(super) fn add_pair(
        &mut self,
        scan: &Scan,
        (result, (engine_mask, engine_fused)): (&PairLooming, &(Vec<u8>, Vec<f32>)),
        objects: &PairObjects,
        truth: &ScanTruth,
    ) {
        let truth_of = |point: usize| truth.of(scan, point);
        if result.availability.ego_velocity {
            self.add_points(scan, result, truth);
        }
        for cell in 0..result.geometry.cells() {
            let point = result.image.point[cell];
            if point == engine::NO_POINT {
                continue;
            }
            let Some(t) = truth_of(point as usize) else {
                continue;
            };
            let masked = engine_mask[cell] != 0;
            let class_of = |masked: bool| {
                if masked {
                    "masked"
                } else if t.moving {
                    "moving"
                } else if t.surface == 0 {
                    "static_road"
                } else if t.incidence_cos >= 0.5 {
                    "static_facing"
                } else {
                    "static_oblique"
                }
            };
            let truth_ray = f64::from(t.ray_looming);
            let mut add = |quantity: &str, value: f32, truth: f64, masked: bool| {
                if value.is_finite() {
                    let error = f64::from(value) - truth;
                    self.add(quantity, class_of(masked), error);
                    if !masked {
                        self.add(quantity, "all_unmasked", error);
                    }
                }
            };
            add("l_lidar", result.l_lidar[cell], truth_ray, masked);
            add("engine_fused", engine_fused[cell], truth_ray, masked);
            add(
                "fused",
                result.fused[cell],
                truth_ray,
                result.mask[cell] != 0,
            );
            if result.availability.ego_velocity {
                add("l_ray_ego", result.l_ray_ego[cell], truth_ray, masked);
                add(
                    "disagreement",
                    result.disagreement[cell],
                    f64::from(t.own_motion_looming),
                    masked,
                );
            }
            if masked || !result.availability.ego_velocity {
                continue;
            }
            let truly_moving = f64::from(t.own_motion_looming).abs() >= OBSERVABLE_MOTION_PER_S;
            let flagged = result.moving[cell];
            let d = &mut self.detection;
            match (flagged, truly_moving) {
                (true, true) => d.true_positive += 1,
                (true, false) => d.false_positive += 1,
                (false, true) => d.false_negative += 1,
                (false, false) => d.true_negative += 1,
            }
            if t.moving {
                self.actor_cells += 1;
                self.actor_cells_flagged += u64::from(flagged);
            }
        }
        self.add_objects(scan, result, objects, truth);
    }

    /// Each object's looming against the truth of its cells: the median true
    /// ray looming over the cells the object's value stands for (those with
    /// a trusted fused value after the object stage), as `object` /
    /// `moving` or `static` by the object's own flag.
    fn add_objects(
        &mut self,
        scan: &Scan,
        result: &PairLooming,
        objects: &PairObjects,
        truth: &ScanTruth,
    ) {
        let mut truths: Vec<Vec<f32>> = vec![Vec::new(); objects.objects.len()];
        for (cell, &object) in objects.cell_object.iter().enumerate() {
            let point = result.image.point[cell];
            if object == crate::objects::NO_OBJECT
                || point == engine::NO_POINT
                || result.mask[cell] != 0
            {
                continue;
            }
            if let Some(t) = truth.of(scan, point as usize)
                && let Some(list) = truths.get_mut(object as usize)
            {
                list.push(t.ray_looming);
            }
        }
        for (object, mut true_values) in objects.objects.iter().zip(truths) {
            let Some(looming_per_s) = object.looming_per_s else {
                continue;
            };
            if true_values.len() < 3 {
                continue;
            }
            let mid = true_values.len() / 2;
            let true_per_s = *true_values.select_nth_unstable_by(mid, f32::total_cmp).1;
            let class = if object.moving { "moving" } else { "static" };
            self.add("object", class, looming_per_s - f64::from(true_per_s));
            self.add("object", "all", looming_per_s - f64::from(true_per_s));
        }
    }

    pub(super) fn finish(mut self) -> (BTreeMap<String, BTreeMap<String, Summary>>, Detection) {
        let d = &mut self.detection;
        let ratio = |a: u64, b: u64| {
            if b == 0 {
                f64::NAN
            } else {
                a as f64 / b as f64
            }
        };
        d.precision = ratio(d.true_positive, d.true_positive + d.false_positive);
        d.recall = ratio(d.true_positive, d.true_positive + d.false_negative);
        d.f1 = 2.0 * d.precision * d.recall / (d.precision + d.recall);
        d.recall_all_actor_cells = ratio(self.actor_cells_flagged, self.actor_cells);
        let errors = self
            .errors
            .into_iter()
            .map(|(q, classes)| {
                (
                    q,
                    classes.into_iter().map(|(c, s)| (c, s.summary())).collect(),
                )
            })
            .collect();
        (errors, self.detection)
    }
}
