//! Sample times as people read them.
//!
//! A sample's `t` is whatever its publisher put there: seconds since the start of a
//! simulation (0.01, 0.02, …) or Unix wall-clock seconds (1.796e9 on a live plant).
//! Times at or after [`WALL_CLOCK_FROM`] are taken as wall-clock and shown as
//! ISO-8601 (`2026-12-02T16:22:05.250Z`, or with the system time zone's offset for
//! [`Zone::Local`], daylight-saving rules included); earlier ones stay seconds
//! (`12.340 s`). Records keep the number; only the display changes.

use jiff::Timestamp;
use jiff::tz::TimeZone;

/// Sample times from this many Unix seconds on (2001-09-09T01:46:40Z) are wall-clock
/// times; a simulation would have to run for 31 years to get there.
pub const WALL_CLOCK_FROM: f64 = 1e9;

/// The time zone wall-clock times are shown in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Zone {
    /// UTC, written with a `Z` (the default: logs of several hosts line up).
    #[default]
    Utc,
    /// The system's time zone (`TZ`, else /etc/localtime), written with its offset.
    Local,
}

/// Whether `t` reads as Unix wall-clock seconds ([`WALL_CLOCK_FROM`]).
#[must_use]
pub fn is_wall_clock(t: f64) -> bool {
    t.is_finite() && t >= WALL_CLOCK_FROM
}

/// `t` as ISO-8601 with milliseconds when it is a wall-clock time, else as seconds
/// (`12.340 s`).
///
/// ```
/// use glrmon_report::clock::{Zone, format_time};
///
/// assert_eq!(format_time(1_796_191_746.296, Zone::Utc), "2026-12-02T06:09:06.296Z");
/// assert_eq!(format_time(2.01, Zone::Utc), "2.010 s");
/// ```
#[must_use]
pub fn format_time(t: f64, zone: Zone) -> String {
    match timestamp(t) {
        Some(ts) => match zone {
            Zone::Utc => ts.strftime("%Y-%m-%dT%H:%M:%S%.3fZ").to_string(),
            Zone::Local => ts
                .to_zoned(TimeZone::system())
                .strftime("%Y-%m-%dT%H:%M:%S%.3f%:z")
                .to_string(),
        },
        None => format!("{t:.3} s"),
    }
}

/// The time of day of a wall-clock `t` (`16:22:05`, with `.250` when `t` has a
/// fraction of a second that shows at `decimals`), for axis ticks; `None` for other
/// times.
#[must_use]
pub fn time_of_day(t: f64, zone: Zone, decimals: usize) -> Option<String> {
    let ts = timestamp(t)?;
    let fmt = match decimals {
        0 => "%H:%M:%S",
        1 => "%H:%M:%S%.1f",
        2 => "%H:%M:%S%.2f",
        _ => "%H:%M:%S%.3f",
    };
    Some(match zone {
        Zone::Utc => ts.strftime(fmt).to_string(),
        Zone::Local => ts.to_zoned(TimeZone::system()).strftime(fmt).to_string(),
    })
}

/// The calendar date and zone of a wall-clock `t` (`2026-12-02 UTC`,
/// `2026-12-02 +01:00`), for an axis title.
#[must_use]
pub fn date(t: f64, zone: Zone) -> Option<String> {
    let ts = timestamp(t)?;
    Some(match zone {
        Zone::Utc => ts.strftime("%Y-%m-%d UTC").to_string(),
        Zone::Local => ts
            .to_zoned(TimeZone::system())
            .strftime("%Y-%m-%d %:z")
            .to_string(),
    })
}

/// A wall-clock `t` as a timestamp, rounded to the millisecond shown.
fn timestamp(t: f64) -> Option<Timestamp> {
    if !is_wall_clock(t) {
        return None;
    }
    let ms = (t * 1e3).round();
    // Beyond jiff's range (year 9999) the number is shown as seconds.
    if ms >= 253_402_300_800_000.0 {
        return None;
    }
    Timestamp::from_millisecond(ms as i64).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wall_clock_times_are_iso_8601_utc_to_the_millisecond() {
        assert_eq!(
            format_time(1_796_191_746.296_4, Zone::Utc),
            "2026-12-02T06:09:06.296Z"
        );
        assert_eq!(format_time(1e9, Zone::Utc), "2001-09-09T01:46:40.000Z");
        // Rounding carries into the second.
        assert_eq!(
            format_time(1_796_191_746.999_6, Zone::Utc),
            "2026-12-02T06:09:07.000Z"
        );
    }

    #[test]
    fn simulation_times_and_odd_values_stay_seconds() {
        assert_eq!(format_time(0.0, Zone::Utc), "0.000 s");
        assert_eq!(format_time(999_999_999.5, Zone::Local), "999999999.500 s");
        assert_eq!(format_time(-3.0, Zone::Utc), "-3.000 s");
        assert_eq!(format_time(f64::NAN, Zone::Utc), "NaN s");
        assert_eq!(format_time(1e300, Zone::Utc), format!("{:.3} s", 1e300));
        assert_eq!(time_of_day(12.0, Zone::Utc, 0), None);
    }

    #[test]
    fn local_time_carries_the_offset_of_its_zone() {
        let s = format_time(1_796_191_746.296, Zone::Local);
        // 2026-12-02T…+HH:MM in whatever zone the machine has.
        assert_eq!(s.len(), "2026-12-02T06:09:06.296+00:00".len(), "{s}");
        assert!(s.ends_with(|c: char| c.is_ascii_digit()), "{s}");
        let off = &s[s.len() - 6..];
        assert!(off.starts_with('+') || off.starts_with('-'), "{s}");
    }

    #[test]
    fn axis_labels() {
        let t = 1_796_191_746.25;
        assert_eq!(time_of_day(t, Zone::Utc, 0).unwrap(), "06:09:06");
        assert_eq!(time_of_day(t, Zone::Utc, 2).unwrap(), "06:09:06.25");
        assert_eq!(date(t, Zone::Utc).unwrap(), "2026-12-02 UTC");
    }
}
