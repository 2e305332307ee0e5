//! KITTI timestamp files (`timestamps.txt`, `timestamps_start.txt`, ...): one
//! `YYYY-MM-DD HH:MM:SS.fffffffff` per line, UTC. Also the bounded file
//! readers shared by the other KITTI parsers.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use super::KittiError;

/// Timestamp files hold one ~30-byte line per frame; 64 MiB is millions of
/// frames, far beyond any drive, yet small enough to read whole.
const MAX_TIMESTAMPS_BYTES: u64 = 64 << 20;

const NS_PER_SECOND: i64 = 1_000_000_000;
const SECONDS_PER_DAY: i64 = 86_400;
/// Fractional seconds are given to at most nanoseconds.
const MAX_FRACTION_DIGITS: usize = 9;

/// Nanoseconds since the Unix epoch of a KITTI timestamp such as
/// `2011-09-26 13:02:25.964389445` (UTC). The fraction may have 0 to 9
/// digits (`13:02:25` and `13:02:25.96` are accepted); surrounding whitespace
/// is ignored. Integer arithmetic only: floats would lose the nanoseconds.
pub(crate) fn parse_timestamp(text: &str) -> Result<i64, String> {
    let text = text.trim();
    let (date, time) = text
        .split_once(' ')
        .ok_or_else(|| format!("expected 'YYYY-MM-DD HH:MM:SS[.fffffffff]', got '{text}'"))?;
    let days = parse_date(date)?;
    let (second_of_day, fraction_ns) = parse_time(time)?;
    days.checked_mul(SECONDS_PER_DAY)
        .and_then(|s| s.checked_add(second_of_day))
        .and_then(|s| s.checked_mul(NS_PER_SECOND))
        .and_then(|ns| ns.checked_add(fraction_ns))
        .ok_or_else(|| format!("'{text}' is outside the range of i64 nanoseconds (1677-2262)"))
}

/// All timestamps of a file, one per line. Trailing empty lines are allowed
/// (files end with a newline, some with two); an empty line followed by more
/// timestamps is an error, as silently skipping it would shift every later
/// frame's time. An empty file gives an empty list (the caller compares the
/// count with the number of frames).
pub(crate) fn read_timestamps(path: &Path) -> Result<Vec<i64>, KittiError> {
    let text = read_text(path, MAX_TIMESTAMPS_BYTES, "timestamps file")?;
    let mut stamps_ns = Vec::new();
    let mut first_blank_line = None;
    for (index, line) in text.lines().enumerate() {
        let line_number = index + 1;
        if line.trim().is_empty() {
            first_blank_line.get_or_insert(line_number);
            continue;
        }
        let malformed = |line, reason| KittiError::Malformed {
            path: path.to_path_buf(),
            line,
            reason,
        };
        if let Some(blank) = first_blank_line {
            return Err(malformed(blank, "empty line before more timestamps".into()));
        }
        stamps_ns.push(parse_timestamp(line).map_err(|reason| malformed(line_number, reason))?);
    }
    Ok(stamps_ns)
}

/// Days since 1970-01-01 of `YYYY-MM-DD`, with the day checked against the
/// month's length (leap years included).
fn parse_date(date: &str) -> Result<i64, String> {
    let mut parts = date.split('-');
    let (Some(year), Some(month), Some(day), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(format!("date '{date}' is not YYYY-MM-DD"));
    };
    let year = parse_digits(year, 4, "year")?;
    let month = parse_digits(month, 2, "month")?;
    let day = parse_digits(day, 2, "day")?;
    if !(1..=12).contains(&month) {
        return Err(format!("month {month} is not in 1..=12"));
    }
    let month_days = days_in_month(year, month);
    if !(1..=month_days).contains(&day) {
        return Err(format!(
            "day {day} is not in 1..={month_days} for {year:04}-{month:02}"
        ));
    }
    Ok(days_from_civil(year, month, day))
}

