//! The looming of the car ahead, measured as issue #24 measures it: on the
//! rear face of the object in a box ahead, the fused looming (what viewers
//! colour and near misses are built from) and `L_lidar` against a reference
//! from the face's own distance. A development tool:
//! `cargo run --release --example face_probe -- LOG.mcap [X_MIN X_MAX Y_HALF Z_MIN Z_MAX]`
//! (default box: x 2-25 m, |y| < 1 m, z -1.4..0.5 m, the braking KITTI
//! sequence's car ahead).
//!
//! Per pair: the box's points; the face = those within 0.5 m of the box's
//! 5th-percentile x; the face's distance = the median x of the face; the
//! reference looming = -(x_now - x_before) / (dt x_now) from consecutive
//! pairs. Reported: the share of face points whose fused looming is finite
//! (trusted), the pairs where that share is >= 80 %, and the median and
//! 90th percentile of |fused - reference| and |L_lidar - reference| over the
//! face points with a value.

use looming::engine::{self, EngineCache, EngineConfig};
use looming::model::Scan;
use looming::objects::{ObjectConfig, ObjectTracker, PairObjects};

struct FaceBox {
    x: (f32, f32),
    y_half: f32,
    z: (f32, f32),
}

/// One pair's face: its distance and the per-point values.
struct Face {
    stamp_ns: i64,
    distance_m: f64,
    points: usize,
    fused: Vec<f32>,
    lidar: Vec<f32>,
    objects: Vec<Option<u32>>,
    /// Per face point: its cell's mask bits (`EMPTY` without a cell).
    masks: Vec<u8>,
    /// Looming of each object id seen on the face.
    object_looming: std::collections::BTreeMap<u32, Option<f64>>,
}

fn percentile(values: &mut [f32], q: f64) -> f32 {
    values.sort_by(f32::total_cmp);
    let at = ((values.len() as f64 - 1.0) * q).round() as usize;
    values.get(at).copied().unwrap_or(f32::NAN)
}

fn face_of(
    scan: &Scan,
    result: &engine::PairLooming,
    objects: &PairObjects,
    b: &FaceBox,
) -> Option<Face> {
    let inside: Vec<usize> = (0..scan.points_m.len())
        .filter(|&i| {
            let p = scan.points_m[i];
            (b.x.0..b.x.1).contains(&p[0])
                && p[1].abs() < b.y_half
                && (b.z.0..b.z.1).contains(&p[2])
        })
        .collect();
    if inside.len() < 10 {
        return None;
    }
    let mut xs: Vec<f32> = inside.iter().map(|&i| scan.points_m[i][0]).collect();
    let near = percentile(&mut xs, 0.05);
    let face: Vec<usize> = inside
        .into_iter()
        .filter(|&i| scan.points_m[i][0] <= near + 0.5)
        .collect();
    let mut face_x: Vec<f32> = face.iter().map(|&i| scan.points_m[i][0]).collect();
    let distance_m = f64::from(percentile(&mut face_x, 0.5));
    let value = |values: &[f32], i: usize, trusted_only: bool| {
        result
            .image
            .surface_cell(i)
            .filter(|&c| !trusted_only || result.mask[c] == 0)
            .map_or(f32::NAN, |c| values[c])
    };
    if std::env::var_os("FACE_WHY").is_some() {
        print_untrusted_causes(result, objects, &face);
    }
    Some(Face {
        stamp_ns: scan.stamp_ns,
        distance_m,
        points: face.len(),
        fused: face
            .iter()
            .map(|&i| value(&result.fused, i, true))
            .collect(),
        lidar: face
            .iter()
            .map(|&i| value(&result.l_lidar, i, false))
            .collect(),
        masks: face
            .iter()
            .map(|&i| {
                result
                    .image
                    .surface_cell(i)
                    .map_or(engine::mask::EMPTY, |c| result.mask[c])
            })
            .collect(),
        objects: face
            .iter()
            .map(|&i| objects.object_of_point(result, i))
            .collect(),
        object_looming: objects
            .objects
            .iter()
            .map(|o| (o.id, o.looming_per_s))
            .collect(),
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("LOG.mcap");
    let number = |i: usize, default: f32| args.get(i).map_or(default, |a| a.parse().unwrap());
    let b = FaceBox {
        x: (number(2, 2.0), number(3, 25.0)),
        y_half: number(4, 1.0),
        z: (number(5, -1.4), number(6, 0.5)),
    };
    // FIRINGS=2: the coarser image of `process --firings-per-column 2`.
    let config = EngineConfig {
        firings_per_column: std::env::var("FIRINGS").map_or(1, |f| f.parse().unwrap()),
        ..EngineConfig::default()
    };
    let mut cache = EngineCache::default();
    let mut faces: Vec<Face> = Vec::new();
    let mut tracker = ObjectTracker::default();
    let object_config = ObjectConfig::default();
    looming::pipeline::replay(
        std::path::Path::new(path),
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            let Some(mut result) = engine::compute_with_cache(&pair, &config, &mut cache) else {
                return;
            };
            let (objects, _) = PairObjects::find_tracked_fused(
                &pair.current,
                &mut result,
                (&object_config, &config.threat_ttc_s),
                &mut tracker,
                pair.step_s,
            );
            if let Some(face) = face_of(&pair.current, &result, &objects, &b) {
                faces.push(face);
            }
        },
    )
    .expect("a readable log");
    report(&faces);
    mask_breakdown(&faces);
}

/// The share of face points carrying each mask bit (a point may carry several).
fn mask_breakdown(faces: &[Face]) {
    let names = [
        "EMPTY",
        "NO_PREVIOUS",
        "EDGE",
        "GRAZING",
        "NO_EGO",
        "OCCLUSION",
    ];
    let masks: Vec<u8> = faces.iter().flat_map(|f| f.masks.iter().copied()).collect();
    let total = masks.len().max(1) as f64;
    let shares: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(bit, name)| {
            let n = masks.iter().filter(|&&m| m & (1 << bit) != 0).count();
            format!("{name} {:.1} %", 100.0 * n as f64 / total)
        })
        .collect();
    println!("face points' mask bits: {}", shares.join(", "));
}

