//! Write a fixture drive log of any size, for measuring `looming process`:
//! `cargo run --release --example drive_log -- OUT.mcap [SCANS] [BEAMS] [COLUMNS]`.

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(out) = args.get(1) else {
        eprintln!("usage: drive_log OUT.mcap [SCANS] [BEAMS] [COLUMNS]");
        std::process::exit(2);
    };
    let number = |i: usize, default: u32| {
        args.get(i)
            .map_or(default, |a| a.parse().expect("a number"))
    };
    let spec = looming::testkit::DriveSpec {
        scans: number(2, 600),
        beams: number(3, 64) as u16,
        columns: number(4, 2048),
        wall_distance_m: 1000.0,
        layout: looming::testkit::Layout {
            chunk_size: 4 << 20,
            ..looming::testkit::Layout::indexed()
        },
        ..looming::testkit::DriveSpec::default()
    };
    std::fs::write(out, looming::testkit::drive_log(&spec)).expect("write the log");
}
