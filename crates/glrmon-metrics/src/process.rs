//! The standard process metrics of the Prometheus client libraries (`process_*`, no
//! labels), read from /proc on Linux; on other systems none is written.

use std::fmt::Write as _;

/// Appends the process families to `o`. A value that cannot be read is left out (its
/// family with it), never written as a zero.
pub(crate) fn render(o: &mut String) {
    #[cfg(target_os = "linux")]
    linux::render(o);
    #[cfg(not(target_os = "linux"))]
    let _ = o;
}

/// One family of one sample without labels.
fn family(o: &mut String, name: &str, kind: &str, help: &str, value: impl std::fmt::Display) {
    let _ = writeln!(
        o,
        "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {value}"
    );
}

#[cfg(target_os = "linux")]
mod linux {
    use super::family;

    /// Fields of /proc/self/stat after the command name (which may hold spaces and
    /// parentheses: the text after the last `)`), numbered from 3 (`state`) as in
    /// proc(5).
    pub(super) struct Stat {
        /// utime + stime, in clock ticks.
        pub(super) cpu_ticks: u64,
        /// Start time after boot, in clock ticks.
        pub(super) start_ticks: u64,
        /// Virtual memory size, bytes.
        pub(super) vsize: u64,
        /// Resident set size, pages.
        pub(super) rss_pages: u64,
    }

    pub(super) fn parse_stat(text: &str) -> Option<Stat> {
        let rest = &text[text.rfind(')')? + 1..];
        let f: Vec<&str> = rest.split_whitespace().collect();
        // f[0] is field 3 (state): field n is f[n - 3].
        let num = |n: usize| f.get(n - 3)?.parse::<u64>().ok();
        Some(Stat {
            cpu_ticks: num(14)?.checked_add(num(15)?)?,
            start_ticks: num(22)?,
            vsize: num(23)?,
            rss_pages: num(24)?,
        })
    }

    /// `btime` of /proc/stat: the boot time, seconds since the epoch.
    pub(super) fn parse_btime(text: &str) -> Option<u64> {
        text.lines()
            .find_map(|l| l.strip_prefix("btime "))?
            .trim()
            .parse()
            .ok()
    }

    /// The soft limit of "Max open files" in /proc/self/limits (`None` if unlimited).
    pub(super) fn parse_max_fds(text: &str) -> Option<u64> {
        let line = text.lines().find(|l| l.starts_with("Max open files"))?;
        line["Max open files".len()..]
            .split_whitespace()
            .next()?
            .parse()
            .ok()
    }

    fn sysconf(name: libc::c_int) -> Option<u64> {
        // SAFETY: sysconf reads a system constant; it has no preconditions.
        let v = unsafe { libc::sysconf(name) };
        u64::try_from(v).ok().filter(|v| *v > 0)
    }

    pub(super) fn render(o: &mut String) {
        let stat = std::fs::read_to_string("/proc/self/stat")
            .ok()
            .and_then(|t| parse_stat(&t));
        let ticks = sysconf(libc::_SC_CLK_TCK);
        let page = sysconf(libc::_SC_PAGESIZE);
        if let (Some(s), Some(hz)) = (&stat, ticks) {
            family(
                o,
                "process_cpu_seconds_total",
                "counter",
                "Total user and system CPU time spent in seconds.",
                s.cpu_ticks as f64 / hz as f64,
            );
        }
        if let Some(fds) = std::fs::read_dir("/proc/self/fd").ok().map(Iterator::count) {
            family(
                o,
                "process_open_fds",
                "gauge",
                "Number of open file descriptors.",
                fds,
            );
        }
        if let Some(max) = std::fs::read_to_string("/proc/self/limits")
            .ok()
            .and_then(|t| parse_max_fds(&t))
        {
            family(
                o,
                "process_max_fds",
                "gauge",
                "Maximum number of open file descriptors.",
                max,
            );
        }
        if let Some(s) = &stat {
            family(
                o,
                "process_virtual_memory_bytes",
                "gauge",
                "Virtual memory size in bytes.",
                s.vsize,
            );
        }
        if let (Some(s), Some(page)) = (&stat, page) {
            family(
                o,
                "process_resident_memory_bytes",
                "gauge",
                "Resident memory size in bytes.",
                s.rss_pages.saturating_mul(page),
            );
        }
        let boot = std::fs::read_to_string("/proc/stat")
            .ok()
            .and_then(|t| parse_btime(&t));
        if let (Some(s), Some(hz), Some(boot)) = (&stat, ticks, boot) {
            family(
                o,
                "process_start_time_seconds",
                "gauge",
                "Start time of the process since unix epoch in seconds.",
                boot as f64 + s.start_ticks as f64 / hz as f64,
            );
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn proc_files_are_parsed_and_odd_names_do_not_shift_fields() {
            let text = "4242 (glr mon) x) S 1 4242 4242 0 -1 4194560 1000 0 0 0 250 50 0 0 20 0 9 0 123456 987654321 2048 18446744073709551615 1 1 0 0 0 0 0 4096 17475 0 0 0 17 1 0 0 0 0 0";
            let s = parse_stat(text).unwrap();
            assert_eq!(
                (s.cpu_ticks, s.start_ticks, s.vsize, s.rss_pages),
                (300, 123_456, 987_654_321, 2048)
            );
            assert!(parse_stat("4242 (cut").is_none());
            assert!(parse_stat("4242 (x) S 1 2").is_none());
            assert_eq!(
                parse_btime("cpu  1 2 3\nbtime 1700000000\nprocesses 9\n"),
                Some(1_700_000_000)
            );
            let limits = "Limit                     Soft Limit           Hard Limit           Units     \nMax cpu time              unlimited            unlimited            seconds   \nMax open files            1024                 524288               files     \n";
            assert_eq!(parse_max_fds(limits), Some(1024));
            assert_eq!(
                parse_max_fds(
                    "Max open files            unlimited            unlimited            files\n"
                ),
                None
            );
        }

        #[test]
        fn this_process_has_every_family() {
            let mut o = String::new();
            super::render(&mut o);
            for name in [
                "process_cpu_seconds_total",
                "process_open_fds",
                "process_max_fds",
                "process_virtual_memory_bytes",
                "process_resident_memory_bytes",
                "process_start_time_seconds",
            ] {
                assert!(o.contains(&format!("\n{name} ")), "{name} not in\n{o}");
            }
        }
    }
}
