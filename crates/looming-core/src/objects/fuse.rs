//! The objects' looming fed back into their cells: the fused looming that
//! viewers colour and near misses are built from, trusted on a solid face.
//!
//! Per cell the engine has only its own ray: on a real car's rear a cell is
//! an edge or crease for the crease test (bumper, lights, window), grazing
//! (the trunk lid), or has no previous surface along its ray (the face grew
//! as it approached), so most of the face is masked although the object's
//! looming is measured well from all of its cells ([`super::measure`]).
//!
//! An object is fed back when its value is corroborated (ten cells the
//! engine trusts agree with it) and its cells scatter about it at most eight
//! times their noise (else it is several faces). Its measured face is the
//! plane of the cells that agree. Each of its cells on that face (within
//! half a metre of the plane, at most a fifth of the object's extent; where
//! the face's normals agree, its own normal within 60 degrees) then takes:
//!
//! - where it has a fused value consistent with its object's (within three
//!   combined standard errors, at most 25 % + 0.1 1/s apart, its own
//!   `L_lidar` too, a noise below 0.3 1/s): the two combined by inverse
//!   variance, and its soft flags (`EDGE`, `GRAZING`, `NO_EGO`) cleared: the
//!   cell measured what its object measures;
//! - where it has no value of its own (`NO_PREVIOUS`, `OCCLUSION`: the face
//!   grew, or its rim met another surface before): the object's value,
//!   trusted (ray looming is the same along every ray meeting a plane that
//!   moves against the sensor);
//! - otherwise (another face of the object, a wild edge value): what the
//!   engine gave it.
//!
//! An object moving across the rays (its track's velocity) has only its
//! trusted cells combined and none filled: its flagged cells are its outline
//! sweeping over what lies beside and behind it. Before its track tells
//! (its first two pairs) no grazing or edge cell is taken.
//!
//! The cells' own noise model can be optimistic on a real sensor: it is
//! scaled per object by how far the cells actually scatter about the
//! object's value (never below the model).

use super::ground::CellPoints;
use super::measure::inverse_variance_mean;
use super::{Object, ObjectCells, PairObjects, collect_bounded, order};
use nalgebra::Vector3;

use crate::engine::{PairLooming, ThreatLevel, mask};
use crate::model::Scan;

/// Flags a cell consistent with its object is trusted despite: its range
/// difference is a measurement of the object's surface.
const SOFT_FLAGS: u8 = mask::EDGE | mask::GRAZING | mask::NO_EGO;
/// A cell within this many combined standard errors of its object's value
/// measured the object.
const CONSISTENT_SIGMAS: f64 = 3.0;
/// Mean resultant length of unit normals that agree (about 25 degrees of
/// spread).
const AGREEING_NORMALS: f64 = 0.9;
/// Cosine of the largest angle between a cell's normal and its face's, where
/// normals agree (60 degrees).
const SAME_FACE_COS: f64 = 0.5;
/// Cosine of the incidence a flagged cell must face the sensor with to be
/// combined, where normals can be believed (60 degrees).
const MIN_FACING_COS: f64 = 0.5;
/// Slower than this across the rays (m/s) an object's outline stays put.
const MIN_ACROSS_SPEED_MPS: f64 = 0.5;
/// A return this close to the plane of its object's measured face is on
/// that face, m: a car's rear with its bumper, lights and the end of its
/// lid; not its roof or sides, nor a building's other walls.
const FACE_DEPTH_M: f64 = 0.5;
/// ... at most this share of the object's horizontal extent.
const FACE_DEPTH_PER_EXTENT: f64 = 0.2;
/// An object whose cells scatter about its value more than this many times
/// their noise model is several faces: no feedback (the braking KITTI car
/// scatters 1-6 times, synthetic single faces 1).
const MAX_NOISE_SCALE: f64 = 8.0;
/// The largest difference between a consistent cell and its object: this
/// share of the object's value ...
const MAX_APART_FRACTION: f64 = 0.25;
/// ... plus this, 1/s.
const MAX_APART_PER_S: f64 = 0.1;
/// A cell noisier than this (1/s, scaled) does not measure its object.
const MAX_COMBINED_SIGMA_PER_S: f64 = 0.3;
/// Fewest cells the engine trusts (mask 0) that agree with an object's value
/// for it to be fed back.
const MIN_CORROBORATING_CELLS: usize = 10;
/// Fewest measured cells for an object's value to stand for cells without
/// one of their own.
const MIN_CELLS_TO_FILL: usize = 10;

