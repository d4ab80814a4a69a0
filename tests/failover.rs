//! A fleet that survives a lost instance (`--shard auto`). Three `glrmon run`
//! instances in client mode behind a Zenoh router on loopback (`zenohd` when installed,
//! else a router-mode session of this process; explicit tcp/127.0.0.1 endpoints,
//! multicast scouting off), 12 DC-motor channels published at 100 samples/s each.
//!
//! Asserts, in one run:
//! - the three split the channels by the rendezvous rule, each channel owned once;
//! - `kill -9` of one: each of its channels is claimed by another instance within
//!   [`TAKEOVER_BOUND`] (a crash closes its connection: the router withdraws its tokens
//!   at once), and monitored again (its `stat` records from the new owner);
//! - a fault injected on every channel after the kill is alarmed exactly once per
//!   channel, by the channel's owner, whose records name it (the Zenoh attachment);
//! - the killed instance, restarted, takes back exactly its former channels and no
//!   other; a fault going on when it takes them is alarmed by it after its settling;
//! - killed again with the fault going on, its channels are alarmed again by their new
//!   owners (a fault in progress at takeover);
//! - SIGTERM of another: every channel it monitored is claimed elsewhere before it
//!   withdraws its own claim (no channel is left unmonitored) and it exits 0;
//! - further kills and restarts: the takeover times stay within the bound (printed);
//! - the new owner of a channel published with a cache (half of them) gets its recent
//!   samples from it, settles on them and publishes l_k from the first live sample on,
//!   none missed; without a cache it settles on the live samples, l_k withheld for
//!   the settling (101 samples), at most 2 samples missed (printed);
//! - `glrmon watch --since 1h`, started last, prints the alarms the live instances kept,
//!   each naming its instance and generation, and flags an alarm record published by
//!   the test's own session (no source).

#[path = "support.rs"]
mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufRead as _;
use std::path::Path;
use std::process::{Child, Command};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_wire::{Record, Sample, Source, encode_sample};
use zenoh::Wait as _;

const CHANNELS: usize = 12;
/// ch00 … ch05 are published with a cache of 1 000 samples (zenoh-ext advanced
/// publishers), ch06 … ch11 without: the new owner of the first starts warm from the
/// cache, of the others from the live samples.
const CACHED: usize = 6;
/// Samples per second on each channel.
const RATE: u64 = 100;
/// The fault's onset (k), well after the first kill and the takeover's settling.
const ONSET: u64 = 600;
/// A crash's takeover bound asserted here: the router sees the connection close at
/// once; the rest is the token's way to the others and their assignment.
const TAKEOVER_BOUND: Duration = Duration::from_secs(2);

/// One instance of the fleet.
struct Instance {
    name: String,
    child: Child,
    log: Arc<Mutex<String>>,
}

impl Instance {
    /// Starts `glrmon run --shard auto` as a client of `endpoint` and waits for its
    /// "monitoring" line.
    fn start(cfg: &Path, name: &str, endpoint: &str) -> Self {
        Self::start_with(cfg, name, &["--mode", "client", "--connect", endpoint])
    }

    /// Starts `glrmon run --shard auto` with these Zenoh flags.
    fn start_with(cfg: &Path, name: &str, zenoh: &[&str]) -> Self {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_glrmon"));
        cmd.args(["run", "--config"])
            .arg(cfg)
            .args(["--shard", "auto", "--instance", name])
            .args(zenoh);
        let (mut child, log) = support::spawn_logged(&mut cmd);
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let instance = Self {
            name: name.to_owned(),
            child,
            log,
        };
        assert!(
            line.contains(&format!("instance {name} monitoring"))
                && line.contains("(shard auto of 12"),
            "{line}{}",
            instance.log()
        );
        instance
    }

    fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What the test sees on the network, with the time it saw it.
#[derive(Default)]
struct Seen {
    /// Owner tokens now: channel → instances.
    owners: BTreeMap<String, BTreeSet<String>>,
    /// (time, channel, instance, put) of every owner token event.
    claims: Vec<(Instant, String, String, bool)>,
    /// (channel, instance, k, whether it carries l_k) of every stat record, in arrival
    /// order.
    stats: Vec<(String, String, u64, bool)>,
    /// (time, channel, instance, k) of every alarm.
    alarms: Vec<(Instant, String, String, u64)>,
    /// The last alarm record as published.
    last_alarm: Vec<u8>,
}

impl Seen {
    /// The owner of each channel when each has exactly one.
    fn single_owners(&self) -> Option<BTreeMap<String, String>> {
        if self.owners.len() < CHANNELS {
            return None;
        }
        self.owners
            .iter()
            .map(|(c, o)| (o.len() == 1).then(|| (c.clone(), o.first().unwrap().clone())))
            .collect()
    }

    /// The last k of `channel` from `instance`'s stat records (before `before` of them).
    fn last_k(&self, channel: &str, instance: &str, before: usize) -> Option<u64> {
        self.stats[..before]
            .iter()
            .filter(|(c, i, _, _)| c == channel && i == instance)
            .map(|s| s.2)
            .max()
    }

