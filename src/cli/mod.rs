//! The `looming` command line: arguments ([`args`], clap only), their checks
//! and the configuration they resolve to ([`resolve`]), what the commands
//! print ([`report`]), and here the dispatch to the library and the exit
//! codes. All the work is in the library.

mod args;
mod choices;
pub mod cpu;
mod hints;
mod report;
mod resolve;

use looming::output::OutputError;
use looming::pipeline::ProcessError;

pub use args::Cli;
use args::{
    BatchArgs, Command, EvalArgs, EventsArgs, ImportKittiArgs, InspectArgs, LayoutArgs,
    ProcessArgs, QualityArgs, RenderArgs, SynthArgs,
};
pub(crate) use hints::hint;
use report::{Progress, summary_text};

/// Exit code of a run stopped by Ctrl-C (SIGINT), as shells report it.
pub(crate) const EXIT_INTERRUPTED: i32 = 130;

/// Ctrl-C asks the run to stop: it ends at its next record, removes its
/// temporary output and exits with [`EXIT_INTERRUPTED`]; a second Ctrl-C
/// exits at once (the temporary file is then left, and a later `batch` or
/// `--force` run removes or replaces it).
pub fn stop_on_ctrl_c() {
    let handler = || {
        if looming::pipeline::stop_requested() {
            std::process::exit(EXIT_INTERRUPTED);
        }
        looming::pipeline::request_stop();
    };
    // Without a handler (another one is installed) Ctrl-C still ends the
    // run, only less cleanly.
    let _ = ctrlc::set_handler(handler);
}

/// An error with its exit code.
pub struct Failure {
    pub error: anyhow::Error,
    pub code: i32,
}

impl Failure {
    fn with_code(error: impl Into<anyhow::Error>, code: i32) -> Self {
        Failure {
            error: error.into(),
            code,
        }
    }
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(error: E) -> Self {
        Failure {
            error: error.into(),
            code: 1,
        }
    }
}

/// Run the command.
pub fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Process(args) => process(args),
        Command::Batch(args) => batch(args),
        Command::Inspect(args) => inspect(args),
        Command::Layout(args) => layout(args),
        Command::Synth(args) => synth(args),
        Command::Eval(args) => eval(args),
        Command::Events(args) => events(args),
        Command::Quality(args) => quality(args),
        Command::ImportKitti(args) => import_kitti(args),
        Command::Render(args) => render(args),
    }
}

fn process(args: ProcessArgs) -> Result<(), Failure> {
    let config = resolve::process_config(&args)?;
    let clips = resolve::process_clips(&args)?;
    let progress = Progress::new(args.quiet);
    let result = looming::pipeline::process(&config, &progress);
    progress.bar.finish_and_clear();
    let summary = result.map_err(|error| {
        let code = match &error {
            ProcessError::Topic { .. } | ProcessError::AlreadyProcessed { .. } => 2,
            ProcessError::Output(OutputError::Exists { .. } | OutputError::SameAsInput { .. }) => 2,
            ProcessError::Strict(_) => 3,
            ProcessError::Interrupted { .. } => EXIT_INTERRUPTED,
            _ => 1,
        };
        Failure {
            error: error.into(),
            code,
        }
    })?;
    if let Some(path) = &args.json_summary {
        let json = serde_json::to_string_pretty(&summary)?;
        std::fs::write(path, json).map_err(|e| {
            anyhow::anyhow!("{}: cannot write the JSON summary: {e}", path.display())
        })?;
    }
    if !args.quiet {
        eprint!("{}", summary_text(&summary));
    }
    if let Some((dir, seconds)) = clips {
        let stem = config
            .output
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy();
        let written = looming::commands::clips::write_clips(
            &config.output,
            &summary.events,
            &dir,
            &stem,
            seconds,
            args.force,
        )
        .map_err(|error| {
            let code = match &error {
                looming::commands::clips::ClipError::Output(OutputError::Exists { .. }) => 2,
                _ => 1,
            };
            Failure::with_code(error, code)
        })?;
        if !args.quiet {
            eprint!("{}", report::clips_text(&written, &dir));
        }
    }
    Ok(())
}