/// What the feedback changed in a pair.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FusionCounts {
    /// Cells whose own value was combined with their object's.
    pub combined: usize,
    /// Cells without a value of their own that took their object's.
    pub filled: usize,
    /// Cells that disagreed with the ego prediction outside a moving patch,
    /// flagged moving by their object's motion ([`confirm_moving_cells`]).
    pub confirmed_moving: usize,
}

/// Combine every object's looming into its cells' fused looming (see the
/// module), update their masks and threat levels; the points' threat levels
/// follow their cells'.
pub fn fuse_objects(
    looming: &mut PairLooming,
    scan: &Scan,
    objects: &PairObjects,
    threat_ttc_s: &[f64; 3],
) -> FusionCounts {
    let points = CellPoints::of(looming, scan);
    let cells = ObjectCells::of(&objects.cell_object, objects.objects.len());
    fuse_with_cells(looming, &points, objects, &cells, threat_ttc_s)
}

/// [`fuse_objects`] with the cells' returns (what `cell_point` gives: no
/// cell's `EMPTY` bit changes here) and the cells of each object gathered.
pub(super) fn fuse_with_cells(
    looming: &mut PairLooming,
    points: &CellPoints,
    objects: &PairObjects,
    cells_of: &ObjectCells,
    threat_ttc_s: &[f64; 3],
) -> FusionCounts {
    let mut counts = FusionCounts::default();
    for (object, cells) in objects.objects.iter().zip(cells_of.iter()) {
        counts.confirmed_moving += confirm_moving_cells(looming, object, cells, threat_ttc_s);
        let (combined, filled) = fuse_object(looming, (points, object), cells, threat_ttc_s);
        counts.combined += combined;
        counts.filled += filled;
    }
    refresh_point_threats(looming);
    counts
}

