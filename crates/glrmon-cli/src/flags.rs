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
    /// The Zenoh session's mode. Default: `peer` for `run` and `demo`; `client` for
    /// the tools that talk to a daemon (`watch`, `status`, `simulate --publish`,
    /// `play`), connecting to tcp/127.0.0.1:7447 unless `--connect` or `--listen`
    /// says otherwise.
    #[arg(long, value_enum)]
    pub(crate) mode: Option<Mode>,
    /// Endpoint to connect to, PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447 (repeatable).
    #[arg(long, value_name = "ENDPOINT", value_parser = endpoint)]
    pub(crate) connect: Vec<String>,
    /// Endpoint to listen on, PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447 (repeatable).
    #[arg(long, value_name = "ENDPOINT", value_parser = endpoint)]
    pub(crate) listen: Vec<String>,
    /// Disable multicast scouting (it is off by default; the flag is accepted for
    /// compatibility with Zenoh's tools).
    #[arg(long = "no-multicast-scouting")]
    pub(crate) no_multicast_scouting: bool,
}

impl ZenohArgs {
    /// Settings for a tool that talks to a daemon (`watch`, `status`, `play`,
    /// `simulate --publish`): client mode (a peer's `open` can wait for the 500 ms
    /// scouting delay, a client's does not; the daemon, a peer, routes for its clients)
    /// connecting to the local default endpoint, unless told otherwise; the flags that
    /// set its endpoints are named for the message of a failure to connect or listen.
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
        let from_file = |key: &str| {
            self.zenoh_config.as_ref().map_or_else(String::new, |f| {
                format!(
                    " (or {key} in {})",
                    glrmon_wire::text::Escaped(&f.to_string_lossy())
                )
            })
        };
        s.connect_hint = Some(if self.connect.is_empty() {
            format!("--connect{}", from_file("connect/endpoints"))
        } else {
            "--connect".into()
        });
        s.listen_hint = Some(if self.listen.is_empty() {
            format!("--listen{}", from_file("listen/endpoints"))
        } else {
            "--listen".into()
        });
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
        if let Some(mode) = self.mode {
            s.mode = Some(mode.as_str().to_owned());
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

/// A Zenoh session mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Mode {
    /// Talks to other peers directly and routes for its clients.
    Peer,
    /// Talks through one peer or router only.
    Client,
    /// Routes between peers and clients (as zenohd does).
    Router,
}

impl Mode {
    /// Zenoh's name of the mode.
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
            Mode::Router => "router",
        }
    }
}

/// Checks a Zenoh endpoint when the command line is parsed
/// ([`glrmon_spec::check_endpoint`], then Zenoh's own parser).
pub(crate) fn endpoint(s: &str) -> Result<String, String> {
    glrmon_spec::check_endpoint(s)?;
    s.parse::<zenoh::config::EndPoint>().map_err(|_| {
        format!("\"{s}\" is not a Zenoh endpoint: PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
    })?;
    Ok(s.to_owned())
}

/// A fault of the channel's dictionary and its magnitude θ: `--fault NAME:MAGNITUDE`
/// (the one spelling of every command that injects faults).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FaultArg {
    /// The fault's name in the dictionary.
    pub(crate) name: String,
    /// Its magnitude θ (finite).
    pub(crate) magnitude: f64,
}

impl std::str::FromStr for FaultArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let Some((name, magnitude)) = s.rsplit_once(':') else {
            return Err(format!(
                "expected NAME:MAGNITUDE, e.g. {s}:1.5 (the magnitude is part of --fault; \
                 there is no --magnitude)"
            ));
        };
        if name.is_empty() {
            return Err("the fault name before ':' is empty".into());
        }
        let magnitude = magnitude
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|m| m.is_finite())
            .ok_or_else(|| format!("\"{magnitude}\" is not a finite number"))?;
        Ok(FaultArg {
            name: name.to_owned(),
            magnitude,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_arguments() {
        let f: FaultArg = "y0_bias:-2.5".parse().unwrap();
        assert_eq!(
            f,
            FaultArg {
                name: "y0_bias".into(),
                magnitude: -2.5
            }
        );
        assert!(
            "y0_bias"
                .parse::<FaultArg>()
                .unwrap_err()
                .contains("NAME:MAGNITUDE")
        );
        assert!(":1".parse::<FaultArg>().is_err());
        assert!("a:inf".parse::<FaultArg>().is_err());
        assert!("a:".parse::<FaultArg>().is_err());
    }

    #[test]
    fn endpoints_are_checked_when_parsed() {
        assert_eq!(
            endpoint("tcp/127.0.0.1:7447").unwrap(),
            "tcp/127.0.0.1:7447"
        );
        assert!(endpoint("tcp/[::1]:7447").is_ok());
        assert!(endpoint("tcp/localhost:7447#iface=lo").is_ok());
        let e = endpoint("127.0.0.1:1").unwrap_err();
        assert!(e.contains("e.g. tcp/127.0.0.1:1"), "{e}");
        assert!(endpoint("tcp/127.0.0.1").is_err());
        assert!(endpoint("tcp/127.0.0.1:99999").is_err());
        assert!(endpoint("/127.0.0.1:1").is_err());
        assert!(endpoint("t c p/127.0.0.1:1").is_err());
    }
}