fn batch(args: BatchArgs) -> Result<(), Failure> {
    use looming::commands::batch::{LogRecord, merge_records, run_batch};
    if let Some(out_dir) = &args.merge_only {
        let records = merge_records(out_dir)?;
        if !args.quiet {
            eprint!("{}", report::merge_summary(&records, out_dir));
        }
        return failed_logs(records.iter(), out_dir);
    }
    let options = resolve::batch_options(&args)?;
    if args.list {
        return list_batch(&options);
    }
    let bar = report::BatchBar::new(args.quiet);
    let outcomes = run_batch(&options, &bar);
    bar.bar.finish_and_clear();
    let outcomes = outcomes.map_err(batch_failure)?;
    if !args.quiet {
        eprint!("{}", report::batch_summary(&outcomes, &options));
    }
    let records: Vec<&LogRecord> = outcomes.iter().map(|o| &o.record).collect();
    failed_logs(records.into_iter(), &options.out_dir)
}

/// Exit code 2 for a usage error (an --only that names no log), else 1.
fn batch_failure(error: looming::commands::batch::BatchError) -> Failure {
    let code = match error {
        looming::commands::batch::BatchError::Interrupted => EXIT_INTERRUPTED,
        _ if error.is_usage() => 2,
        _ => 1,
    };
    Failure::with_code(error, code)
}

/// `batch --list`: the logs, one JSON object per line on stdout.
fn list_batch(options: &looming::commands::batch::BatchOptions) -> Result<(), Failure> {
    use looming::commands::batch::{output_path, plan};
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    for log in plan(options).map_err(batch_failure)? {
        let line = serde_json::json!({
            "relative": log.relative,
            "input": log.input,
            "output": output_path(&options.out_dir, &log),
        });
        writeln!(stdout, "{line}").map_err(anyhow::Error::from)?;
    }
    Ok(())
}

/// Exit code 1 when any log failed.
fn failed_logs<'a>(
    records: impl Iterator<Item = &'a looming::commands::batch::LogRecord>,
    out_dir: &std::path::Path,
) -> Result<(), Failure> {
    let failed = records
        .filter(|r| r.entry.status == looming::commands::batch::LogStatus::Failed)
        .count();
    if failed > 0 {
        return Err(Failure::with_code(
            anyhow::anyhow!(
                "{failed} logs failed (see {})",
                out_dir.join("logs").display()
            ),
            1,
        ));
    }
    Ok(())
}

fn eval(args: EvalArgs) -> Result<(), Failure> {
    let config = looming::engine::EngineConfig {
        rotation_compensation: !args.no_rotation_compensation,
        firings_per_column: usize::from(args.firings_per_column),
        ..Default::default()
    };
    let scans = resolve::scan_options(&args.scans)?;
    let report = looming::commands::eval::evaluate_against(
        &args.file,
        &config,
        args.truth.as_deref(),
        &scans,
    )
    .map_err(|error| {
        let strict = matches!(error, looming::commands::eval::EvalError::Strict(_));
        Failure::with_code(error, if strict { 3 } else { 1 })
    })?;
    print!("{}", report.to_text());
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .map_err(|e| anyhow::anyhow!("{}: cannot write the report: {e}", path.display()))?;
    }
    Ok(())
}

fn render(args: RenderArgs) -> Result<(), Failure> {
    let options = resolve::render_options(&args)?;
    let summary = looming::commands::render::render(&options).map_err(|error| {
        let code = if error.is_usage() {
            2
        } else if error.is_strict() {
            3
        } else {
            1
        };
        Failure::with_code(error, code)
    })?;
    eprintln!(
        "looming render: pair {} (stamp {}), {} x {} px -> {}",
        summary.pair_index,
        looming::model::format_log_time(summary.stamp_ns.max(0) as u64),
        summary.width_px,
        summary.height_px,
        summary.output.display()
    );
    Ok(())
}

fn layout(args: LayoutArgs) -> Result<(), Failure> {
    looming::output::check_output_path(&args.log, &args.output, args.force)
        .map_err(|error| Failure::with_code(error, 2))?;
    let target = looming::commands::layout::target_of(&args.log, args.lidar_topic.as_deref());
    let target = target.map_err(|error| {
        let code = match error {
            looming::commands::layout::LayoutError::Topic { .. } => 2,
            _ => 1,
        };
        Failure::with_code(error, code)
    })?;
    looming::commands::layout::write_layout(&args.output, &target)?;
    eprintln!(
        "looming layout: 3D panel in frame {} (from {}) -> {}",
        target.frame_id,
        target.frame_from,
        args.output.display()
    );
    Ok(())
}