/// One object's looming fed back into its `cells` (see the module): how
/// many cells were combined with it and how many filled.
fn fuse_object(
    looming: &mut PairLooming,
    (points, object): (&CellPoints, &Object),
    cells: &[usize],
    threat_ttc_s: &[f64; 3],
) -> (usize, usize) {
    let Some(value) = object_value(object) else {
        return (0, 0);
    };
    let (own, without) = split_by_own_value(looming, cells);
    let scale = noise_scale(looming, &own, value.0);
    if scale > MAX_NOISE_SCALE {
        // Its cells scatter far beyond their noise: several faces (a
        // building's corner, a car seen at its corner) whose ray looming
        // differs; one value does not stand for them.
        return (0, 0);
    }
    let corroborating = cells
        .iter()
        .filter(|&&c| looming.mask[c] == 0 && consistent(looming, c, value, scale))
        .count();
    if corroborating < MIN_CORROBORATING_CELLS {
        // No cell the engine trusts agrees: the value may be the
        // artefact of its flagged cells (a parked car's silhouette
        // sweeping over the background reads 4 1/s on edge cells).
        return (0, 0);
    }
    // Without a measured face no cell is on it: nothing to combine or fill.
    let Some(face) = measured_face(looming, (points, object), &own, value, scale) else {
        return (0, 0);
    };
    // Across the rays an object's flagged cells are its outline sweeping
    // over what lies beside and behind it (a crossing pedestrian's
    // trailing side reads its front's looming): only what the engine
    // trusted is combined, nothing filled.
    let across = moves_across(object);
    // Until its track tells (its first two pairs), a grazing or edge
    // cell is not taken either: near grazing a curved object's ray
    // looming is another's (a pedestrian's side, -5 1/s beside a front
    // of 0.85), and at an occlusion edge an object crossing the rays
    // sweeps (a crossing car's edge, segmented with the static object
    // beside it, read that object's 0.80 1/s against a truth of -1.49).
    let may_take = |looming: &PairLooming, cell: usize| match across {
        Some(false) => true,
        Some(true) => looming.mask[cell] == 0,
        None => looming.mask[cell] & (mask::GRAZING | mask::EDGE) == 0,
    };
    // First the cells that measured the object, then those without a
    // valid measurement. (A cell's tests read only that cell, which only
    // its own combining changes: the face's, which reads its return, last.)
    let mut combined = Vec::with_capacity(own.len());
    for &cell in &own {
        if may_take(looming, cell)
            && may_combine(looming, cell, value, (scale, &face))
            && on_face(looming, points, cell, &face)
        {
            combine_cell(looming, cell, value, scale);
            combined.push(cell);
        }
    }
    let may_fill = across != Some(true) && object.measured_cells >= MIN_CELLS_TO_FILL;
    let fillable = without
        .iter()
        .copied()
        .filter(|_| may_fill)
        .filter(|&cell| lacks_valid_value(looming, cell) && may_take(looming, cell))
        .filter(|&cell| on_face(looming, points, cell, &face));
    let fillable = collect_bounded(without.len(), fillable);
    for &cell in &fillable {
        looming.fused[cell] = value.0 as f32;
        looming.fused_sigma_per_s[cell] = value.1 as f32;
        looming.mask[cell] = 0;
    }
    // (Every changed cell's threat follows its new value: combined ones
    // too when nothing is filled.)
    for &cell in combined.iter().chain(&fillable) {
        looming.threat[cell] = if looming.mask[cell] == 0 {
            ThreatLevel::of(f64::from(looming.fused[cell]), threat_ttc_s)
        } else {
            ThreatLevel::None
        };
    }
    (combined.len(), fillable.len())
}

/// The cells of an object moving on its own (its `D` significant over all
/// its cells) that disagree with the ego prediction its way, but were left
/// out of the engine's moving patches (which a lone beam's line cannot
/// join, lest the junction of road and wall pass for a mover): moving,
/// their fused looming their own measurement. A car followed beside a side
/// sensor at 20 Hz shows it one beam: its 139 cells read `L_lidar` within
/// 0.002 1/s, and fused halfway to the ego prediction (0.27 1/s off) before.
/// How many were flagged.
fn confirm_moving_cells(
    looming: &mut PairLooming,
    object: &Object,
    cells: &[usize],
    threat_ttc_s: &[f64; 3],
) -> usize {
    let Some(d_object) = object.disagreement_per_s.filter(|_| object.moving) else {
        return 0;
    };
    let mut confirmed = 0;
    for &cell in cells {
        let d_cell = looming.disagreement[cell];
        if looming.disagrees[cell]
            && !looming.moving[cell]
            && looming.mask[cell] == 0
            && f64::from(d_cell).signum() == d_object.signum()
        {
            looming.moving[cell] = true;
            looming.fused[cell] = looming.l_lidar[cell];
            looming.fused_sigma_per_s[cell] = looming.sigma_per_s[cell];
            looming.threat[cell] = ThreatLevel::of(f64::from(looming.l_lidar[cell]), threat_ttc_s);
            confirmed += 1;
        }
    }
    confirmed
}

/// The object's looming and standard error, when measured.
fn object_value(object: &Object) -> Option<(f64, f64)> {
    Some((object.looming_per_s?, object.looming_se_per_s?))
}

/// Whether a cell holds a fused value of its own that measured its surface.
fn has_own_value(looming: &PairLooming, cell: usize) -> bool {
    let no_measurement = mask::EMPTY | mask::NO_PREVIOUS | mask::OCCLUSION;
    looming.mask[cell] & no_measurement == 0
        && looming.fused[cell].is_finite()
        && looming.fused_sigma_per_s[cell].is_finite()
        && looming.l_lidar[cell].is_finite()
        && looming.sigma_per_s[cell].is_finite()
}

