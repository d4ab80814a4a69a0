//! Sets `GLRMON_GIT_HASH` for `glrmon_metrics::GIT_HASH`: the environment's
//! `GLRMON_GIT_HASH` if set (a packager building from a tarball can pass the hash it
//! knows), else `git rev-parse --short HEAD` of the checkout being built, else
//! "unknown" (no git, or not a checkout of glrmon): never a build failure.

use std::path::PathBuf;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let text = String::from_utf8(out.stdout).ok()?;
    let text = text.trim();
    (!text.is_empty()).then(|| text.to_owned())
}

fn main() {
    println!("cargo:rerun-if-env-changed=GLRMON_GIT_HASH");
    let from_env = std::env::var("GLRMON_GIT_HASH")
        .ok()
        .filter(|h| !h.trim().is_empty());
    let hash = from_env.or_else(|| {
        // A tarball unpacked inside some other repository is not a checkout of glrmon:
        // this file must be tracked by the repository git finds.
        git(&["ls-files", "--error-unmatch", "build.rs"])?;
        let hash = git(&["rev-parse", "--short", "HEAD"])?;
        // Built again when HEAD moves: HEAD itself (a checkout of another branch or
        // commit) and the branch it points to (a commit), loose or packed.
        if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
            println!(
                "cargo:rerun-if-changed={}",
                PathBuf::from(dir).join("HEAD").display()
            );
        }
        if let (Some(common), Some(branch)) = (
            git(&["rev-parse", "--git-common-dir"]),
            git(&["symbolic-ref", "-q", "HEAD"]),
        ) {
            let common = PathBuf::from(common);
            let loose = common.join(&branch);
            if loose.exists() {
                println!("cargo:rerun-if-changed={}", loose.display());
            }
            // Only files that exist: cargo reruns a build script on every build while
            // one of its watched paths is missing.
            let packed = common.join("packed-refs");
            if packed.exists() {
                println!("cargo:rerun-if-changed={}", packed.display());
            }
        }
        Some(hash)
    });
    // Only characters that need no escaping in a Prometheus label value.
    let hash: String = hash
        .unwrap_or_else(|| "unknown".to_owned())
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.' | '_' | '+'))
        .take(64)
        .collect();
    let hash = if hash.is_empty() {
        "unknown".to_owned()
    } else {
        hash
    };
    println!("cargo:rustc-env=GLRMON_GIT_HASH={hash}");
}
