//! Objects: the non-ground returns of a scan pair grouped into objects
//! ([`segment`]), each with its looming measured robustly from all of its
//! cells that hold a measurement ([`measure`]), followed across pairs under a
//! stable id ([`ObjectTracker`]). Pure computation on the engine's result.
//!
//! What a fleet engineer judges is the car ahead, a wall, a person, not a
//! cell: a cell's fused looming is often masked on a real object (a car's
//! rear face is edges and creases for the crease test), while the object's
//! `L_lidar` cells still carry range information. The object's looming is the
//! inverse-variance weighted median of `L_lidar` over its cells that face the
//! sensor and have a previous surface along their ray, with a standard error
//! from the weighted spread.

mod fuse;
pub mod ground;
mod measure;
pub mod order;
mod segment;
mod track;

pub use fuse::{FusionCounts, fuse_objects};
pub use measure::measure_objects;
pub use segment::segment;
pub use track::ObjectTracker;

use serde::{Deserialize, Serialize};

use crate::engine::PairLooming;
use crate::model::Scan;
use ground::CellPoints;

/// No object (in [`PairObjects::cell_object`]).
pub const NO_OBJECT: u32 = u32::MAX;

/// How objects are found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectConfig {
    /// A return this far above the ground, or more, may be an object, m.
    pub min_height_m: f64,
    /// Neighbouring returns are one object when the angle between the
    /// line joining them and the farther one's ray is at least this
    /// (Bogoslavskyi & Stachniss 2016), degrees.
    pub join_angle_deg: f64,
    /// ... and when they are at most this far apart, m.
    pub max_gap_m: f64,
    /// Fewest cells of an object.
    pub min_cells: usize,
    /// Returns beyond this range are not segmented, m.
    pub max_range_m: f64,
}

impl Default for ObjectConfig {
    fn default() -> Self {
        Self {
            min_height_m: 0.25,
            join_angle_deg: 10.0,
            max_gap_m: 1.0,
            min_cells: 6,
            max_range_m: 80.0,
        }
    }
}

/// One object of a pair, in the LiDAR frame of its current scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Object {
    /// Stable over the pairs it is followed in (from 1; 0 before tracking).
    pub id: u32,
    /// Pairs this object has been followed in, this one included.
    pub age_pairs: u32,
    pub cells: usize,
    /// Points of the scan that are its cells' surfaces.
    pub points: usize,
    /// 10th percentile of its cells' ranges, m.
    pub nearest_range_m: f64,
    /// Mean of its returns, m.
    pub centroid_m: [f64; 3],
    /// Axis-aligned extent of its returns, m.
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
    /// Azimuth of the centroid (0 ahead, left positive), degrees.
    pub bearing_deg: f64,
    /// Its looming, 1/s, and standard error; `None` without a measured cell.
    /// On an object that does not move on its own, the measurement and the
    /// ego prediction combined; else the measurement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub looming_per_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub looming_se_per_s: Option<f64>,
    /// The measurement alone: the weighted median of `L_lidar` over its
    /// measured cells, 1/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lidar_looming_per_s: Option<f64>,
    /// Cells the looming was measured on.
    pub measured_cells: usize,
    /// No cell measured it: the looming is its track's, from the change of
    /// its nearest range since the last pair.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub looming_from_track: bool,
    /// Neither its cells nor its track measured it (its first pair): the
    /// looming is what it would be were the object static, from the ego
    /// motion alone; replaced by its track's range rate from its next pair.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub looming_assumed_static: bool,
    /// `1 / looming` when approaching, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_to_contact_s: Option<f64>,
    /// Its `D` (looming of its own motion), 1/s; `None` without ego motion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disagreement_per_s: Option<f64>,
    /// `|D|` significant: the object moves on its own.
    pub moving: bool,
    /// Its own velocity over the ground (ego motion removed), LiDAR frame,
    /// m/s, from its track's centroid (smoothed); `None` before its third
    /// pair.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_mps: Option<[f64; 3]>,
}

/// The cells of every object, by index in `PairObjects::objects`: one list,
/// each object's cells ascending and the objects one after another, counted
/// out of the per-cell labels in two passes. Built once per pair and read by
/// measuring, tracking and fusing (a list per object, grown by pushes and
/// built for each of the three, was a twentieth of the stage).
#[derive(Debug, Clone, Default)]
pub(crate) struct ObjectCells {
    /// Object `o`'s cells are `cells[starts[o]..starts[o + 1]]`.
    starts: Vec<usize>,
    cells: Vec<usize>,
}