/// An object's cells that hold a value of their own ([`has_own_value`])
/// and the others, each in order, told once for every test below that asks:
/// combining a cell changes only that cell, and it still holds its own value.
fn split_by_own_value(looming: &PairLooming, cells: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let (mut own, mut without) = (Vec::with_capacity(cells.len()), Vec::new());
    for &cell in cells {
        if has_own_value(looming, cell) {
            own.push(cell);
        } else {
            without.push(cell);
        }
    }
    (own, without)
}

/// How many times the engine's noise model an object's cells holding a
/// value of their own (`own`) scatter about `centre` (1.4826 times the
/// median of `|fused - centre| / sigma`), at least 1.
fn noise_scale(looming: &PairLooming, own: &[usize], centre: f64) -> f64 {
    let normalised = own.iter().map(|&c| {
        let sigma = f64::from(looming.fused_sigma_per_s[c]).max(1e-4);
        order::key((f64::from(looming.fused[c]) - centre).abs() / sigma)
    });
    let mut normalised = collect_bounded(own.len(), normalised);
    if normalised.is_empty() {
        return 1.0;
    }
    let mid = normalised.len() / 2;
    let median = order::select(&mut normalised, mid);
    (1.4826 * median).max(1.0)
}

/// The object's measured face: the plane of the cells consistent with its
/// value (their mean normal, and the median distance of their returns along
/// it).
#[derive(Clone, Copy)]
struct Face {
    normal: Vector3<f64>,
    offset_m: f64,
    /// The measured cells' normals agree (their mean resultant length is at
    /// least [`AGREEING_NORMALS`]): a cell's normal then tells its face.
    /// Where they scatter (a real sensor's returns 1 cm apart with 2 cm of
    /// range noise: on KITTI's braking car the fitted normals wander by tens
    /// of degrees), only the distance from the plane does.
    normals_agree: bool,
    /// How far from the plane a return is still on the face, m.
    depth_m: f64,
}

impl Face {
    /// How far the cell's return lies from the face's plane, m.
    fn distance_m(&self, points: &CellPoints, cell: usize) -> Option<f64> {
        let p = points.get(cell)?;
        Some((self.normal.dot(&Vector3::from(p)) - self.offset_m).abs())
    }
}

/// The face of an object's cells holding a value of their own (`own`) that
/// is consistent with the object's value; `None` with fewer than
/// [`MIN_CELLS_TO_FILL`].
fn measured_face(
    looming: &PairLooming,
    (points, object): (&CellPoints, &Object),
    own: &[usize],
    value: (f64, f64),
    scale: f64,
) -> Option<Face> {
    let consistent_cells = own
        .iter()
        .copied()
        .filter(|&c| consistent(looming, c, value, scale))
        .filter_map(|c| {
            let normal = Vector3::from(looming.normal[c].map(f64::from));
            (normal.norm_squared() > 0.5).then_some((c, normal))
        });
    let consistent_cells = collect_bounded(own.len(), consistent_cells);
    if consistent_cells.len() < MIN_CELLS_TO_FILL {
        return None;
    }
    let sum = consistent_cells
        .iter()
        .map(|(_, n)| n)
        .sum::<Vector3<f64>>();
    let resultant_length = sum.norm() / consistent_cells.len() as f64;
    let normal = sum.try_normalize(1e-9)?;
    let offsets = consistent_cells
        .iter()
        .filter_map(|&(c, _)| points.get(c))
        .map(|p| order::key(normal.dot(&Vector3::from(p))));
    let mut offsets = collect_bounded(consistent_cells.len(), offsets);
    if offsets.is_empty() {
        return None;
    }
    let mid = offsets.len() / 2;
    let offset_m = order::select(&mut offsets, mid);
    Some(Face {
        normal,
        offset_m,
        normals_agree: resultant_length >= AGREEING_NORMALS,
        depth_m: face_depth_m(object),
    })
}