/// (seconds since midnight, nanoseconds) of `HH:MM:SS[.f...]`.
fn parse_time(time: &str) -> Result<(i64, i64), String> {
    let (clock, fraction) = match time.split_once('.') {
        Some((clock, fraction)) => (clock, Some(fraction)),
        None => (time, None),
    };
    let mut parts = clock.split(':');
    let (Some(hour), Some(minute), Some(second), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(format!("time '{time}' is not HH:MM:SS[.fffffffff]"));
    };
    let hour = parse_digits(hour, 2, "hour")?;
    let minute = parse_digits(minute, 2, "minute")?;
    // Leap seconds (:60) are rejected: KITTI's clocks never emit them.
    let second = parse_digits(second, 2, "second")?;
    if hour > 23 || minute > 59 || second > 59 {
        return Err(format!("time '{clock}' is out of range"));
    }
    let fraction_ns = fraction.map_or(Ok(0), parse_fraction_ns)?;
    Ok((hour * 3600 + minute * 60 + second, fraction_ns))
}

/// Nanoseconds of the digits after the decimal point: `96` is 960 ms.
fn parse_fraction_ns(digits: &str) -> Result<i64, String> {
    if digits.is_empty() || digits.len() > MAX_FRACTION_DIGITS {
        return Err(format!(
            "fraction '{digits}' must have 1 to {MAX_FRACTION_DIGITS} digits"
        ));
    }
    let value = parse_digits(digits, digits.len(), "fraction")?;
    let padding = MAX_FRACTION_DIGITS - digits.len();
    Ok(value * 10_i64.pow(padding as u32))
}

/// A field of exactly `count` ASCII digits (no sign, no spaces: `str::parse`
/// alone would accept `+1`).
fn parse_digits(text: &str, count: usize, what: &str) -> Result<i64, String> {
    if text.len() != count || !text.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!("{what} '{text}' is not {count} digits"));
    }
    text.parse()
        .map_err(|_| format!("{what} '{text}' is not {count} digits"))
}

fn is_leap_year(year: i64) -> bool {
    (year % 4 == 0 && year % 100 != 0) || year % 400 == 0
}

fn days_in_month(year: i64, month: i64) -> i64 {
    match month {
        2 if is_leap_year(year) => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's
/// `days_from_civil`): years start in March so the leap day comes last, and
/// 400-year eras repeat exactly.
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let year = if month <= 2 { year - 1 } else { year };
    let era = year.div_euclid(400);
    let year_of_era = year - era * 400;
    let month_from_march = if month > 2 { month - 3 } else { month + 9 };
    let day_of_year = (153 * month_from_march + 2) / 5 + day - 1;
    let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
    era * 146_097 + day_of_era - 719_468
}

/// A whole text file, refused beyond `max_bytes` before anything is read:
/// the size of an untrusted file must not decide how much memory we take.
/// Shared by the KITTI readers; `what` names the file in `Missing` errors.
pub(super) fn read_text(path: &Path, max_bytes: u64, what: &str) -> Result<String, KittiError> {
    let (file, len_bytes) = open_sized(path, what)?;
    if len_bytes > max_bytes {
        return Err(KittiError::Invalid {
            path: path.to_path_buf(),
            reason: format!("{len_bytes} bytes, more than the {max_bytes}-byte limit for a {what}"),
        });
    }
    let bytes = read_exact_len(file, path, len_bytes)?;
    String::from_utf8(bytes).map_err(|error| {
        let valid = error.as_bytes().get(..error.utf8_error().valid_up_to());
        let newlines = valid.map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count());
        KittiError::Malformed {
            path: path.to_path_buf(),
            line: newlines + 1,
            reason: "not UTF-8 text".into(),
        }
    })
}

