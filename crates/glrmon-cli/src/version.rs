//! `glrmon --version`: the package version and the commit it was built from.

use std::sync::OnceLock;

/// `0.1.0 (git 1a2b3c4d5e6f)`, or `(git unknown)` when built outside a git checkout
/// (from a source tarball).
pub(crate) fn long() -> &'static str {
    static LONG: OnceLock<String> = OnceLock::new();
    LONG.get_or_init(|| {
        format!(
            "{} (git {})",
            env!("CARGO_PKG_VERSION"),
            env!("GLRMON_GIT_COMMIT")
        )
    })
}