fn inspect(args: InspectArgs) -> Result<(), Failure> {
    let report = looming::commands::inspect::inspect(&args.file)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    Ok(())
}

fn events(args: EventsArgs) -> Result<(), Failure> {
    let mut events = looming::commands::events::read_events(&args.file)?;
    looming::events::rank(&mut events);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&events)?);
    } else {
        print!("{}", looming::commands::events::events_table(&events));
    }
    Ok(())
}

fn quality(args: QualityArgs) -> Result<(), Failure> {
    let report = looming::commands::quality::read_quality(&args.file).map_err(|error| {
        let usage = matches!(
            error,
            looming::commands::quality::QualityError::NotProcessed { .. }
        );
        Failure::with_code(error, if usage { 2 } else { 1 })
    })?;
    print!("{}", report.to_text());
    if let Some(path) = &args.json {
        let json = serde_json::to_vec_pretty(&report)?;
        std::fs::write(path, json)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    }
    Ok(())
}

fn synth(args: SynthArgs) -> Result<(), Failure> {
    let options = looming::synth::SynthOptions {
        scenario: args.scenario,
        output: args.output,
        seed: args.seed,
        start_s: args.start,
        duration_s: args.duration,
        beams: args.beams,
        columns: args.columns,
        output_options: looming::output::OutputOptions {
            force: args.force,
            compression_level: args.compression_level.unwrap_or(0),
            ..looming::output::OutputOptions::default()
        },
    };
    let lidar = looming::synth::LidarOverrides {
        layout: args.layout,
        realism: None,
        lidars: args.lidars,
        frame: args.frame,
        one_topic: args.one_topic,
    };
    let summary = looming::synth::synthesize_with(&options, &lidar).map_err(|error| {
        let usage = matches!(
            &error,
            looming::synth::SynthError::Scenario(_)
                | looming::synth::SynthError::Output(OutputError::Exists { .. })
        );
        Failure::with_code(error, if usage { 2 } else { 1 })
    })?;
    if !args.quiet {
        eprintln!(
            "looming synth {}: {} scans, {} points, {} messages, {:.1} MB in {:.2} s -> {}",
            summary.scenario,
            summary.scans,
            summary.points,
            summary.messages,
            summary.output_bytes as f64 / 1e6,
            summary.elapsed_s,
            summary.output
        );
        for event in &summary.events {
            eprintln!(
                "  planted near miss: actor {} ({}) {:.2}..{:.2} s, min time to contact {:.2} s",
                event.actor_id,
                event.label,
                event.start_s,
                event.end_s,
                event.min_time_to_contact_s
            );
        }
    }
    Ok(())
}

fn import_kitti(args: ImportKittiArgs) -> Result<(), Failure> {
    let options = looming::kitti::ImportOptions {
        drive_dir: args.drive,
        calib_dir: args.calib,
        output: args.output,
        output_options: looming::output::OutputOptions {
            force: args.force,
            ..looming::output::OutputOptions::default()
        },
        max_points: args.max_points,
        sweep: args.sweep.into(),
    };
    let summary = looming::kitti::import_kitti(&options).map_err(|error| {
        let usage = matches!(
            &error,
            looming::kitti::ImportError::Output(OutputError::Exists { .. })
        );
        Failure::with_code(error, if usage { 2 } else { 1 })
    })?;
    if !args.quiet {
        eprintln!(
            "looming import-kitti: {} scans ({} points, {} missing), {} OXTS packets ({} missing), {:.1} MB in {:.2} s -> {}",
            summary.scans_written,
            summary.points_written,
            summary.scans_missing,
            summary.oxts_written,
            summary.oxts_missing,
            summary.output_bytes as f64 / 1e6,
            summary.elapsed_s,
            summary.output
        );
        eprintln!(
            "  sweep times   {}; turning {:?}; rings derived in {} of {} scans",
            summary.sweep_times,
            summary.sweep_direction,
            summary.scans_with_rings,
            summary.scans_written
        );
        if let Some(calib) = &summary.calibration {
            eprintln!("  calibration   {calib}");
        }
        for warning in &summary.warnings {
            eprintln!("  warning       {warning}");
        }
    }
    Ok(())
}
