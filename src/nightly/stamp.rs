//! The names of the dated result folders `process --then` writes
//! (`DATASET/models/STAMP/`, `gap/STAMP/`, `report/STAMP/`): the UTC time
//! of the night, `YYYY-MM-DDTHHMMSSZ`. Folders written before seconds were
//! added (`YYYY-MM-DDTHHMMZ`) are still read, counted and ordered.
//!
//! One night's steps share one stamp, and no two nights share one: a stamp
//! already used under any of the folders moves on by a second
//! ([`fresh`]). Before, two nights within one minute wrote into the same
//! folder, so a folder could hold one night's files beside another's.

use std::path::Path;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The folders under a dataset that hold the `--then` steps' dated results.
pub const RESULT_FOLDERS: [&str; 3] = ["models", "gap", "report"];

/// `YYYY-MM-DDTHHMMSSZ` of a time (UTC).
pub fn utc_stamp(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (year, month, day) = crate::calendar::civil_from_days(days);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Whether `name` is a stamp: `YYYY-MM-DDTHHMMSSZ`, or the older
/// `YYYY-MM-DDTHHMMZ`.
pub fn is_stamp(name: &str) -> bool {
    let b = name.as_bytes();
    let digits = |r: std::ops::Range<usize>| b[r].iter().all(u8::is_ascii_digit);
    let time_digits = match b.len() {
        16 => 4,
        18 => 6,
        _ => return false,
    };
    digits(0..4)
        && b[4] == b'-'
        && digits(5..7)
        && b[7] == b'-'
        && digits(8..10)
        && b[10] == b'T'
        && digits(11..11 + time_digits)
        && b[11 + time_digits] == b'Z'
}

/// A stamp in the seconds form, to order stamps of both forms in time: an
/// older minute stamp counts as that minute's second 0.
pub fn time_order(stamp: &str) -> String {
    if stamp.len() == 16 {
        format!("{}00Z", &stamp[..15])
    } else {
        stamp.to_string()
    }
}

/// The stamp of `now`, or of the first second after it that no folder
/// under `dataset/sub` uses yet (in either form), for every `sub`: the
/// night's folders are its own.
pub fn fresh(dataset: &Path, subs: &[&str], now: SystemTime) -> String {
    let used: Vec<String> = subs
        .iter()
        .filter_map(|sub| std::fs::read_dir(dataset.join(sub)).ok())
        .flat_map(|entries| entries.flatten())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| is_stamp(n))
        .map(|n| time_order(&n))
        .collect();
    let mut t = now;
    loop {
        let stamp = utc_stamp(t);
        if !used.contains(&stamp) {
            return stamp;
        }
        t += Duration::from_secs(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: u64) -> SystemTime {
        UNIX_EPOCH + Duration::from_secs(s)
    }

    #[test]
    fn utc_stamps_by_hand() {
        assert_eq!(utc_stamp(at(0)), "1970-01-01T000000Z");
        // `date -u -d @951782400` = 2000-02-29 00:00:00 (a leap day of a century year).
        assert_eq!(utc_stamp(at(951_782_400)), "2000-02-29T000000Z");
        // `date -u -d @1795437000` = 2026-11-23 12:30:00; 59 s later.
        assert_eq!(utc_stamp(at(1_795_437_000)), "2026-11-23T123000Z");
        assert_eq!(utc_stamp(at(1_795_437_059)), "2026-11-23T123059Z");
        // `date -u -d @1798761599` = 2026-12-31 23:59:59.
        assert_eq!(utc_stamp(at(1_798_761_599)), "2026-12-31T235959Z");
    }

    #[test]
    fn stamps_by_hand() {
        assert!(is_stamp("2026-11-30T213005Z"));
        assert!(is_stamp("2026-11-30T2130Z"));
        assert!(!is_stamp("2026-11-30T21300Z"));
        assert!(!is_stamp("2026-11-30T2130"));
        assert!(!is_stamp("2026-11-30T213005"));
        assert!(!is_stamp("2026-11-30 2130Z"));
        assert!(!is_stamp("2026-1a-30T2130Z"));
        assert!(!is_stamp("2026-11-30T2130aaZ"));
        assert!(!is_stamp("baseline"));
        assert!(!is_stamp(""));
    }

    #[test]
    fn both_forms_order_in_time() {
        let mut names = [
            "2026-11-30T2131Z",
            "2026-11-30T213059Z",
            "2026-11-30T2130Z",
            "2026-11-30T213001Z",
            "2026-11-29T235959Z",
        ];
        names.sort_by_key(|n| time_order(n));
        assert_eq!(
            names,
            [
                "2026-11-29T235959Z",
                "2026-11-30T2130Z",
                "2026-11-30T213001Z",
                "2026-11-30T213059Z",
                "2026-11-30T2131Z",
            ]
        );
    }

    #[test]
    fn a_used_stamp_moves_on_by_a_second() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let now = at(1_795_437_000); // 2026-11-23 12:30:00
        assert_eq!(fresh(d, &["models", "gap"], now), "2026-11-23T123000Z");
        // Used under one folder (the older form names the same second), or
        // under another: each moves the stamp on.
        std::fs::create_dir_all(d.join("models/2026-11-23T1230Z")).unwrap();
        assert_eq!(fresh(d, &["models", "gap"], now), "2026-11-23T123001Z");
        std::fs::create_dir_all(d.join("gap/2026-11-23T123001Z")).unwrap();
        assert_eq!(fresh(d, &["models", "gap"], now), "2026-11-23T123002Z");
        // A folder not asked about does not.
        std::fs::create_dir_all(d.join("report/2026-11-23T123002Z")).unwrap();
        assert_eq!(fresh(d, &["models", "gap"], now), "2026-11-23T123002Z");
    }
}