fn report(faces: &[Face]) {
    let (mut fused_err, mut lidar_err) = (Vec::new(), Vec::new());
    let (mut trusted, mut all, mut good_pairs, mut pairs) = (0usize, 0usize, 0usize, 0usize);
    let mut one_object_pairs = 0usize;
    let mut object_err = Vec::new();
    let mut ids = std::collections::BTreeMap::new();
    println!(
        "| pair stamp | face m | points | trusted | reference 1/s | fused median | L_lidar median | object (share of face) | object looming |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for w in faces.windows(2) {
        let (before, now) = (&w[0], &w[1]);
        let dt_s = (now.stamp_ns - before.stamp_ns) as f64 * 1e-9;
        if dt_s <= 0.0 || dt_s > 0.25 {
            continue;
        }
        let reference = -(now.distance_m - before.distance_m) / (dt_s * now.distance_m);
        pairs += 1;
        let finite: Vec<f32> = now
            .fused
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        trusted += finite.len();
        all += now.points;
        let share = finite.len() as f64 / now.points as f64;
        good_pairs += usize::from(share >= 0.8);
        fused_err.extend(
            finite
                .iter()
                .map(|v| (f64::from(*v) - reference).abs() as f32),
        );
        let lidar: Vec<f32> = now
            .lidar
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        lidar_err.extend(
            lidar
                .iter()
                .map(|v| (f64::from(*v) - reference).abs() as f32),
        );
        let object = dominant_object(&now.objects);
        one_object_pairs += usize::from(object.is_some_and(|(_, share)| share >= 0.8));
        let object_looming =
            object.and_then(|(id, _)| now.object_looming.get(&id).copied().flatten());
        if let Some((id, _)) = object {
            *ids.entry(id).or_insert(0usize) += 1;
        }
        if let Some(l) = object_looming {
            object_err.push((l - reference).abs() as f32);
        }
        println!(
            "| {:.1} | {:.2} | {} | {:.0} % | {:+.3} | {:+.3} | {:+.3} | {} | {} |",
            now.stamp_ns as f64 * 1e-9,
            now.distance_m,
            now.points,
            100.0 * share,
            reference,
            percentile(&mut finite.clone(), 0.5),
            percentile(&mut lidar.clone(), 0.5),
            object.map_or("-".into(), |(id, s)| format!("{id} ({:.0} %)", 100.0 * s)),
            object_looming.map_or("-".into(), |l| format!("{l:+.3}")),
        );
    }
    let counts = Counts {
        pairs,
        trusted,
        all,
        good_pairs,
        one_object_pairs,
    };
    summary(&counts, &fused_err, &lidar_err, &object_err, &ids);
}