/// Open a regular file and report its length. A missing file is `Missing`
/// (the caller's `what`), anything else that fails is `Io`.
pub(super) fn open_sized(path: &Path, what: &str) -> Result<(File, u64), KittiError> {
    let io = |source| KittiError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = File::open(path).map_err(|source: std::io::Error| {
        if source.kind() == std::io::ErrorKind::NotFound {
            KittiError::Missing {
                path: path.to_path_buf(),
                what: what.to_string(),
            }
        } else {
            io(source)
        }
    })?;
    let metadata = file.metadata().map_err(io)?;
    if !metadata.is_file() {
        return Err(KittiError::Invalid {
            path: path.to_path_buf(),
            reason: format!("not a regular file (expected a {what})"),
        });
    }
    Ok((file, metadata.len()))
}

/// Read `len_bytes` (already checked against a limit) and no more: a file
/// that changed size since its metadata was read is refused rather than
/// read without bound.
pub(super) fn read_exact_len(
    file: File,
    path: &Path,
    len_bytes: u64,
) -> Result<Vec<u8>, KittiError> {
    let changed = || KittiError::Invalid {
        path: path.to_path_buf(),
        reason: format!("changed size while being read (expected {len_bytes} bytes)"),
    };
    let capacity = usize::try_from(len_bytes).map_err(|_| changed())?;
    let mut bytes = Vec::with_capacity(capacity);
    file.take(len_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|source| KittiError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    if bytes.len() != capacity {
        return Err(changed());
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamp(text: &str) -> i64 {
        parse_timestamp(text).expect(text)
    }

    fn write(dir: &tempfile::TempDir, name: &str, contents: &[u8]) -> std::path::PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, contents).expect("write temp file");
        path
    }

    #[test]
    fn kitti_timestamp() {
        // `date -u -d '2011-09-26 13:02:25' +%s` is 1317042145.
        assert_eq!(
            stamp("2011-09-26 13:02:25.964389445"),
            1_317_042_145_964_389_445
        );
        assert_eq!(
            stamp("  2011-09-26 13:02:25.964389445\r\n"),
            1_317_042_145_964_389_445
        );
    }

    #[test]
    fn fewer_fraction_digits_are_padded() {
        assert_eq!(stamp("2011-09-26 13:02:25.96"), 1_317_042_145_960_000_000);
        assert_eq!(stamp("2011-09-26 13:02:25.9"), 1_317_042_145_900_000_000);
        assert_eq!(stamp("2011-09-26 13:02:25"), 1_317_042_145_000_000_000);
        assert_eq!(
            stamp("2011-09-26 13:02:25.000000001"),
            1_317_042_145_000_000_001
        );
    }

    #[test]
    fn calendar_edges() {
        assert_eq!(stamp("1970-01-01 00:00:00"), 0);
        // 2012-02-29 is day 15399 since the epoch; 2012-03-01 the next.
        assert_eq!(
            stamp("2012-02-29 00:00:00"),
            15_399 * SECONDS_PER_DAY * NS_PER_SECOND
        );
        assert_eq!(
            stamp("2012-03-01 00:00:00"),
            15_400 * SECONDS_PER_DAY * NS_PER_SECOND
        );
        assert_eq!(
            stamp("2000-02-29 12:00:00"),
            (11_016 * SECONDS_PER_DAY + 43_200) * NS_PER_SECOND
        );
        // One nanosecond before 2012-01-01 (day 15340).
        assert_eq!(
            stamp("2011-12-31 23:59:59.999999999"),
            15_340 * SECONDS_PER_DAY * NS_PER_SECOND - 1
        );
        assert_eq!(stamp("1969-12-31 23:59:59.5"), -500_000_000);
    }

    #[test]
    fn malformed_timestamps_are_refused() {
        for bad in [
            "2011-13-26 13:02:25.964389445",
            "2011-00-26 13:02:25",
            "2011-09-32 13:02:25",
            "2011-09-00 13:02:25",
            "2011-02-29 13:02:25",
            "2011-02-30 13:02:25",
            "1900-02-29 00:00:00",
            "2011-04-31 00:00:00",
            "2011-09-26 24:00:00",
            "2011-09-26 13:60:00",
            "2011-09-26 13:02:60",
            "abcd-09-26 13:02:25",
            "2011-09-26 13:02:2x",
            "2011-09-26",
            "2011-09-26 ",
            "13:02:25.964389445",
            "2011-09-26 13:02:25.9643894451",
            "2011-09-26 13:02:25.",
            "2011-09-26 13:02:25.+5",
            "-2011-09-26 13:02:25",
            "2011-09-26 -13:02:25",
            "2011-9-26 13:02:25",
            "2011-09-26 13:02",
            "2011-09-26 13:02:25:00",
            "2011-09-26-01 13:02:25",
            "2011-09-26  13:02:25",
            "2011-09-26T13:02:25",
            "9999-12-31 23:59:59",
            "",
        ] {
            assert!(parse_timestamp(bad).is_err(), "accepted '{bad}'");
        }
        let reason = parse_timestamp("2011-13-26 13:02:25").unwrap_err();
        assert!(reason.contains("month 13"), "{reason}");
    }

    #[test]
    fn days_from_civil_matches_known_days() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(days_from_civil(2000, 3, 1), 11_017);
        assert_eq!(days_from_civil(1600, 1, 1), -135_140);
    }

    #[test]
    fn reads_a_file_with_trailing_newlines() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(
            &dir,
            "timestamps.txt",
            b"2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.064389445\n\n",
        );
        assert_eq!(
            read_timestamps(&path).expect("valid"),
            vec![1_317_042_145_964_389_445, 1_317_042_146_064_389_445]
        );
        let empty = write(&dir, "empty.txt", b"");
        assert_eq!(read_timestamps(&empty).expect("empty"), Vec::<i64>::new());
    }

    #[test]
    fn bad_third_line_is_reported_as_line_3() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(
            &dir,
            "timestamps.txt",
            b"2011-09-26 13:02:25.1\n2011-09-26 13:02:25.2\n2011-09-26 13:02:2x.3\n",
        );
        match read_timestamps(&path) {
            Err(KittiError::Malformed { line: 3, .. }) => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn empty_line_in_the_middle_is_malformed() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(
            &dir,
            "t.txt",
            b"2011-09-26 13:02:25.1\n\n2011-09-26 13:02:25.2\n",
        );
        match read_timestamps(&path) {
            Err(KittiError::Malformed { line: 2, .. }) => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn missing_file_directory_and_non_utf8() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert!(matches!(
            read_timestamps(&dir.path().join("absent.txt")),
            Err(KittiError::Missing { .. })
        ));
        assert!(matches!(
            read_timestamps(dir.path()),
            Err(KittiError::Invalid { .. })
        ));
        let path = write(&dir, "latin1.txt", b"2011-09-26 13:02:25\n\xff\n");
        assert!(matches!(
            read_timestamps(&path),
            Err(KittiError::Malformed { line: 2, .. })
        ));
    }

    #[test]
    fn size_limit_is_checked_before_reading() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(&dir, "big.txt", b"");
        // A sparse file: its length, not its contents, must trip the limit.
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(&path)
            .expect("open");
        file.set_len(MAX_TIMESTAMPS_BYTES + 1).expect("set_len");
        assert!(matches!(
            read_timestamps(&path),
            Err(KittiError::Invalid { .. })
        ));
        assert!(matches!(
            read_text(&path, 10, "x"),
            Err(KittiError::Invalid { .. })
        ));
    }

    #[test]
    fn read_exact_len_refuses_a_changed_size() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(&dir, "f.bin", b"12345");
        let file = File::open(&path).expect("open");
        assert!(matches!(
            read_exact_len(file, &path, 3),
            Err(KittiError::Invalid { .. })
        ));
        let file = File::open(&path).expect("open");
        assert_eq!(read_exact_len(file, &path, 5).expect("exact"), b"12345");
    }

    #[test]
    fn open_sized_reports_length() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(&dir, "f.bin", b"1234");
        assert_eq!(open_sized(&path, "x").expect("open").1, 4);
    }
}
