//! What the command line adds to a library error: the flag that gets past
//! it. The library's errors say what is wrong and know nothing of flags.

use looming::commands::eval::EvalError;
use looming::commands::render::RenderError;
use looming::kitti::ImportError;
use looming::output::OutputError;
use looming::pipeline::{ProcessError, ReplayError};
use looming::synth::SynthError;
use looming::topics::{Role, TopicError};

/// The remedy to print after `error`, if the command line has one.
pub(crate) fn hint(error: &anyhow::Error) -> Option<String> {
    if exists_already(error) {
        return Some(" (use --force to replace it)".into());
    }
    if let Some(ProcessError::AlreadyProcessed { .. }) = error.downcast_ref::<ProcessError>() {
        return Some(
            "; process the original log, or pass --replace to drop these channels and write fresh ones"
                .into(),
        );
    }
    match topic_error(error)? {
        TopicError::Ambiguous { role, .. } => Some(format!("\nchoose one with {}", flag(*role)?)),
        _ => None,
    }
}

/// An output that exists, without `--force`.
fn exists_already(error: &anyhow::Error) -> bool {
    let output = error
        .downcast_ref::<OutputError>()
        .or_else(|| match error.downcast_ref::<ProcessError>() {
            Some(ProcessError::Output(output)) => Some(output),
            _ => None,
        })
        .or_else(|| match error.downcast_ref::<SynthError>() {
            Some(SynthError::Output(output)) => Some(output),
            _ => None,
        })
        .or_else(|| match error.downcast_ref::<ImportError>() {
            Some(ImportError::Output(output)) => Some(output),
            _ => None,
        });
    matches!(output, Some(OutputError::Exists { .. }))
        || matches!(
            error.downcast_ref::<RenderError>(),
            Some(RenderError::Exists { .. })
        )
}

/// The topic choice that failed, whichever command met it.
fn topic_error(error: &anyhow::Error) -> Option<&TopicError> {
    if let Some(ProcessError::Topic { source, .. }) = error.downcast_ref::<ProcessError>() {
        return Some(source);
    }
    if let Some(EvalError::Topic { source, .. }) = error.downcast_ref::<EvalError>() {
        return Some(source);
    }
    if let Some(RenderError::Replay(e)) = error.downcast_ref::<RenderError>() {
        return replay_topic_error(e);
    }
    error
        .downcast_ref::<ReplayError>()
        .and_then(replay_topic_error)
}

fn replay_topic_error(error: &ReplayError) -> Option<&TopicError> {
    match error {
        ReplayError::Topic { source, .. } => Some(source),
        _ => None,
    }
}

/// The flag that chooses the topic of `role`.
fn flag(role: Role) -> Option<&'static str> {
    match role {
        Role::Lidar => Some("--lidar-topic"),
        Role::Imu => Some("--imu-topic"),
        Role::Velocity => Some("--velocity-topic"),
        Role::Tf | Role::TfStatic => None,
    }
}