/// Whether the cell's fused value agrees with its object's value:
/// within [`CONSISTENT_SIGMAS`] combined standard errors, and however noisy
/// the cell, within [`MAX_APART_FRACTION`] of the value plus
/// [`MAX_APART_PER_S`] (beyond, it is another face or a mixed return: the
/// side of a crossing pedestrian reads half its front's looming).
fn consistent(looming: &PairLooming, cell: usize, (value, se): (f64, f64), scale: f64) -> bool {
    let sigma = f64::from(looming.fused_sigma_per_s[cell]) * scale;
    let apart = (f64::from(looming.fused[cell]) - value).abs();
    // The cheap bound first: it needs no root.
    apart <= MAX_APART_FRACTION * value.abs() + MAX_APART_PER_S
        && within_hypot(apart, CONSISTENT_SIGMAS, (sigma, se))
}

/// `apart <= k * a.hypot(b)`, exactly, with libm's `hypot` (a tenth of the
/// objects stage: every cell of every object, up to three times) called
/// only where the plain root of the squares, within a few ulps of it where
/// the squares are normal numbers, leaves the verdict in doubt.
fn within_hypot(apart: f64, k: f64, (a, b): (f64, f64)) -> bool {
    let squares = a * a + b * b;
    let bound = k * squares.sqrt();
    let normal = (1e-290..1e290).contains(&squares);
    if normal && (apart - bound).abs() > 1e-12 * bound {
        apart <= bound
    } else {
        apart <= k * a.hypot(b)
    }
}

/// Whether the cell's own measurement (`L_lidar`; its fused value may come
/// from its neighbours or the ego prediction) is within the largest
/// difference a face allows of its object's value: the trailing side of a
/// pedestrian crossing at 3 m reads 0.7 1/s (truth -1.7) beside a front of
/// 1.3, and an edge cell's fused value there is its neighbours'.
fn measurement_agrees(looming: &PairLooming, cell: usize, value: f64) -> bool {
    let apart = (f64::from(looming.l_lidar[cell]) - value).abs();
    apart <= MAX_APART_FRACTION * value.abs() + MAX_APART_PER_S
}

/// Whether a cell the engine flagged may still have measured its object:
/// where the face's normals agree (a sensor whose fitted normals can be
/// believed), only if it faces the sensor ([`MIN_FACING_COS`], as the cells
/// an object's looming is measured on): on a curved object (a pedestrian) the
/// ray looming of a cell seen obliquely is another (the trailing side of a
/// crossing pedestrian: -1.7 1/s beside a front of 1.3). Where they
/// scatter, a cell's incidence says nothing.
fn masked_cell_may_measure(looming: &PairLooming, cell: usize, face: &Face) -> bool {
    looming.mask[cell] == 0
        || !face.normals_agree
        || f64::from(looming.incidence_cos[cell]) >= MIN_FACING_COS
}

/// Whether the own value of a cell that holds one ([`has_own_value`]) and
/// its object's agree, to be combined (see the module).
fn may_combine(
    looming: &PairLooming,
    cell: usize,
    (value, se): (f64, f64),
    (scale, face): (f64, &Face),
) -> bool {
    if !consistent(looming, cell, (value, se), scale)
        || !measurement_agrees(looming, cell, value)
        || !masked_cell_may_measure(looming, cell, face)
    {
        return false;
    }
    let sigma = f64::from(looming.fused_sigma_per_s[cell]) * scale;
    // Agreement within a noise this large says nothing.
    let too_noisy = sigma > MAX_COMBINED_SIGMA_PER_S;
    !too_noisy
}

/// Combine a cell's own value with its object's (where [`may_combine`]).
fn combine_cell(looming: &mut PairLooming, cell: usize, (value, se): (f64, f64), scale: f64) {
    let sigma = f64::from(looming.fused_sigma_per_s[cell]) * scale;
    let (fused, fused_sigma) =
        inverse_variance_mean((f64::from(looming.fused[cell]), sigma), (value, se));
    looming.fused[cell] = fused as f32;
    looming.fused_sigma_per_s[cell] = fused_sigma as f32;
    looming.mask[cell] &= !SOFT_FLAGS;
}

