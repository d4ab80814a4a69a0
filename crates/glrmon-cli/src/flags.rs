//! Zenoh flags shared by the commands that use the network (Zenoh's own flag names).

use std::path::PathBuf;

use clap::Args;
use glrmon_zenoh::SessionSettings;

/// Zenoh session flags; they override the configuration file's `[zenoh]` section.
#[derive(Debug, Args, Clone, Default)]
pub(crate) struct ZenohArgs {
    /// A Zenoh JSON5 configuration file, passed through untouched (TLS, auth, ACL).
    #[arg(long = "zenoh-config")]
    pub(crate) zenoh_config: Option<PathBuf>,
    /// `peer` (default) or `client`.
    #[arg(long)]
    pub(crate) mode: Option<String>,
    /// Endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable).
    #[arg(long)]
    pub(crate) connect: Vec<String>,
    /// Endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable).
    #[arg(long)]
    pub(crate) listen: Vec<String>,
    /// Disable multicast scouting (it is off by default; the flag is accepted for
    /// compatibility with Zenoh's tools).
    #[arg(long = "no-multicast-scouting")]
    pub(crate) no_multicast_scouting: bool,
}

impl ZenohArgs {
    /// Settings for a tool that talks to a daemon: client mode (a peer's `open` can
    /// wait for the 500 ms scouting delay, a client's does not; the daemon, a peer,
    /// routes for its clients) connecting to the local default endpoint, unless told
    /// otherwise.
    pub(crate) fn client_settings(&self) -> glrmon_zenoh::SessionSettings {
        let mut s = self.settings(None);
        if s.config_file.is_none() {
            if s.mode.is_none() {
                s.mode = Some("client".into());
            }
            if s.connect.is_empty() && s.listen.is_empty() {
                s.connect = vec![crate::common::DEFAULT_ENDPOINT.to_owned()];
            }
        }
        s
    }

    /// Command-line flags over the configuration file's section.
    pub(crate) fn settings(
        &self,
        file: Option<&glrmon_spec::schema::ZenohSpec>,
    ) -> SessionSettings {
        let mut s = SessionSettings::default();
        if let Some(f) = file {
            s.config_file.clone_from(&f.config);
            s.mode.clone_from(&f.mode);
            s.connect.clone_from(&f.connect);
            s.listen.clone_from(&f.listen);
            s.multicast_scouting = f.multicast_scouting;
        }
        if self.zenoh_config.is_some() {
            s.config_file.clone_from(&self.zenoh_config);
        }
        if self.mode.is_some() {
            s.mode.clone_from(&self.mode);
        }
        if !self.connect.is_empty() {
            s.connect.clone_from(&self.connect);
        }
        if !self.listen.is_empty() {
            s.listen.clone_from(&self.listen);
        }
        if self.no_multicast_scouting {
            s.multicast_scouting = Some(false);
        }
        s
    }
}
