//! Per-scan ground-truth statistics of a scenario, for designing scenarios:
//! `cargo run --release --example truth_stats -- SCENARIO [BEAMS COLUMNS DURATION]`.

use looming::synth::sensor::World;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut scenario = looming::synth::scene::load(&args[1]).expect("scenario");
    if args.len() >= 5 {
        scenario.lidar.beams = args[2].parse().unwrap();
        scenario.lidar.columns = args[3].parse().unwrap();
        scenario.duration_s = args[4].parse().unwrap();
    }
    let world = World::new(scenario);
    println!(
        "scan  t_s   points  | per actor: id points max_ray_looming n_over_0.667 | static: max_ray max_point"
    );
    for index in 0..world.scan_count() {
        let scan = world.scan(index, 1);
        let mut line = format!("{index:4} {:5.2} {:7} |", scan.stamp_s, scan.points.len());
        for actor in &world.scenario.actors {
            let looming: Vec<f64> = scan
                .points
                .iter()
                .filter(|p| p.truth.object_id == actor.id)
                .map(|p| p.truth.ray_looming_per_s)
                .collect();
            let max = looming.iter().copied().fold(f64::NAN, f64::max);
            let over = scan
                .points
                .iter()
                .filter(|p| {
                    p.truth.object_id == actor.id
                        && p.truth.incidence_cos >= 0.5
                        && p.truth.ray_looming_per_s >= 1.0 / 1.5
                })
                .count();
            line += &format!(" {} {:5} {:7.3} {:5} |", actor.id, looming.len(), max, over);
        }
        let statics = scan.points.iter().filter(|p| p.truth.object_id == 0);
        let (mut max_ray, mut max_point) = (f64::NAN, f64::NAN);
        for p in statics {
            max_ray = max_ray.max(p.truth.ray_looming_per_s);
            max_point = max_point.max(p.truth.point_looming_per_s);
        }
        line += &format!(" {max_ray:7.3} {max_point:7.3}");
        println!("{line}");
    }
}