impl ObjectCells {
    /// The cells of the objects `0..count` labelled in `cell_object` (other
    /// labels, [`NO_OBJECT`] among them, are no object's).
    pub(crate) fn of(cell_object: &[u32], count: usize) -> Self {
        let object_of = |label: u32| Some(label as usize).filter(|&o| o < count);
        let mut starts = vec![0usize; count + 1];
        for &label in cell_object {
            if let Some(object) = object_of(label) {
                starts[object + 1] += 1;
            }
        }
        for object in 0..count {
            starts[object + 1] += starts[object];
        }
        let mut cells = vec![0usize; starts[count]];
        let mut next = starts[..count].to_vec();
        for (cell, &label) in cell_object.iter().enumerate() {
            if let Some(object) = object_of(label) {
                cells[next[object]] = cell;
                next[object] += 1;
            }
        }
        Self { starts, cells }
    }

    /// The cells of object `object`; `None` past the last object.
    pub(crate) fn get(&self, object: usize) -> Option<&[usize]> {
        let (&start, &end) = (self.starts.get(object)?, self.starts.get(object + 1)?);
        self.cells.get(start..end)
    }

    /// How many objects.
    pub(crate) fn len(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    /// Each object's cells, in order of index.
    pub(crate) fn iter(&self) -> impl Iterator<Item = &[usize]> {
        self.starts.windows(2).map(|w| &self.cells[w[0]..w[1]])
    }
}

/// `items` collected into a vector of `capacity`, an upper bound on their
/// count (a filter's `collect` starts small and grows by doubling, copying
/// what it holds each time).
pub(crate) fn collect_bounded<T>(capacity: usize, items: impl Iterator<Item = T>) -> Vec<T> {
    let mut collected = Vec::with_capacity(capacity);
    collected.extend(items);
    collected
}

/// The objects of one pair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PairObjects {
    /// The ground the objects stand on (also what `looming::quality` judges
    /// the ego motion by: found once per pair).
    pub ground: Option<ground::GroundFit>,
    /// Per range-image cell, the index of its object in `objects`
    /// ([`NO_OBJECT`]: ground, empty or too small a group).
    pub cell_object: Vec<u32>,
    pub objects: Vec<Object>,
}

impl PairObjects {
    /// Find and measure the objects of a pair (ids not yet given: see
    /// [`ObjectTracker::update`]).
    pub fn find(scan: &Scan, looming: &PairLooming, config: &ObjectConfig) -> Self {
        Self::find_in(&CellPoints::of(looming, scan), looming, config).0
    }

    /// [`PairObjects::find`] from the pair's cell returns, and the cells of
    /// each object.
    fn find_in(
        points: &CellPoints,
        looming: &PairLooming,
        config: &ObjectConfig,
    ) -> (Self, ObjectCells) {
        let ground = ground::GroundFit::find_in(looming, points);
        let cell_object = segment(points, looming, ground.as_ref(), config);
        let (objects, cells) = measure::measure_labelled(points, looming, &cell_object);
        let found = Self {
            ground,
            cell_object,
            objects,
        };
        (found, cells)
    }

    /// The objects stage as `process` runs it on a pair: find the objects,
    /// give them their ids and velocities (`tracker`, `dt_s` after the pair
    /// it saw last), and feed their looming back into `looming`'s cells
    /// ([`fuse_objects`]). The cells' returns and each object's cells are
    /// gathered once for the three.
    pub fn find_tracked_fused(
        scan: &Scan,
        looming: &mut PairLooming,
        (config, threat_ttc_s): (&ObjectConfig, &[f64; 3]),
        tracker: &mut ObjectTracker,
        dt_s: f64,
    ) -> (Self, FusionCounts) {
        let points = CellPoints::of(looming, scan);
        let (mut objects, cells) = Self::find_in(&points, looming, config);
        tracker.update_with_cells(&mut objects, &cells, looming, dt_s);
        let counts = fuse::fuse_with_cells(looming, &points, &objects, &cells, threat_ttc_s);
        (objects, counts)
    }

    /// The id of the object point `index` of the scan is the surface of.
    pub fn object_of_point(&self, looming: &PairLooming, index: usize) -> Option<u32> {
        self.object_of_cell(looming.image.surface_cell(index)?)
    }

    /// The id of the object range-image cell `cell` belongs to.
    pub fn object_of_cell(&self, cell: usize) -> Option<u32> {
        let object = *self.cell_object.get(cell)?;
        self.objects.get(object as usize).map(|o| o.id)
    }
}
