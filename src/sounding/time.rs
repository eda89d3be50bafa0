//! Stage 1 — ingest: the nominal time that picks one sounding of a file holding several. In: a
//! time as a user writes it (`2010-06-01 12`, `2010-06-01T12`, `2010-06-01T12:00Z`,
//! `2010-06-01 12:00`). Out: the canonical `"YYYY-MM-DD HH"` (UTC) that the readers compare
//! with, and, when no sounding has that time, a short message: how many there are, the first
//! and last few and the ones nearest to the time asked for — never the whole list, which for a
//! decades-long IGRA2 record runs to tens of thousands of entries. Also: the `yyyy, mm, dd,
//! hh:mm:ss` times of NCAR/EOL headers ([`CommaTime`]) and their display form.

/// The canonical form `"YYYY-MM-DD HH"` of a nominal time, or why `text` is not one. Accepted:
/// a date `YYYY-MM-DD`, a space or `T`, an hour `HH`, optionally `:00` (or `:00:00`) and `Z`.
pub fn canonical_time(text: &str) -> Result<String, String> {
    let bad = || {
        format!(
            "{text:?} is not a nominal time: expected \"YYYY-MM-DD HH\" (UTC), e.g. \
             \"2010-06-01 12\" or \"2010-06-01T12:00Z\""
        )
    };
    let t = text.trim();
    let t = t.strip_suffix(['Z', 'z']).unwrap_or(t);
    if t.len() < 13 || !t.is_ascii() {
        return Err(bad());
    }
    let (date, rest) = t.split_at(10);
    let (sep, rest) = rest.split_at(1);
    let (hour, minutes) = rest.split_at(2);
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|c| c.is_ascii_digit());
    let date_ok = date.len() == 10
        && date.as_bytes()[4] == b'-'
        && date.as_bytes()[7] == b'-'
        && digits(&date[..4])
        && digits(&date[5..7])
        && digits(&date[8..]);
    let minutes_ok = matches!(minutes, "" | ":00" | ":00:00");
    if !(date_ok && matches!(sep, " " | "T" | "t") && digits(hour) && minutes_ok) {
        return Err(bad());
    }
    let (month, day, h): (u32, u32, u32) = (
        date[5..7].parse().map_err(|_| bad())?,
        date[8..].parse().map_err(|_| bad())?,
        hour.parse().map_err(|_| bad())?,
    );
    if !(1..=12).contains(&month) || !(1..=31).contains(&day) || h > 23 {
        return Err(bad());
    }
    Ok(format!("{date} {hour}"))
}

/// A date and time of day (UTC) written the way NCAR/EOL file headers write them:
/// `2024, 02, 26, 11:20:12` (year, month, day, then `hh:mm:ss`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CommaTime {
    /// Four-digit year.
    pub year: u32,
    /// Month, 1–12.
    pub month: u32,
    /// Day of the month, 1–31.
    pub day: u32,
    /// Hour, 0–23.
    pub hour: u32,
    /// Minute, 0–59.
    pub minute: u32,
    /// Second, 0–59.
    pub second: u32,
}

impl CommaTime {
    /// Reads `yyyy, mm, dd, hh:mm:ss` (fields of one or two digits, the year of four, spaces
    /// optional); `None` for anything else or for an impossible date or time.
    pub fn parse(text: &str) -> Option<CommaTime> {
        let number = |s: &str, max_len: usize| {
            let s = s.trim();
            let ok = !s.is_empty() && s.len() <= max_len && s.bytes().all(|b| b.is_ascii_digit());
            ok.then(|| s.parse::<u32>().ok()).flatten()
        };
        let parts: Vec<&str> = text.trim().split(',').collect();
        let [year, month, day, clock] = parts.as_slice() else {
            return None;
        };
        let clock: Vec<&str> = clock.split(':').collect();
        let [hour, minute, second] = clock.as_slice() else {
            return None;
        };
        let t = CommaTime {
            year: number(year, 4).filter(|y| *y >= 1000)?,
            month: number(month, 2).filter(|m| (1..=12).contains(m))?,
            day: number(day, 2).filter(|d| (1..=31).contains(d))?,
            hour: number(hour, 2).filter(|h| *h <= 23)?,
            minute: number(minute, 2).filter(|m| *m <= 59)?,
            second: number(second, 2).filter(|s| *s <= 59)?,
        };
        Some(t)
    }

    /// `"YYYY-MM-DD HH:MM:SS UTC"`, e.g. `"2024-02-26 11:20:12 UTC"`.
    pub fn readable(&self) -> String {
        format!(
            "{:04}-{:02}-{:02} {:02}:{:02}:{:02} UTC",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )
    }

    /// The canonical nominal time `"YYYY-MM-DD HH"` ([`canonical_time`]) when the time is on
    /// the hour; `None` otherwise (a nominal time is an hour).
    pub fn nominal(&self) -> Option<String> {
        (self.minute == 0 && self.second == 0).then(|| {
            format!(
                "{:04}-{:02}-{:02} {:02}",
                self.year, self.month, self.day, self.hour
            )
        })
    }
}

/// A time for display: EOL's comma form (`2024, 02, 26, 11:20:12`) becomes
/// `"2024-02-26 11:20:12 UTC"` ([`CommaTime::readable`]); any other text is returned trimmed.
pub fn readable_time(text: &str) -> String {
    CommaTime::parse(text).map_or_else(|| text.trim().to_string(), |t| t.readable())
}

