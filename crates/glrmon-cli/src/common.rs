//! What every subcommand shares: the user-error type behind exit code 1, loading a
//! configuration, choosing its channel, a simulator with the `--fault` flags' faults,
//! and the default endpoint.

use std::path::Path;

use glrmon_sim::Simulator;
use glrmon_spec::Channel;

use crate::flags::FaultArg;

/// Where `run` listens and `watch`/`simulate --publish` connect when nothing is given.
pub(crate) const DEFAULT_ENDPOINT: &str = "tcp/127.0.0.1:7447";

/// How the user ran this binary, for commands printed as hints: `glrmon` when it was
/// found on the PATH, else the path it was run by (`target/release/glrmon` after
/// `make demo`), so the hint can be pasted as it is.
pub(crate) fn invoked_as() -> String {
    std::env::args_os()
        .next()
        .map(std::path::PathBuf::from)
        .filter(|p| p.components().count() > 1)
        .map_or_else(|| "glrmon".to_owned(), |p| p.display().to_string())
}

/// A user's input or configuration is at fault (exit code 1).
#[derive(Debug)]
pub(crate) struct InvalidInput(pub(crate) String);

impl std::fmt::Display for InvalidInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for InvalidInput {}

/// An input file's error with its exit code: [`InvalidInput`] (1) when the user's file
/// is at fault, a runtime failure (3) otherwise.
pub(crate) fn input_error(e: glrmon_input::InputError) -> anyhow::Error {
    if e.is_invalid_input() {
        InvalidInput(e.to_string()).into()
    } else {
        e.into()
    }
}

/// An error of reading ahead: the source's as [`input_error`], the reader thread's a
/// runtime failure.
pub(crate) fn read_ahead_error(
    e: glrmon_input::ReadAheadError<glrmon_input::InputError>,
) -> anyhow::Error {
    match e {
        glrmon_input::ReadAheadError::Source(e) => input_error(e),
        e => e.into(),
    }
}

/// Loads a configuration; every problem becomes one line of an [`InvalidInput`],
/// `file:line:column: path: reason` where the line is known.
pub(crate) fn load_config(path: &Path) -> anyhow::Result<glrmon_spec::Config> {
    glrmon_spec::load(path).map_err(|e| {
        let file = path.display().to_string();
        InvalidInput(format!("{file} is invalid:\n{}", e.in_file(&file))).into()
    })
}

/// The channel a command works on (`--channel`, or the only one).
pub(crate) fn pick<'a>(
    cfg: &'a glrmon_spec::Config,
    name: Option<&str>,
) -> anyhow::Result<&'a glrmon_spec::Channel> {
    cfg.pick_channel(name)
        .map_err(|e| InvalidInput(e.to_string()).into())
}

/// The channel's simulator ([`glrmon_sim::from_channel`]) with the `--fault`
/// faults injected at `onset`.
pub(crate) fn simulator(
    channel: &Channel,
    seed: u64,
    faults: &[FaultArg],
    onset: u64,
) -> anyhow::Result<Simulator> {
    let faults: Vec<(String, f64)> = faults
        .iter()
        .map(|f| (f.name.clone(), f.magnitude))
        .collect();
    glrmon_sim::faulty_simulator(channel, seed, &faults, onset).map_err(|e| match e {
        glrmon_sim::ChannelError::UnknownFault { .. } => {
            InvalidInput(format!("--fault: {e}")).into()
        }
        other => other.into(),
    })
}

/// A reliable publisher on `key` with `encoding` that keeps its last `cache` samples
/// for an instance that takes the channel over (`glrmon_zenoh::plant_publisher`),
/// once a subscriber matches (so that the first samples are not lost); an error after
/// 10 s without one.
pub(crate) async fn matched_publisher(
    session: &zenoh::Session,
    key: &str,
    encoding: zenoh::bytes::Encoding,
    cache: usize,
) -> anyhow::Result<zenoh_ext::AdvancedPublisher<'static>> {
    let publisher = glrmon_zenoh::plant_publisher(session, key, encoding, cache)
        .await
        .map_err(|e| anyhow::anyhow!("declaring a publisher on {key}: {e}"))?;
    let start = std::time::Instant::now();
    while !publisher
        .matching_status()
        .await
        .is_ok_and(|m| m.matching())
    {
        if start.elapsed() > std::time::Duration::from_secs(10) {
            anyhow::bail!("no subscriber on {key} after 10 s: is `glrmon run` reachable?");
        }
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
    Ok(publisher)
}

/// Lowers the calling thread's scheduling priority by `nice` (Linux: a thread may always
/// lower its own; elsewhere nothing), for work that must not take the CPU from intake
/// and the monitors.
pub(crate) fn lower_thread_priority(nice: i32) {
    #[cfg(target_os = "linux")]
    // SAFETY: gettid, getpriority and setpriority take and return plain integers;
    // setpriority on the calling thread's id changes only that thread.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        let current = libc::getpriority(libc::PRIO_PROCESS, tid);
        let _ = libc::setpriority(libc::PRIO_PROCESS, tid, current + nice);
    }
    #[cfg(not(target_os = "linux"))]
    let _ = nice;
}
