//! The sun's true position at a time and place. In: a UTC time ([`UtcTime`], parsed from
//! `YYYY-MM-DDTHH:MM[:SS][Z]`) and an observer's latitude, longitude and height ([`Site`]). Out:
//! the sun's topocentric elevation and azimuth *without* atmospheric refraction
//! ([`SunPosition`]): the true position that a render's `[sun]` takes, the refraction being what
//! the ray tracer adds.
//!
//! The algorithm is NREL's Solar Position Algorithm (Reda & Andreas 2003, Solar Energy 76,
//! 577–589), as implemented by the `solar-positioning` crate, whose stated uncertainty is
//! ±0.0003° for the years −2000 to 6000. ΔT (TT − UT1) is that crate's estimate for the date
//! (Espenak & Meeus polynomials, refitted from 2015 on); UTC is taken for UT1 (within 0.9 s,
//! at most 0.004° of hour angle).

use solar_positioning::{Location, SolarPositions, time::JulianDate};

/// Seconds in a day.
const DAY_S: i64 = 86_400;
/// Julian date of 1970-01-01 00:00 UTC.
const UNIX_EPOCH_JD: f64 = 2_440_587.5;

/// A solar position could not be computed, or a time could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolarError {
    /// A time is not `YYYY-MM-DDTHH:MM[:SS][Z]` (UTC).
    #[error(
        "{0:?} is not a UTC time: expected YYYY-MM-DDTHH:MM[:SS][Z], e.g. 2026-02-12T13:00Z \
         (a space may replace the T; the minutes may be left out)"
    )]
    Time(String),
    /// Latitude or longitude out of range.
    #[error(
        "the site must have a latitude within -90…90° and a longitude within -180…180°, got {lat_deg}°, {lon_deg}°"
    )]
    Site {
        /// Latitude given (degrees north).
        lat_deg: f64,
        /// Longitude given (degrees east).
        lon_deg: f64,
    },
    /// The solar-position algorithm refused the input (a date outside its range).
    #[error("cannot compute the sun's position at {time}: {message}")]
    Algorithm {
        /// The time asked for.
        time: String,
        /// The algorithm's reason.
        message: String,
    },
}

/// A UTC instant to the second (leap seconds are not represented).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
pub struct UtcTime {
    /// Seconds since 1970-01-01 00:00:00 UTC.
    pub unix_s: i64,
}

impl UtcTime {
    /// Read `YYYY-MM-DD` then `T` or a space, `HH`, optionally `:MM` and `:SS`, then optionally
    /// `Z` or ` UTC`. The date must exist (2026-02-30 is refused).
    pub fn parse(text: &str) -> Result<Self, SolarError> {
        let bad = || SolarError::Time(text.to_string());
        let t = text.trim();
        let t = t
            .strip_suffix(" UTC")
            .or_else(|| t.strip_suffix(['Z', 'z']))
            .unwrap_or(t);
        if !t.is_ascii() || t.len() < 13 {
            return Err(bad());
        }
        let (date, rest) = t.split_at(10);
        if !matches!(rest.as_bytes()[0], b'T' | b't' | b' ') {
            return Err(bad());
        }
        let number = |s: &str, digits: usize| -> Result<i64, SolarError> {
            if s.len() == digits && s.bytes().all(|c| c.is_ascii_digit()) {
                s.parse().map_err(|_| bad())
            } else {
                Err(bad())
            }
        };
        let d: Vec<&str> = date.split('-').collect();
        let [y, mo, da] = d.as_slice() else {
            return Err(bad());
        };
        let (year, month, day) = (number(y, 4)?, number(mo, 2)?, number(da, 2)?);
        let clock: Vec<&str> = rest[1..].split(':').collect();
        let (hour, minute, second) = match clock.as_slice() {
            [h] => (number(h, 2)?, 0, 0),
            [h, m] => (number(h, 2)?, number(m, 2)?, 0),
            [h, m, s] => (number(h, 2)?, number(m, 2)?, number(s, 2)?),
            _ => return Err(bad()),
        };
        let valid = (1..=12).contains(&month)
            && day >= 1
            && day <= days_in_month(year, month)
            && hour < 24
            && minute < 60
            && second < 60;
        if !valid {
            return Err(bad());
        }
        let days = days_from_civil(year, month, day);
        Ok(UtcTime {
            unix_s: days * DAY_S + hour * 3600 + minute * 60 + second,
        })
    }

    /// `YYYY-MM-DDTHH:MM:SSZ`.
    pub fn iso(&self) -> String {
        let days = self.unix_s.div_euclid(DAY_S);
        let s = self.unix_s.rem_euclid(DAY_S);
        let (y, m, d) = civil_from_days(days);
        format!(
            "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
            s / 3600,
            (s / 60) % 60,
            s % 60
        )
    }

    /// This instant plus `seconds`.
    pub fn plus_s(&self, seconds: i64) -> UtcTime {
        UtcTime {
            unix_s: self.unix_s + seconds,
        }
    }

    /// The Julian date (UT).
    pub fn julian_date(&self) -> f64 {
        UNIX_EPOCH_JD + self.unix_s as f64 / DAY_S as f64
    }