    /// The first k of `channel` from `instance`'s stat records after the first `from`
    /// (that carries l_k, when `armed`).
    fn first_k(&self, channel: &str, instance: &str, from: usize, armed: bool) -> Option<u64> {
        self.stats[from..]
            .iter()
            .find(|(c, i, _, a)| c == channel && i == instance && (*a || !armed))
            .map(|s| s.2)
    }
}

/// Polls `seen` until `done` gives a value (`limit` at most).
async fn wait_for<T>(
    seen: &Mutex<Seen>,
    what: &str,
    limit: Duration,
    done: impl Fn(&Seen) -> Option<T>,
) -> T {
    let t = Instant::now();
    loop {
        if let Some(v) = done(&seen.lock().unwrap()) {
            return v;
        }
        assert!(
            t.elapsed() < limit,
            "{what}: not within {limit:?}; owners {:?}",
            seen.lock().unwrap().owners
        );
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

/// Waits until the publisher reaches sample `k`.
async fn until_k(published: &AtomicU64, k: u64) {
    while published.load(Ordering::Relaxed) < k {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// One channel's takeover after a kill.
#[derive(Debug, Clone)]
struct Takeover {
    channel: String,
    owner: String,
    /// From the kill to the new owner's claim.
    time: Duration,
    /// Samples no instance processed: between the victim's last and the new owner's
    /// first (0 when the new owner's first came from the publisher's cache).
    missed: u64,
    /// Live samples after the victim's last before the new owner's l_k is published
    /// again (it settles on the cache's samples when there are any).
    blind: u64,
}

/// Kills `victim` with SIGKILL and waits until each of its channels is claimed by
/// another instance and its statistic is published again.
async fn kill_and_measure(victim: &mut Instance, seen: &Mutex<Seen>) -> Vec<Takeover> {
    let (mine, stats_before) = {
        let s = seen.lock().unwrap();
        let mine: Vec<String> = s
            .owners
            .iter()
            .filter(|(_, o)| o.contains(&victim.name))
            .map(|(c, _)| c.clone())
            .collect();
        (mine, s.stats.len())
    };
    assert!(!mine.is_empty(), "{} owns no channel", victim.name);
    let killed = Instant::now();
    victim.child.kill().unwrap();
    let _ = victim.child.wait();
    let name = victim.name.clone();
    let new_owners = wait_for(seen, "takeover", Duration::from_secs(10), |s| {
        mine.iter()
            .map(|c| {
                s.claims
                    .iter()
                    .find(|(t, ch, i, put)| *put && *t >= killed && ch == c && *i != name)
                    .map(|(t, _, i, _)| (c.clone(), (*t, i.clone())))
            })
            .collect::<Option<BTreeMap<_, _>>>()
    })
    .await;
    // The new owner's first stat of each channel, and its first with l_k.
    let firsts = wait_for(
        seen,
        "stats of the new owners",
        Duration::from_secs(10),
        |s| {
            new_owners
                .iter()
                .map(|(c, (_, i))| {
                    Some((
                        s.first_k(c, i, stats_before, false)?,
                        s.first_k(c, i, stats_before, true)?,
                    ))
                })
                .collect::<Option<Vec<(u64, u64)>>>()
        },
    )
    .await;
    let s = seen.lock().unwrap();
    new_owners
        .into_iter()
        .zip(firsts)
        .map(|((channel, (t, owner)), (first, armed))| {
            let last = s.last_k(&channel, &name, s.stats.len()).unwrap_or(0);
            Takeover {
                time: t.duration_since(killed),
                missed: first.saturating_sub(last + 1),
                blind: armed.saturating_sub(last + 1),
                channel,
                owner,
            }
        })
        .collect()
}

/// Each channel's owner among `live` by the rendezvous rule.
fn assignment(cfg: &glrmon_spec::Config, live: &[String]) -> BTreeMap<String, String> {
    cfg.channels
        .iter()
        .map(|ch| {
            (
                ch.name.clone(),
                glrmon_spec::rendezvous_owner(&ch.name, live)
                    .unwrap()
                    .to_owned(),
            )
        })
        .collect()
}

/// The first names `fleet<n>-a`, `-b`, `-c` (n = 0, 1, …) that the rule gives at least
/// `least` channels each, `-b` some with a cache and some without.
fn names_with_shares(cfg: &glrmon_spec::Config, least: usize) -> Vec<String> {
    (0..)
        .map(|n| ["a", "b", "c"].map(|x| format!("fleet{n}-{x}")).to_vec())
        .find(|names| {
            let owners: Vec<String> = assignment(cfg, names).into_values().collect();
            let b = |range: std::ops::Range<usize>| owners[range].iter().any(|o| *o == names[1]);
            names
                .iter()
                .all(|n| owners.iter().filter(|o| *o == n).count() >= least)
                && b(0..CACHED)
                && b(CACHED..CHANNELS)
        })
        .unwrap()
}

/// Follows the owners' tokens into `seen` (owners now, and every event with its time).
async fn follow_claims(
    session: &zenoh::Session,
    seen: &Arc<Mutex<Seen>>,
) -> zenoh::pubsub::Subscriber<()> {
    let s = Arc::clone(seen);
    session
        .liveliness()
        .declare_subscriber("glrmon/@owners/**")
        .history(true)
        .callback(move |sample| {
            let key = sample.key_expr().as_str();
            let Some((channel, instance)) = key
                .strip_prefix("glrmon/@owners/")
                .and_then(|r| r.rsplit_once('/'))
            else {
                return;
            };
            let put = sample.kind() == zenoh::sample::SampleKind::Put;
            let mut s = s.lock().unwrap();
            let owners = s.owners.entry(channel.to_owned()).or_default();
            if put {
                owners.insert(instance.to_owned());
            } else {
                owners.remove(instance);
            }
            s.claims
                .push((Instant::now(), channel.to_owned(), instance.to_owned(), put));
        })
        .await
        .unwrap()
}

/// The fleet's configuration: 12 copies of the DC motor, ch00 … ch11, every stat
/// record published; (its text, the file written in `dir`).
fn fleet_config(dir: &Path) -> (String, std::path::PathBuf) {
    let motor_path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let motor = std::fs::read_to_string(&motor_path).unwrap();
    let mut text = "[daemon]\nstat_every = 1\nworkers = 1\n\n".to_owned();
    for i in 0..CHANNELS {
        text.push_str(&motor.replace("name = \"dc_motor\"", &format!("name = \"ch{i:02}\"")));
        text.push('\n');
    }
    let path = dir.join("fleet.toml");
    std::fs::write(&path, &text).unwrap();
    (text, path)
}

/// A frozen instance (SIGSTOP: its connection stays open, its keep-alives stop) is
/// taken over once its Zenoh lease expires at the router: 2 s here
/// (`transport.link.tx.lease` in the instances' Zenoh configuration), so after at
/// least half a second (it is not the crash's closed connection) and within 3.5 s. When
/// it wakes up (SIGCONT) it reconnects and the fleet converges to the assignment of
/// both instances again, every channel with one owner.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frozen_instance_is_taken_over_when_its_lease_expires() {
    let dir = support::Scratch::new("failover-freeze");
    let port = support::free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let router = support::Router::start(&endpoint).await;
    let (text, cfg_path) = fleet_config(&dir.0);
    let cfg = glrmon_spec::parse(&text).unwrap();
    let zenoh_cfg = dir.0.join("zenoh.json5");
    std::fs::write(
        &zenoh_cfg,
        format!(
            r#"{{ mode: "client", connect: {{ endpoints: ["{endpoint}"] }},
               scouting: {{ multicast: {{ enabled: false }} }},
               transport: {{ link: {{ tx: {{ lease: 2000, keep_alive: 4 }} }} }} }}"#
        ),
    )
    .unwrap();
    let session = support::client(&endpoint).await;
    let seen = Arc::new(Mutex::new(Seen::default()));
    let _claims = follow_claims(&session, &seen).await;
    let names = names_with_shares(&cfg, 3);
    let zenoh_args = ["--zenoh-config", zenoh_cfg.to_str().unwrap()];
    let a = Instance::start_with(&cfg_path, &names[0], &zenoh_args);
    let mut b = Instance::start_with(&cfg_path, &names[1], &zenoh_args);
    let both = assignment(&cfg, &names[..2]);
    wait_for(
        &seen,
        "the assignment of both",
        Duration::from_secs(10),
        |s| s.single_owners().filter(|o| *o == both),
    )
    .await;
    let alone = assignment(&cfg, &names[..1]);
    let frozen = Instant::now();
    signal(&b.child, "-STOP");
    wait_for(
        &seen,
        "a owns every channel",
        Duration::from_secs(10),
        |s| s.single_owners().filter(|o| *o == alone),
    )
    .await;
    let took = frozen.elapsed();
    eprintln!(
        "a frozen instance's channels taken over after {:.2} s (lease 2 s)",
        took.as_secs_f64()
    );
    assert!(
        took > Duration::from_millis(500) && took < Duration::from_millis(3500),
        "{took:?}"
    );
    signal(&b.child, "-CONT");
    wait_for(
        &seen,
        "the assignment of both again",
        Duration::from_secs(15),
        |s| s.single_owners().filter(|o| *o == both),
    )
    .await;
    let _ = b.child.kill();
    drop((a, b));
    router.stop().await;
}

/// Sends `sig` (`-STOP`, `-CONT`, `-TERM`) to `child`.
fn signal(child: &Child, sig: &str) {
    let status = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fleet_takes_over_a_lost_instance_and_hands_over_on_sigterm() {
    let dir = support::Scratch::new("failover");
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let router = support::Router::start(&endpoint).await;
    eprintln!("router: {}", router.kind());

    let (text, cfg_path) = fleet_config(&dir.0);
    let cfg = glrmon_spec::parse(&text).unwrap();

    // The test's session: the owners' tokens, the stat and alarm records.
    let session = support::client(&endpoint).await;
    let seen = Arc::new(Mutex::new(Seen::default()));
    let _claims = follow_claims(&session, &seen).await;
    let s = Arc::clone(&seen);
    let _results = session
        .declare_subscriber("glrmon/*/*")
        .callback(move |sample| {
            let Some(source) = sample
                .attachment()
                .and_then(|a| Source::decode(&a.to_bytes()).ok())
            else {
                return;
            };
            let bytes = sample.payload().to_bytes();
            let Ok(record) = glrmon_wire::decode_record(&bytes) else {
                return;
            };
            let mut s = s.lock().unwrap();
            if matches!(record, Record::Alarm(_)) {
                s.last_alarm = bytes.into_owned();
            }
            match record {
                Record::Stat(st) => {
                    let armed = st.glr.is_some();
                    s.stats.push((st.channel, source.instance, st.k, armed));
                }
                Record::Alarm(a) => {
                    s.alarms
                        .push((Instant::now(), a.channel, source.instance, a.k));
                }
                _ => {}
            }
        })
        .await
        .unwrap();

    // Three names that the rule gives at least 3 channels each (the first such of a
    // fixed sequence), so that every step below moves some.
    let names = names_with_shares(&cfg, 3);
    let [na, nb, nc] = [0, 1, 2].map(|i| names[i].as_str());
    let a = Instance::start(&cfg_path, na, &endpoint);
    let mut b = Instance::start(&cfg_path, nb, &endpoint);
    let mut c = Instance::start(&cfg_path, nc, &endpoint);
    let expected = assignment(&cfg, &names);
    let initial = wait_for(
        &seen,
        "one owner per channel",
        Duration::from_secs(10),
        |s| s.single_owners().filter(|o| *o == expected),
    )
    .await;

    // The plant: every channel's samples at 100/s, an actuator bias from ONSET on.
    let data: Vec<(String, Vec<Sample>)> = cfg
        .channels
        .iter()
        .enumerate()
        .map(|(i, ch)| {
            let mut sim = glrmon_sim::faulty_simulator(
                ch,
                i as u64 + 1,
                &[("actuator_bias".to_owned(), 0.5)],
                ONSET,
            )
            .unwrap();
            let samples = support::wire_samples(&mut sim, 0, 6000);
            (ch.name.clone(), samples)
        })
        .collect();
    let published = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let publisher = {
        let (published, stop) = (Arc::clone(&published), Arc::clone(&stop));
        let mut pubs = Vec::new();
        for (i, (name, _)) in data.iter().enumerate() {
            let cache = if i < CACHED { 1000 } else { 0 };
            let p =
                support::matched_plant_publisher(&session, &format!("plant/{name}"), cache).await;
            pubs.push(p);
        }
        std::thread::spawn(move || {
            let start = Instant::now();
            let mut bytes = Vec::new();
            for k in 0..6000u64 {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                let due = start + Duration::from_micros(k * 1_000_000 / RATE);
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
                for ((name, samples), p) in data.iter().zip(&pubs) {
                    bytes.clear();
                    encode_sample(name, &samples[k as usize], &mut bytes).unwrap();
                    p.put(bytes.clone()).wait().unwrap();
                }
                published.store(k + 1, Ordering::Relaxed);
            }
        })
    };

    // 1. kill -9 of b under load, before the fault.
    until_k(&published, 200).await;
    let mut takeovers = kill_and_measure(&mut b, &seen).await;
    let moved: BTreeMap<String, String> = takeovers
        .iter()
        .map(|t| (t.channel.clone(), t.owner.clone()))
        .collect();
    for (channel, owner) in &moved {
        assert_eq!(initial[channel], nb);
        assert_eq!(
            owner,
            &assignment(&cfg, &[na.to_owned(), nc.to_owned()])[channel],
            "{channel} went to its next instance"
        );
    }
    for (channel, owner) in &initial {
        if owner != nb {
            assert!(!moved.contains_key(channel), "{channel} of {owner} moved");
        }
    }

    // 2. The fault on every channel: one alarm each, from its owner then.
    until_k(&published, ONSET + 200).await;
    let owner_now = |seen: &Seen| seen.single_owners().unwrap();
    let (alarms_fault, owners_fault) = wait_for(&seen, "12 alarms", Duration::from_secs(10), |s| {
        let fault: Vec<_> = s.alarms.iter().filter(|a| a.3 >= ONSET).cloned().collect();
        (fault.len() >= CHANNELS).then(|| (fault, owner_now(s)))
    })
    .await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let alarms_now: Vec<_> = seen
        .lock()
        .unwrap()
        .alarms
        .iter()
        .filter(|a| a.3 >= ONSET)
        .cloned()
        .collect();
    assert_eq!(
        alarms_now.len(),
        CHANNELS,
        "one alarm per channel: {alarms_now:?}"
    );
    let alarmed: BTreeSet<&String> = alarms_fault.iter().map(|a| &a.1).collect();
    assert_eq!(alarmed.len(), CHANNELS, "{alarms_fault:?}");
    for (_, channel, instance, k) in &alarms_fault {
        assert_eq!(&owners_fault[channel], instance, "{channel}");
        assert!((ONSET..ONSET + 150).contains(k), "{channel} alarmed at {k}");
    }

    // 3. b restarts: it takes back exactly its former channels, and alarms the
    //    fault going on in each after its settling.
    let alarms_before = seen.lock().unwrap().alarms.len();
    let mut b = Instance::start(&cfg_path, nb, &endpoint);
    wait_for(&seen, "b's share back", Duration::from_secs(10), |s| {
        s.single_owners().filter(|o| *o == expected)
    })
    .await;
    let b_channels: Vec<String> = expected
        .iter()
        .filter(|(_, o)| *o == nb)
        .map(|(c, _)| c.clone())
        .collect();
    let rejoined = wait_for(&seen, "b's alarms", Duration::from_secs(10), |s| {
        let new = &s.alarms[alarms_before..];
        b_channels
            .iter()
            .all(|c| new.iter().any(|a| &a.1 == c && a.2 == nb))
            .then(|| new.to_vec())
    })
    .await;
    assert!(
        rejoined.iter().all(|a| a.2 == nb),
        "only {nb}'s channels alarm again: {rejoined:?}"
    );

    // 4. kill -9 of b with the fault going on: its channels are alarmed again by
    //    their new owners, after the settling.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let alarms_before = seen.lock().unwrap().alarms.len();
    let again = kill_and_measure(&mut b, &seen).await;
    let moved: BTreeMap<String, String> = again
        .iter()
        .map(|t| (t.channel.clone(), t.owner.clone()))
        .collect();
    takeovers.extend(again);
    let in_progress = wait_for(
        &seen,
        "alarms of the faults in progress",
        Duration::from_secs(10),
        |s| {
            let new = &s.alarms[alarms_before..];
            moved
                .iter()
                .map(|(c, o)| new.iter().find(|a| &a.1 == c && &a.2 == o).cloned())
                .collect::<Option<Vec<_>>>()
        },
    )
    .await;
    assert_eq!(in_progress.len(), b_channels.len());

    // 5. SIGTERM of c: each of its channels claimed elsewhere before it withdraws
    //    its claim.
    let c_channels: Vec<String> = seen
        .lock()
        .unwrap()
        .owners
        .iter()
        .filter(|(_, o)| o.contains(nc))
        .map(|(ch, _)| ch.clone())
        .collect();
    assert!(!c_channels.is_empty());
    let sent = Instant::now();
    signal(&c.child, "-TERM");
    assert_eq!(
        support::exit_code_within(&mut c.child, Duration::from_secs(15)),
        Some(0),
        "{}",
        c.log()
    );
    let handed = wait_for(&seen, "c's channels with a", Duration::from_secs(5), |s| {
        s.single_owners()
            .filter(|o| c_channels.iter().all(|ch| o[ch] == na))
    })
    .await;
    assert_eq!(handed.len(), CHANNELS);
    {
        let s = seen.lock().unwrap();
        for ch in &c_channels {
            let claimed = s
                .claims
                .iter()
                .find(|(t, c2, i, put)| *put && *t >= sent && c2 == ch && i == na)
                .map(|x| x.0)
                .unwrap();
            let withdrawn = s
                .claims
                .iter()
                .find(|(t, c2, i, put)| !*put && *t >= sent && c2 == ch && i == nc)
                .map(|x| x.0)
                .unwrap();
            assert!(
                claimed <= withdrawn,
                "{ch}: claimed by {na} {:?} after {nc} withdrew",
                claimed.duration_since(withdrawn)
            );
        }
    }
    assert!(
        c.log()
            .contains("Handed every channel over before stopping."),
        "{}",
        c.log()
    );

    // 6. More kills: c restarted, then b started and killed, three times.
    let c = Instance::start(&cfg_path, nc, &endpoint);
    for _ in 0..3 {
        let mut b = Instance::start(&cfg_path, nb, &endpoint);
        wait_for(
            &seen,
            "the first assignment again",
            Duration::from_secs(10),
            |s| s.single_owners().filter(|o| *o == expected),
        )
        .await;
        tokio::time::sleep(Duration::from_millis(300)).await;
        takeovers.extend(kill_and_measure(&mut b, &seen).await);
    }
    stop.store(true, Ordering::Relaxed);
    publisher.join().unwrap();

    let cached = |t: &Takeover| t.channel.as_str() < format!("ch{CACHED:02}").as_str();
    let mut times: Vec<Duration> = takeovers.iter().map(|t| t.time).collect();
    times.sort();
    let ms = |d: &Duration| d.as_secs_f64() * 1e3;
    eprintln!(
        "takeover after kill -9 ({} channel moves over 5 kills): median {:.1} ms, worst {:.1} ms",
        times.len(),
        ms(&times[times.len() / 2]),
        ms(times.last().unwrap()),
    );
    for (label, with) in [
        ("with the publishers' cache", true),
        ("without history", false),
    ] {
        let mut missed: Vec<u64> = takeovers
            .iter()
            .filter(|t| cached(t) == with)
            .map(|t| t.missed)
            .collect();
        let mut blind: Vec<u64> = takeovers
            .iter()
            .filter(|t| cached(t) == with)
            .map(|t| t.blind)
            .collect();
        missed.sort_unstable();
        blind.sort_unstable();
        eprintln!(
            "{label} ({} moves): samples never processed median {}, worst {}; live samples before l_k again median {}, worst {}",
            missed.len(),
            missed[missed.len() / 2],
            missed.last().unwrap(),
            blind[blind.len() / 2],
            blind.last().unwrap(),
        );
    }
    assert!(
        *times.last().unwrap() < TAKEOVER_BOUND,
        "takeover times {times:?}"
    );
    // The settling (w = 100 samples) then one sample for the first onset.
    let settle = cfg.channels[0].settle.unwrap_or(100) + 1;
    for t in &takeovers {
        if cached(t) {
            assert_eq!((t.missed, t.blind), (0, 0), "warm from the cache: {t:?}");
        } else {
            assert!(t.missed <= 2, "{t:?}");
            assert_eq!(t.blind, t.missed + settle, "settled on live samples: {t:?}");
        }
    }
    // 7. A watcher that was away: `glrmon watch --since 1h` first prints the alarms
    //    the live instances kept, each naming its instance; a record published by
    //    anyone else is flagged.
    let mut watch = Command::new(env!("CARGO_BIN_EXE_glrmon"));
    watch
        .args([
            "watch",
            "glrmon/*/alarm",
            "--since",
            "1h",
            "--mode",
            "client",
        ])
        .args(["--connect", &endpoint]);
    let (mut watcher, _) = support::spawn_logged(&mut watch);
    let lines = Arc::new(Mutex::new(Vec::<String>::new()));
    {
        let (lines, out) = (Arc::clone(&lines), watcher.stdout.take().unwrap());
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
                lines.lock().unwrap().push(line);
            }
        });
    }
    let kept_by_a = seen
        .lock()
        .unwrap()
        .alarms
        .iter()
        .filter(|x| x.2 == na)
        .count();
    let t = Instant::now();
    while lines.lock().unwrap().len() < kept_by_a.min(32 * CHANNELS) {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "{kept_by_a} alarms of {na}, printed: {:?}",
            lines.lock().unwrap()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let from_a = format!("[from {na} g");
    assert!(
        lines
            .lock()
            .unwrap()
            .iter()
            .all(|l| l.contains("[from fleet")),
        "{:?}",
        lines.lock().unwrap()
    );
    assert!(
        lines
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.contains(&from_a))
            .count()
            >= kept_by_a.min(32),
        "{:?}",
        lines.lock().unwrap()
    );
    let printed = lines.lock().unwrap().len();
    // A real alarm record published again without a source, as any client could.
    let (channel, alarm_json) = {
        let s = seen.lock().unwrap();
        (s.alarms.last().unwrap().1.clone(), s.last_alarm.clone())
    };
    session
        .put(format!("glrmon/{channel}/alarm"), alarm_json)
        .await
        .unwrap();
    let t = Instant::now();
    while lines.lock().unwrap().len() <= printed {
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "the forged alarm is not printed"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let last = lines.lock().unwrap()[printed].clone();
    assert!(
        last.contains("[! no source: not published by a glrmon instance]"),
        "{last}"
    );
    let _ = watcher.kill();
    let _ = watcher.wait();

    drop((a, c));
    router.stop().await;
}