#[derive(Clone, Copy)]
struct Counts {
    pairs: usize,
    trusted: usize,
    all: usize,
    good_pairs: usize,
    one_object_pairs: usize,
}

fn summary(
    c: &Counts,
    fused_err: &[f32],
    lidar_err: &[f32],
    object_err: &[f32],
    ids: &std::collections::BTreeMap<u32, usize>,
) {
    let Counts {
        pairs,
        trusted,
        all,
        good_pairs,
        one_object_pairs,
    } = *c;
    println!();
    println!(
        "pairs {pairs}: face points trusted {:.1} % overall, >= 80 % in {good_pairs} pairs ({:.0} %); one object on >= 80 % of the face in {one_object_pairs} pairs",
        100.0 * trusted as f64 / all.max(1) as f64,
        100.0 * good_pairs as f64 / pairs.max(1) as f64
    );
    println!(
        "|fused - ref|: median {:.4}, p90 {:.4} 1/s ({} values); |L_lidar - ref|: median {:.4}, p90 {:.4} 1/s",
        percentile(&mut fused_err.to_vec(), 0.5),
        percentile(&mut fused_err.to_vec(), 0.9),
        fused_err.len(),
        percentile(&mut lidar_err.to_vec(), 0.5),
        percentile(&mut lidar_err.to_vec(), 0.9),
    );
    let most = ids.values().copied().max().unwrap_or(0);
    println!(
        "object: the face's dominant object has the same id in {most} of {pairs} pairs ({:.0} %), ids seen {:?}; |object looming - ref| median {:.4}, p90 {:.4} 1/s over {} pairs",
        100.0 * most as f64 / pairs.max(1) as f64,
        ids,
        percentile(&mut object_err.to_vec(), 0.5),
        percentile(&mut object_err.to_vec(), 0.9),
        object_err.len()
    );
}

/// The object most face points belong to, and its share of the face.
fn dominant_object(objects: &[Option<u32>]) -> Option<(u32, f64)> {
    let mut counts = std::collections::BTreeMap::new();
    for id in objects.iter().flatten() {
        *counts.entry(*id).or_insert(0usize) += 1;
    }
    counts
        .into_iter()
        .max_by_key(|&(_, n)| n)
        .map(|(id, n)| (id, n as f64 / objects.len().max(1) as f64))
}

/// FACE_WHY: why the face's untrusted points are untrusted: no object, an
/// own value inconsistent with the object's, or no value of its own (with
/// its normal's x component: the rear face's normal is about -x).
fn print_untrusted_causes(result: &engine::PairLooming, objects: &PairObjects, face: &[usize]) {
    let mut causes: std::collections::BTreeMap<String, usize> = std::collections::BTreeMap::new();
    for &i in face {
        let Some(cell) = result.image.surface_cell(i) else {
            *causes.entry("no cell".into()).or_default() += 1;
            continue;
        };
        if result.mask[cell] == 0 {
            continue;
        }
        let cause = if objects.cell_object[cell] == looming::objects::NO_OBJECT {
            "no object".to_string()
        } else if result.fused[cell].is_finite()
            && result.mask[cell] & (engine::mask::NO_PREVIOUS | engine::mask::OCCLUSION) == 0
        {
            format!("own value, mask {}", result.mask[cell])
        } else {
            let nx = result.normal[cell][0];
            format!(
                "no own value, mask {}, n_x {}",
                result.mask[cell],
                if nx == 0.0 {
                    "unknown".to_string()
                } else {
                    format!("{:.1}", (nx * 5.0).round() / 5.0)
                }
            )
        };
        *causes.entry(cause).or_default() += 1;
    }
    println!("untrusted of {} face points: {causes:?}", face.len());
}