    /// The year with its fraction (for ΔT).
    fn decimal_year(&self) -> f64 {
        1970.0 + self.unix_s as f64 / (365.2425 * DAY_S as f64)
    }
}

impl std::fmt::Display for UtcTime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.iso())
    }
}

/// Days in `month` of `year` (proleptic Gregorian).
fn days_in_month(year: i64, month: i64) -> i64 {
    match month {
        2 if (year % 4 == 0 && year % 100 != 0) || year % 400 == 0 => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm).
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The date of `days` since 1970-01-01 (inverse of [`days_from_civil`]).
fn civil_from_days(days: i64) -> (i64, i64, i64) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// Where the observer stands.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Site {
    /// Latitude (degrees north).
    pub lat_deg: f64,
    /// Longitude (degrees east).
    pub lon_deg: f64,
    /// Height above mean sea level (m), for the parallax.
    pub height_m: f64,
}

impl Site {
    /// Check the latitude (−90…90°) and longitude (−180…180°).
    pub fn validate(&self) -> Result<(), SolarError> {
        let ok =
            self.lat_deg.abs() <= 90.0 && self.lon_deg.abs() <= 180.0 && self.height_m.is_finite();
        if ok {
            Ok(())
        } else {
            Err(SolarError::Site {
                lat_deg: self.lat_deg,
                lon_deg: self.lon_deg,
            })
        }
    }
}

/// The sun's true topocentric position (no atmospheric refraction).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SunPosition {
    /// Elevation of the centre above the astronomical horizon (degrees).
    pub elevation_deg: f64,
    /// Azimuth, clockwise from north (degrees, 0–360).
    pub azimuth_deg: f64,
}

/// The sun's true position at `time` from `site`, with ΔT estimated for the date.
pub fn sun_position(time: UtcTime, site: &Site) -> Result<SunPosition, SolarError> {
    let algorithm = |e: solar_positioning::Error| SolarError::Algorithm {
        time: time.iso(),
        message: e.to_string(),
    };
    let delta_t_s = solar_positioning::delta_t::estimate(time.decimal_year()).map_err(algorithm)?;
    sun_position_with_delta_t(time, site, delta_t_s)
}

/// As [`sun_position`] with ΔT (TT − UT1, seconds) given.
pub fn sun_position_with_delta_t(
    time: UtcTime,
    site: &Site,
    delta_t_s: f64,
) -> Result<SunPosition, SolarError> {
    site.validate()?;
    let algorithm = |e: solar_positioning::Error| SolarError::Algorithm {
        time: time.iso(),
        message: e.to_string(),
    };
    let jd = JulianDate::new(time.julian_date(), delta_t_s).map_err(algorithm)?;
    let location = Location {
        latitude: site.lat_deg,
        longitude: site.lon_deg,
    };
    let p = SolarPositions::new()
        .at_from_julian(jd, location, site.height_m, None)
        .map_err(algorithm)?;
    Ok(SunPosition {
        elevation_deg: 90.0 - p.zenith_angle(),
        azimuth_deg: p.azimuth(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_parse_and_print() {
        let t = UtcTime::parse("2026-02-12T13:05Z").unwrap();
        assert_eq!(t.iso(), "2026-02-12T13:05:00Z");
        assert_eq!(
            UtcTime::parse("2026-02-12 13:05:07").unwrap().unix_s,
            t.unix_s + 7
        );
        assert_eq!(
            UtcTime::parse("2026-02-05 23 UTC").unwrap().iso(),
            "2026-02-05T23:00:00Z"
        );
        // The Unix epoch and a leap day.
        assert_eq!(UtcTime::parse("1970-01-01T00:00Z").unwrap().unix_s, 0);
        assert_eq!(
            UtcTime::parse("2024-02-29T00:00").unwrap().iso(),
            "2024-02-29T00:00:00Z"
        );
        // 2000-01-01 12:00 UTC is JD 2451545.0 (the J2000 epoch, to UTC).
        let j2000 = UtcTime::parse("2000-01-01T12:00Z").unwrap();
        assert_eq!(j2000.julian_date(), 2_451_545.0);
        for bad in [
            "2026-02-30T00:00",
            "2026-13-01T00:00",
            "2026-02-12",
            "2026-02-12T25:00",
            "2026-2-12T10:00",
            "yesterday",
            "2026-02-12T10:00:00:00",
        ] {
            assert!(UtcTime::parse(bad).is_err(), "{bad}");
        }
        // Round trip over a range of days, before and after the epoch.
        for days in [-800_000, -1, 0, 59, 60, 365, 20_000, 2_000_000] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days);
        }
    }

    #[test]
    fn a_bad_site_is_an_error() {
        let t = UtcTime::parse("2026-02-12T13:00Z").unwrap();
        let site = Site {
            lat_deg: 91.0,
            lon_deg: 0.0,
            height_m: 0.0,
        };
        assert!(matches!(
            sun_position(t, &site),
            Err(SolarError::Site { .. })
        ));
    }
}