/// A return of the object without a valid measurement of its own: no
/// previous surface along its ray, or another one there. (A cell whose own
/// value its object contradicts keeps it: another face of the object, an
/// oblique wall whose ray looming is truly larger, is not the measured
/// face's.)
fn lacks_valid_value(looming: &PairLooming, cell: usize) -> bool {
    let m = looming.mask[cell];
    m & mask::EMPTY == 0 && m != 0 && !has_own_value(looming, cell)
}

/// Whether the object moves across the sensor's rays: its track's velocity
/// over the ground, less its part along the ray to its centroid, at least
/// [`MIN_ACROSS_SPEED_MPS`]; `None` before its track tells a velocity.
fn moves_across(object: &Object) -> Option<bool> {
    let v = Vector3::from(object.velocity_mps?);
    let ray = Vector3::from(object.centroid_m).try_normalize(1e-9)?;
    Some((v - ray * v.dot(&ray)).norm() >= MIN_ACROSS_SPEED_MPS)
}

/// The depth of an object's face: [`FACE_DEPTH_M`], and on a small object
/// [`FACE_DEPTH_PER_EXTENT`] of its horizontal extent (a pedestrian is half
/// a metre deep: its sides are not its front).
fn face_depth_m(object: &Object) -> f64 {
    let extent_m = (object.max_m[0] - object.min_m[0]).hypot(object.max_m[1] - object.min_m[1]);
    (FACE_DEPTH_PER_EXTENT * extent_m).min(FACE_DEPTH_M)
}

/// Whether the cell's return lies on the object's measured face (within
/// [`FACE_DEPTH_M`] of its plane): its ray looming is then about the face's
/// (on a plane moving against the sensor it is the same along every ray).
fn on_face(looming: &PairLooming, points: &CellPoints, cell: usize, face: &Face) -> bool {
    let normal = Vector3::from(looming.normal[cell].map(f64::from));
    let turned_away = face.normals_agree
        && normal.norm_squared() > 0.5
        && normal.dot(&face.normal) < SAME_FACE_COS;
    !turned_away
        && face
            .distance_m(points, cell)
            .is_some_and(|d| d <= face.depth_m)
}

/// Each point's threat level from its cell's, when the point is that cell's
/// surface.
fn refresh_point_threats(looming: &mut PairLooming) {
    for (point, &cell) in looming.image.point_surface.iter().enumerate() {
        if let Some(threat) = looming.threat.get(cell as usize) {
            looming.point_threat[point] = *threat;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The root of the squares decides as `hypot` does, at the bound's
    /// ulps and at values beyond the squares' range.
    #[test]
    fn the_bound_without_hypot_is_hypots_verdict() {
        let mut rng = crate::test_rng::SplitMix64(26);
        let specials = [0.0, 1e-200, 1e200, f64::INFINITY, f64::NAN, 1e-3, 0.5];
        for case in 0..200_000 {
            let mut pick = || {
                if case % 5 == 0 {
                    specials[(rng.uniform(0.0, specials.len() as f64)) as usize % specials.len()]
                } else {
                    10f64.powf(rng.uniform(-6.0, 2.0))
                }
            };
            let (a, b) = (pick(), pick());
            let exact = 3.0 * a.hypot(b);
            // At the bound, an ulp either side, and further away.
            for apart in [
                exact,
                f64::from_bits(exact.to_bits().wrapping_add(1)),
                f64::from_bits(exact.to_bits().wrapping_sub(1)),
                exact * 0.9,
                exact * 1.1,
                pick(),
            ] {
                assert_eq!(
                    within_hypot(apart, 3.0, (a, b)),
                    apart <= exact,
                    "{apart} {a} {b}"
                );
            }
        }
    }
}
