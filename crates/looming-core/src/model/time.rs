//! Log times as people read them.

/// Log time as seconds.nanoseconds, as `mcap cat` prints it.
pub fn format_log_time(log_time_ns: u64) -> String {
    format!(
        "{}.{:09} s",
        log_time_ns / 1_000_000_000,
        log_time_ns % 1_000_000_000
    )
}
