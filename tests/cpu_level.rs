//! The binary on a CPU older than its build's level (`.cargo/config.toml`:
//! x86-64-v3) ends with a message that says how to build for it, not with
//! SIGILL; on one of the level it runs. Under `qemu-x86_64` (Debian's
//! `qemu-user`) emulating such CPUs; where qemu is not installed the test
//! says so and passes (it ran where the check was written).

#![cfg(all(target_arch = "x86_64", target_os = "linux", target_feature = "avx2"))]

use std::process::{Command, Output};

/// `looming ARGS` under qemu emulating `cpu`; None without qemu.
fn under_qemu(cpu: &str, args: &[&str]) -> Option<Output> {
    Command::new("qemu-x86_64")
        .args(["-cpu", cpu, env!("CARGO_BIN_EXE_looming")])
        .args(args)
        .output()
        .ok()
}

#[test]
fn an_older_cpu_is_told_how_to_build_and_the_level_runs() {
    // Sandy Bridge has AVX but not AVX2, FMA or BMI: the build's first
    // AVX2 or BMI instruction would be its end.
    let Some(older) = under_qemu("SandyBridge", &["--version"]) else {
        eprintln!("qemu-x86_64 not installed (Debian: qemu-user): not run");
        return;
    };
    let stderr = String::from_utf8_lossy(&older.stderr);
    assert_eq!(older.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("this CPU lacks"), "{stderr}");
    assert!(
        stderr.contains("RUSTFLAGS=\"-C target-cpu=native\""),
        "{stderr}"
    );
    let level = under_qemu("Haswell", &["--version"]).expect("qemu ran above");
    assert!(
        level.status.success(),
        "{}",
        String::from_utf8_lossy(&level.stderr)
    );
    assert!(String::from_utf8_lossy(&level.stdout).starts_with("looming "));
}
