//! `glrmon status [INSTANCES]`: asks every live instance (the status queryables,
//! QueryTarget All) and prints one line each: its shard and channels, its recent
//! throughput, active alarms, rejected and dropped input, its Zenoh sessions by kind,
//! reconnections and uptime.
//!
//! Any peer can answer, so the instance names, shards and status JSON shown are escaped
//! ([`glrmon_wire::text`]).

use std::time::Duration;

use clap::Args;
use glrmon_wire::status;
use glrmon_wire::text::{escape_control, escape_json};

use crate::common::InvalidInput;
use crate::flags::ZenohArgs;

#[derive(Debug, Args)]
pub(crate) struct StatusArgs {
    /// Instances to ask: a key expression over instance names (`*` for all).
    #[arg(default_value = "*")]
    instances: String,
    /// Print each instance's status JSON on a line of its own instead of the table.
    #[arg(long)]
    json: bool,
    /// Print one line per channel instead: the instance monitoring it (its owner), that
    /// instance's assignment generation, and the channel's counters; a channel two
    /// instances monitor is flagged.
    #[arg(long, conflicts_with = "json")]
    channels: bool,
    /// Seconds to wait for the instances' answers.
    #[arg(long, default_value_t = 3.0)]
    timeout: f64,
    #[command(flatten)]
    zenoh: ZenohArgs,
}

pub(crate) fn run(args: &StatusArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(status(args))
}

async fn status(args: &StatusArgs) -> anyhow::Result<()> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(InvalidInput(format!("--timeout {} must be positive", args.timeout)).into());
    }
    let session = glrmon_zenoh::open(&args.zenoh.client_settings()).await?;
    let replies = glrmon_zenoh::query_status(
        &session,
        &args.instances,
        Duration::from_secs_f64(args.timeout),
    )
    .await?;
    let _ = session.close().await;
    if replies.is_empty() {
        return Err(InvalidInput(format!(
            "no glrmon instance matching \"{}\" answered within {} s",
            args.instances, args.timeout
        ))
        .into());
    }
    if args.json {
        for (_, json) in &replies {
            println!("{}", escape_json(json));
        }
        return Ok(());
    }
    if args.channels {
        print!("{}", channel_table(&replies));
    } else {
        print!("{}", table(&replies));
    }
    Ok(())
}

/// One instance's line for a channel: (owner, generation, samples, alarms, active).
type OwnerRow = (String, String, u64, u64, bool);

/// One line per channel: its owner (the instance whose status lists it), that
/// instance's generation, samples, alarms and whether one is active; channels listed by
/// two instances are flagged, and a last line says whether the automatic shards' views
/// of the live instances agree.
fn channel_table(replies: &[(String, String)]) -> String {
    let mut owners: std::collections::BTreeMap<String, Vec<OwnerRow>> =
        std::collections::BTreeMap::new();
    let mut views: std::collections::BTreeSet<Vec<String>> = std::collections::BTreeSet::new();
    for (name, json) in replies {
        let Ok(v) = status::decode(json.as_bytes()) else {
            continue;
        };
        let generation = v
            .assignment
            .as_ref()
            .map_or_else(|| "-".to_owned(), |a| a.generation.to_string());
        if let Some(a) = &v.assignment {
            views.insert(a.instances.clone());
        }
        for c in &v.channels {
            owners
                .entry(escape_control(&c.channel).into_owned())
                .or_default()
                .push((
                    escape_control(name).into_owned(),
                    generation.clone(),
                    c.samples,
                    c.alarms,
                    c.alarm_active,
                ));
        }
    }
    let mut rows =
        vec![["CHANNEL", "OWNER", "GEN", "SAMPLES", "ALARMS", "ACTIVE", ""].map(str::to_owned)];
    for (channel, list) in &owners {
        for (owner, generation, samples, alarms, active) in list {
            rows.push([
                channel.clone(),
                owner.clone(),
                generation.clone(),
                samples.to_string(),
                alarms.to_string(),
                if *active { "yes" } else { "no" }.to_owned(),
                if list.len() > 1 {
                    format!("monitored by {} instances", list.len())
                } else {
                    String::new()
                },
            ]);
        }
    }
    let mut out = aligned(&rows, |i| i < 2 || i == 6);
    let doubled = owners.values().filter(|l| l.len() > 1).count();
    out.push_str(&format!(
        "{} channel(s) monitored, {doubled} by more than one instance",
        owners.len()
    ));
    match views.len() {
        0 => out.push('\n'),
        1 => out.push_str("; the automatic shard's instances agree on the live set\n"),
        n => out.push_str(&format!(
            "; the automatic shard's instances see {n} different live sets (a view is changing, or the network is split)\n"
        )),
    }
    out
}

