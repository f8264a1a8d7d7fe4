//! Where and when a measurement was made: the date, the machine, the threads and the commit
//! that `relume sweep` writes into every row of its CSV, so that a results file says what it
//! measured without anyone copying it by hand.

use std::process::Command;

/// The four provenance columns, in the order they end a results CSV.
pub(crate) const COLUMNS: [&str; 4] = ["date", "machine", "threads", "commit"];

/// The cells of `COLUMNS` for a measurement made now by this process.
pub(crate) fn cells() -> [String; 4] {
    let days = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 86_400);
    [date_of_days(days as i64), machine(), rayon::current_num_threads().to_string(), commit()]
}

/// `YYYY-MM-DD` (UTC) of the day `days` after 1970-01-01 (the civil calendar's arithmetic of
/// Howard Hinnant's `civil_from_days`).
pub(crate) fn date_of_days(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

/// The architecture, the operating system, the logical cores and, on x86_64, the widest
/// vector extension the processor reports: `x86_64 linux with 2 cores (AVX-512)`. A vectorised
/// renderer's speed depends on the last (Mitsuba's LLVM variant compiles for it).
fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let simd = widest_simd().map(|s| format!(" ({s})")).unwrap_or_default();
    format!("{} {} with {cores} cores{simd}", std::env::consts::ARCH, std::env::consts::OS)
}

#[cfg(target_arch = "x86_64")]
fn widest_simd() -> Option<&'static str> {
    if std::arch::is_x86_feature_detected!("avx512f") {
        Some("AVX-512")
    } else if std::arch::is_x86_feature_detected!("avx2") {
        Some("AVX2")
    } else {
        Some("SSE2")
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn widest_simd() -> Option<&'static str> {
    None
}

/// The checked-out commit of the repository around the working folder (12 hex digits, with
/// `-dirty` when tracked files differ from it), or `unknown` outside one or without git.
fn commit() -> String {
    let git = |args: &[&str]| Command::new("git").args(args).output().ok().filter(|o| o.status.success()).map(|o| o.stdout);
    let Some(head) = git(&["rev-parse", "--short=12", "HEAD"]) else { return "unknown".into() };
    let head = String::from_utf8_lossy(&head).trim().to_string();
    let dirty = git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|o| !o.is_empty());
    if dirty {
        format!("{head}-dirty")
    } else {
        head
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn days_since_the_epoch_become_calendar_dates() {
        assert_eq!(date_of_days(0), "1970-01-01");
        assert_eq!(date_of_days(59), "1970-03-01");
        assert_eq!(date_of_days(11_016), "2000-02-29");
        assert_eq!(date_of_days(20_786), "2026-11-29");
        assert_eq!(date_of_days(-1), "1969-12-31");
    }

    #[test]
    fn a_measurement_names_its_machine_and_threads() {
        let [date, machine, threads, commit] = cells();
        assert_eq!(date.len(), 10);
        assert!(machine.contains(std::env::consts::ARCH) && machine.contains(" cores"), "{machine}");
        assert!(threads.parse::<usize>().unwrap() >= 1);
        assert!(!commit.is_empty());
    }
}