/// Hours since an arbitrary epoch of a canonical time (for "nearest"); `None` if malformed.
fn hours(canonical: &str) -> Option<i64> {
    let y: i64 = canonical.get(..4)?.parse().ok()?;
    let m: i64 = canonical.get(5..7)?.parse().ok()?;
    let d: i64 = canonical.get(8..10)?.parse().ok()?;
    let h: i64 = canonical.get(11..13)?.parse().ok()?;
    // Days from civil (Howard Hinnant's algorithm), proleptic Gregorian.
    let (y, m) = if m <= 2 { (y - 1, m + 9) } else { (y, m - 3) };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * m + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some((era * 146_097 + doe) * 24 + h)
}

/// The times of a file in short: all of them when there are at most four, else the first and
/// the last (`"2013-05-17 00 … 2013-05-22 00"`).
pub fn span(times: &[String]) -> String {
    match times {
        [first, .., last] if times.len() > 4 => format!("{first} … {last}"),
        _ => times.join(", "),
    }
}

/// How many entries the message shows at each end of the list and nearest to the time.
const SHOWN: usize = 3;

/// The message for a time that no sounding of a file has: the count, the first and last
/// [`SHOWN`] times, and the [`SHOWN`] nearest to `wanted` (all canonical, in file order).
pub fn no_such_time(wanted: &str, available: &[String]) -> String {
    if available.is_empty() {
        return format!("no sounding at {wanted:?}: the file holds no soundings");
    }
    let list = |v: &[String]| v.join(", ");
    let ends = if available.len() <= 2 * SHOWN {
        list(available)
    } else {
        format!(
            "{} … {}",
            list(&available[..SHOWN]),
            list(&available[available.len() - SHOWN..])
        )
    };
    let mut text = format!(
        "no sounding at {wanted:?}: the file holds {} sounding{} ({ends})",
        available.len(),
        if available.len() == 1 { "" } else { "s" }
    );
    if let Some(w) = hours(wanted) {
        let mut near: Vec<&String> = available.iter().collect();
        near.sort_by_key(|t| hours(t).map_or(i64::MAX, |h| (h - w).abs()));
        near.dedup();
        let near: Vec<&str> = near.iter().take(SHOWN).map(|s| s.as_str()).collect();
        text.push_str(&format!("; nearest: {}", near.join(", ")));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_the_usual_spellings_and_refuses_the_rest() {
        for t in [
            "2010-06-01 12",
            "2010-06-01T12",
            "2010-06-01T12:00Z",
            " 2010-06-01 12:00:00 ",
            "2010-06-01t12z",
        ] {
            assert_eq!(canonical_time(t).unwrap(), "2010-06-01 12", "{t}");
        }
        for t in [
            "2010-06-01",
            "2010-6-1 12",
            "2010-06-01 24",
            "2010-13-01 00",
            "2010-06-01 12:30",
            "tuesday",
            "2010-06-01 1",
            "2010-06-01é12",
        ] {
            let e = canonical_time(t).unwrap_err();
            assert!(e.contains("not a nominal time"), "{t}: {e}");
        }
    }

    #[test]
    fn a_missing_time_is_summarised_with_its_neighbours() {
        let all: Vec<String> = (0..30_000)
            .map(|i| {
                let day = i / 2;
                format!(
                    "{:04}-{:02}-{:02} {:02}",
                    1980 + day / 360,
                    1 + (day / 30) % 12,
                    1 + day % 30,
                    12 * (i % 2)
                )
            })
            .collect();
        let m = no_such_time("1990-03-05 06", &all);
        assert!(m.len() < 300, "{} chars: {m}", m.len());
        assert!(m.contains("holds 30000 soundings"), "{m}");
        assert!(
            m.contains("1980-01-01 00, 1980-01-01 12, 1980-01-02 00 …"),
            "{m}"
        );
        assert!(m.contains("nearest: 1990-03-05 00, 1990-03-05 12"), "{m}");
        let few = no_such_time("2010-06-03 00", &all[..2]);
        assert!(
            few.ends_with("(1980-01-01 00, 1980-01-01 12); nearest: 1980-01-01 12, 1980-01-01 00"),
            "{few}"
        );
        assert!(no_such_time("x", &[]).contains("holds no soundings"));
    }

    #[test]
    fn eol_comma_times_read_and_print() {
        let t = CommaTime::parse("2024, 02, 26, 11:20:12").unwrap();
        assert_eq!(
            (t.year, t.month, t.day, t.hour, t.minute, t.second),
            (2024, 2, 26, 11, 20, 12)
        );
        assert_eq!(t.readable(), "2024-02-26 11:20:12 UTC");
        assert_eq!(t.nominal(), None);
        let n = CommaTime::parse("2024,2,26,12:00:00").unwrap();
        assert_eq!(n.nominal().as_deref(), Some("2024-02-26 12"));
        assert_eq!(
            canonical_time(&n.nominal().unwrap()).unwrap(),
            "2024-02-26 12"
        );
        for bad in [
            "2024-02-26 11:20:12",
            "2024, 13, 26, 11:20:12",
            "2024, 02, 26, 24:00:00",
            "2024, 02, 26, 11:20",
            "24, 02, 26, 11:20:12",
            "2024, 02, 26, 11:20:12, 5",
            "2024, 02, x, 11:20:12",
            "",
        ] {
            assert_eq!(CommaTime::parse(bad), None, "{bad}");
        }
        assert_eq!(
            readable_time(" 2022, 02, 22, 22:00:00 "),
            "2022-02-22 22:00:00 UTC"
        );
        assert_eq!(
            readable_time(" 2026-02-05 23:29 UTC "),
            "2026-02-05 23:29 UTC"
        );
    }

    #[test]
    fn hours_count_across_months_and_leap_days() {
        let h = |t| hours(t).unwrap();
        assert_eq!(h("2024-03-01 00") - h("2024-02-28 00"), 48);
        assert_eq!(h("2023-03-01 00") - h("2023-02-28 00"), 24);
        assert_eq!(h("2011-01-01 00") - h("2010-12-31 12"), 12);
    }
}