/// The status table: a header and one line per instance, then a total line.
fn table(replies: &[(String, String)]) -> String {
    let mut rows = vec![
        [
            "INSTANCE",
            "SHARD",
            "CHANNELS",
            "SAMPLES/S",
            "ACTIVE",
            "ALARMS",
            "ERRORS",
            "DROPPED",
            "SESSIONS",
            "RECONNECT",
            "UPTIME",
        ]
        .map(str::to_owned),
    ];
    let (mut channels, mut rate) = (0u64, 0.0);
    for (name, json) in replies {
        let name = escape_control(name).into_owned();
        let Ok(v) = status::decode(json.as_bytes()) else {
            rows.push([
                name,
                "(unreadable status)".into(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ]);
            continue;
        };
        let ch = &v.channels;
        let sum = |f: &dyn Fn(&glrmon_wire::ChannelStatus) -> u64| ch.iter().map(f).sum::<u64>();
        let active = sum(&|c| u64::from(c.alarm_active));
        let alarms = sum(&|c| c.alarms);
        let errors = sum(&glrmon_wire::ChannelStatus::error_total);
        let dropped = sum(&|c| c.dropped);
        let sps = v.samples_per_second;
        channels += ch.len() as u64;
        rate += sps;
        let shard = v
            .shard
            .as_deref()
            .map_or_else(|| "-".to_owned(), |s| escape_control(s).into_owned());
        rows.push([
            name,
            match &v.assignment {
                Some(a) => format!("{shard} g{}", a.generation),
                None => shard,
            },
            ch.len().to_string(),
            format!("{sps:.0}"),
            active.to_string(),
            alarms.to_string(),
            errors.to_string(),
            dropped.to_string(),
            sessions(v.sessions),
            format!(
                "{}{}",
                v.reconnections,
                if v.connected { "" } else { " (down)" }
            ),
            uptime(v.uptime),
        ]);
    }
    let mut out = aligned(&rows, |i| i < 2);
    out.push_str(&format!(
        "{} instance(s), {channels} channel(s), {rate:.0} samples/s\n",
        replies.len()
    ));
    out
}

/// The rows as a table: each column as wide as its widest cell, two spaces apart,
/// left-aligned where `left(column)`, else right-aligned; one line per row.
fn aligned<const N: usize>(rows: &[[String; N]], left: impl Fn(usize) -> bool) -> String {
    let mut widths = [0usize; N];
    for r in rows {
        for (w, c) in widths.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let mut out = String::new();
    for r in rows {
        let cells: Vec<String> = r
            .iter()
            .zip(widths)
            .enumerate()
            .map(|(i, (c, w))| {
                if left(i) {
                    format!("{c:<w$}")
                } else {
                    format!("{c:>w$}")
                }
            })
            .collect();
        out.push_str(cells.join("  ").trim_end());
        out.push('\n');
    }
    out
}

/// "1 router, 2 clients", "none", or "?" when the instance did not say (an earlier
/// release).
fn sessions(s: Option<glrmon_wire::ZenohSessions>) -> String {
    let Some(s) = s else {
        return "?".to_owned();
    };
    let parts: Vec<String> = [
        (s.routers, "router"),
        (s.peers, "peer"),
        (s.clients, "client"),
    ]
    .iter()
    .filter(|(n, _)| *n > 0)
    .map(|(n, kind)| format!("{n} {kind}{}", if *n == 1 { "" } else { "s" }))
    .collect();
    if parts.is_empty() {
        "none".to_owned()
    } else {
        parts.join(", ")
    }
}

fn uptime(s: f64) -> String {
    let s = s.max(0.0) as u64;
    match s {
        0..60 => format!("{s}s"),
        60..3600 => format!("{}m{:02}s", s / 60, s % 60),
        3600..86400 => format!("{}h{:02}m", s / 3600, s % 3600 / 60),
        _ => format!("{}d{:02}h", s / 86400, s % 86400 / 3600),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An automatic shard's statuses: each channel's owner and generation; a channel
    /// two instances list is flagged, and so are views of the live set that differ.
    #[test]
    fn channel_table_names_owners_and_flags_doubles_and_split_views() {
        let status = |name: &str, generation: u64, live: &str, channels: &[&str]| {
            let list: Vec<String> = channels
                .iter()
                .map(|c| format!(r#"{{"channel":"{c}","samples":7,"alarms":1,"alarm_active":false,"dropped":0,"last_k":6,"errors":{{}}}}"#))
                .collect();
            format!(
                r#"{{"instance":"{name}","uptime":1,"shard":"auto","connected":true,"reconnections":0,"overlaps":0,"samples_per_second":0.0,"channels":[{}],"assignment":{{"generation":{generation},"instances":[{live}],"takeovers":0,"handovers":0}}}}"#,
                list.join(",")
            )
        };
        let both = r#""a","b""#;
        let t = channel_table(&[
            ("a".into(), status("a", 3, both, &["c1", "c2"])),
            ("b".into(), status("b", 2, both, &["c3"])),
        ]);
        let lines: Vec<Vec<&str>> = t.lines().map(|l| l.split_whitespace().collect()).collect();
        assert_eq!(
            lines[0],
            ["CHANNEL", "OWNER", "GEN", "SAMPLES", "ALARMS", "ACTIVE"]
        );
        assert_eq!(lines[1], ["c1", "a", "3", "7", "1", "no"], "{t}");
        assert_eq!(lines[3], ["c3", "b", "2", "7", "1", "no"], "{t}");
        assert!(t.ends_with("3 channel(s) monitored, 0 by more than one instance; the automatic shard's instances agree on the live set\n"), "{t}");
        let t = channel_table(&[
            ("a".into(), status("a", 3, both, &["c1"])),
            ("b".into(), status("b", 1, r#""b""#, &["c1"])),
        ]);
        assert!(t.contains("monitored by 2 instances"), "{t}");
        assert!(t.contains("1 by more than one instance; the automatic shard's instances see 2 different live sets"), "{t}");
    }

    #[test]
    fn table_sums_channels_and_marks_lost_connections() {
        let a = r#"{"instance":"a","uptime":3725.2,"shard":"0/2","connected":true,"reconnections":1,"overlaps":0,"samples_per_second":1500.0,"channels":[{"channel":"c1","samples":10,"alarms":2,"alarm_active":true,"dropped":3,"last_k":9,"errors":{"non_finite":4}}],"sessions":{"routers":0,"peers":0,"clients":1}}"#;
        let b = r#"{"instance":"b","uptime":5,"shard":null,"connected":false,"reconnections":0,"overlaps":0,"samples_per_second":0.0,"channels":[]}"#;
        let t = table(&[
            ("a".into(), a.into()),
            ("b".into(), b.into()),
            ("c".into(), r#"{"instance":"c"}"#.into()),
        ]);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 5, "{t}");
        assert!(lines[0].starts_with("INSTANCE"), "{t}");
        let a: Vec<&str> = lines[1].split_whitespace().collect();
        assert_eq!(
            a,
            [
                "a", "0/2", "1", "1500", "1", "2", "4", "3", "1", "client", "1", "1h02m"
            ],
            "{t}"
        );
        let b: Vec<&str> = lines[2].split_whitespace().collect();
        assert_eq!(
            b,
            [
                "b", "-", "0", "0", "0", "0", "0", "0", "?", "0", "(down)", "5s"
            ],
            "sessions unknown (an earlier release's status), no connection: {t}"
        );
        assert_eq!(
            lines[3].split_whitespace().collect::<Vec<_>>(),
            ["c", "(unreadable", "status)"],
            "a status missing fields is not shown as zeros: {t}"
        );
        assert_eq!(lines[4], "3 instance(s), 1 channel(s), 1500 samples/s");
    }

    /// Any peer can answer a status query: its name and shard reach the table escaped,
    /// so the table stays one line per instance and sends nothing to the terminal.
    #[test]
    fn hostile_instance_names_and_shards_are_escaped() {
        let json = r#"{"instance":"x","uptime":1,"shard":"\u001b[2J","connected":true,"reconnections":0,"overlaps":0,"samples_per_second":0.0,"channels":[]}"#;
        let t = table(&[("\u{1b}]0;pwned\u{7}\nALARM\u{202e}".into(), json.into())]);
        assert!(
            !t.chars()
                .any(|c| c != '\n' && glrmon_wire::text::needs_escape(c)),
            "{t:?}"
        );
        assert_eq!(t.lines().count(), 3, "{t}");
        assert!(
            t.lines()
                .nth(1)
                .unwrap()
                .starts_with(r"\x1b]0;pwned\x07\nALARM\u{202e}  \x1b[2J "),
            "{t}"
        );
    }

    #[test]
    fn sessions_are_named_by_kind() {
        use glrmon_wire::ZenohSessions;
        let s = |routers, peers, clients| {
            sessions(Some(ZenohSessions {
                routers,
                peers,
                clients,
            }))
        };
        assert_eq!(s(0, 0, 0), "none");
        assert_eq!(s(1, 0, 2), "1 router, 2 clients");
        assert_eq!(s(0, 3, 1), "3 peers, 1 client");
        assert_eq!(sessions(None), "?");
    }
}
