//! `glrmon --version`: the package version and the commit it was built from.

use std::sync::OnceLock;

/// `0.1.0 (git 1a2b3c4)`, or `(git unknown)` when built outside a git checkout of
/// glrmon (a source tarball without `GLRMON_GIT_HASH`): the same commit as
/// `glrmon_build_info` ([`glrmon_metrics::GIT_HASH`]).
pub(crate) fn long() -> &'static str {
    static LONG: OnceLock<String> = OnceLock::new();
    LONG.get_or_init(|| {
        format!(
            "{} (git {})",
            env!("CARGO_PKG_VERSION"),
            glrmon_metrics::GIT_HASH
        )
    })
}
