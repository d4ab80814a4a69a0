//! One module per subcommand: each parses its flags (`…Args`) and calls the
//! libraries; none imports another.

pub(crate) mod calibrate;
pub(crate) mod config;
pub(crate) mod demo;
pub(crate) mod diagnose;
pub(crate) mod docs;
pub(crate) mod evaluate;
pub(crate) mod identify;
pub(crate) mod info;
pub(crate) mod play;
pub(crate) mod recover;
pub(crate) mod replay;
pub(crate) mod run;
pub(crate) mod simulate;
pub(crate) mod status;
pub(crate) mod validate;
pub(crate) mod watch;
