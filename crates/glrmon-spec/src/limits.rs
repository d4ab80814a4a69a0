//! Upper bounds on every size a configuration sets, and the memory a channel needs.
//!
//! A configuration must never make glrmon panic, abort on an allocation or compute for
//! minutes (as some did: `window = 2⁶³−1` overflowed a capacity, `window = 1e9`
//! asked for 8 GB, a diagnosis `history = 1e12` for 184 TB). Each size has a hard limit
//! below, and on top of them the memory a channel allocates when its monitor is built,
//! estimated by [`ChannelFootprint::bytes`] from n, p, l, m, w and the diagnosis history,
//! must stay within [`CHANNEL_MEMORY_BUDGET`]. `glrmon validate` and every reload
//! (SIGHUP) check both, with the path of the field.
//!
//! The estimate follows the allocations of `glrmon_core` (the GLR window bank and its
//! stationary tables) and `glrmon_monitor` (the diagnosis ring), in 8-byte numbers:
//!
//! ```text
//! bank     = w · (3nm + 2pm + 2m² + 6m + 7)                         (per onset slot)
//! matrices = 16 · (n² + p² + np + nl + pl + nm + pm) + 64
//! ring     = history · (n² + 2np + p² + p + (n + p)m + 32)          (diagnosis, per sample)
//! bytes    = 8 · (bank + matrices + ring)
//! ```
//!
//! The ring is counted whether or not `[channels.diagnosis] enabled` is set, because
//! `glrmon diagnose` builds it for any channel.

/// Most states n (rows of F).
pub const MAX_STATES: usize = 128;
/// Most outputs p (rows of H).
pub const MAX_OUTPUTS: usize = 64;
/// Most known inputs l (columns of G or J).
pub const MAX_INPUTS: usize = 64;
/// Most scheduling signals q (`signals`, or `p<i>` of an LPV matrix or expression).
pub const MAX_SIGNALS: usize = 1024;
/// Most faults m in a dictionary (after the `all_sensors`/`all_actuators` shortcuts).
pub const MAX_FAULTS: usize = 128;
/// Most rows or columns of any matrix as written (before its shape is checked against
/// n, p and l).
pub const MAX_MATRIX_SIDE: usize = 256;
/// Largest GLR window w (`glr.window`); the memory budget lowers it for large channels.
pub const MAX_WINDOW: usize = 100_000;
/// Largest `glr.max_gap`: a gap is bridged by as many predict-only steps.
pub const MAX_GAP: u64 = 100_000;
/// Largest `glr.max_reorder`.
pub const MAX_REORDER: u64 = 1_000_000;
/// Largest `glr.settle` in samples.
pub const MAX_SETTLE: u64 = 1_000_000_000;
/// Largest `glr.warm_up` in samples.
pub const MAX_WARM_UP: u64 = 1_000_000_000;
/// Largest diagnosis `history` and `span`, in samples.
pub const MAX_HISTORY: usize = 1_000_000;
/// Most points of the Lasso λ path (`diagnosis.lasso.path_points`).
pub const MAX_PATH_POINTS: usize = 10_000;
/// Largest consistency block (`consistency.window`), in samples.
pub const MAX_CONSISTENCY_WINDOW: usize = 100_000_000;
/// Most worker threads (`daemon.workers`).
pub const MAX_WORKERS: usize = 1024;
/// Largest queue in messages (`daemon.worker_queue`, `daemon.output_queue`,
/// `recording.queue`).
pub const MAX_QUEUE: usize = 1 << 22;
/// Largest accepted payload (`daemon.max_payload_bytes`): 64 MiB.
pub const MAX_PAYLOAD_BYTES: usize = 64 << 20;
/// Longest pre-fault capture kept in memory (`recording.capture.before_seconds`), and
/// longest post-fault capture, in seconds.
pub const MAX_CAPTURE_SECONDS: f64 = 3600.0;
/// Smallest `[channels.scaling]` scale (`u_scale`, `y_scale`). A raw-unit fault's
/// signature is e_j/scale in model units and the GLR's Fisher information sums its
/// square over the window; the isolation tests multiply two of those. Scales within
/// 10^±60 keep these products inside f64's range (10^±308) for any window up to
/// [`MAX_WINDOW`]; a scale of 1e-300 overflowed the signature, one of 1e160 underflowed
/// the correlation of two faults into ±∞.
pub const MIN_SCALE: f64 = 1e-60;
/// Largest `[channels.scaling]` scale (see [`MIN_SCALE`]).
pub const MAX_SCALE: f64 = 1e60;
/// Largest |offset| of `[channels.scaling]` (`u_offset`, `y_offset`): a raw sample near
/// 0 becomes −offset/scale in model units, which the monitor refuses beyond 10¹⁰⁰
/// (`too_large`): MAX_OFFSET / [`MIN_SCALE`] = 10¹⁰⁰. An offset of 1e308 made every
/// sample `too_large`.
pub const MAX_OFFSET: f64 = 1e40;
/// Memory one channel may need, by [`ChannelFootprint::bytes`]: 1 GiB.
pub const CHANNEL_MEMORY_BUDGET: u64 = 1 << 30;

/// What sizes a channel's memory: its dimensions, window and diagnosis history.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelFootprint {
    /// n.
    pub states: usize,
    /// p.
    pub outputs: usize,
    /// l.
    pub inputs: usize,
    /// m.
    pub faults: usize,
    /// w.
    pub window: usize,
    /// Diagnosis history in samples.
    pub history: usize,
}

impl ChannelFootprint {
    /// Bytes of the GLR window bank and its stationary tables (see the module docs).
    #[must_use]
    pub fn window_bytes(&self) -> u64 {
        let (n, p, m) = (self.states as u64, self.outputs as u64, self.faults as u64);
        let per_slot = 3 * n * m + 2 * p * m + 2 * m * m + 6 * m + 7;
        8u64.saturating_mul(self.window as u64)
            .saturating_mul(per_slot)
    }

    /// Bytes of the diagnosis ring (see the module docs).
    #[must_use]
    pub fn history_bytes(&self) -> u64 {
        let (n, p, m) = (self.states as u64, self.outputs as u64, self.faults as u64);
        let per_sample = n * n + 2 * n * p + p * p + p + (n + p) * m + 32;
        8u64.saturating_mul(self.history as u64)
            .saturating_mul(per_sample)
    }

    /// Bytes of the model's and filter's own matrices.
    #[must_use]
    pub fn matrix_bytes(&self) -> u64 {
        let (n, p, l, m) = (
            self.states as u64,
            self.outputs as u64,
            self.inputs as u64,
            self.faults as u64,
        );
        8 * (16 * (n * n + p * p + n * p + n * l + p * l + n * m + p * m) + 64)
    }

    /// The estimate of the memory the channel's monitor allocates.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        self.window_bytes()
            .saturating_add(self.history_bytes())
            .saturating_add(self.matrix_bytes())
    }

    /// `window bank X for w = …, diagnosis ring Y for history = …`, for messages.
    #[must_use]
    pub fn breakdown(&self) -> String {
        format!(
            "window bank {} for w = {} with n = {}, p = {}, m = {}; diagnosis ring {} for \
             history = {}",
            human_bytes(self.window_bytes()),
            self.window,
            self.states,
            self.outputs,
            self.faults,
            human_bytes(self.history_bytes()),
            self.history
        )
    }
}

/// `1.5 GiB`, `12.0 MiB`, `800 B`.
#[must_use]
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 6] = ["KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut value = bytes as f64 / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.1} {}", UNITS[unit])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimate_follows_the_formula_and_saturates() {
        let f = ChannelFootprint {
            states: 2,
            outputs: 1,
            inputs: 1,
            faults: 2,
            window: 100,
            history: 200,
        };
        // 3·2·2 + 2·1·2 + 2·4 + 12 + 7 = 43 numbers per slot.
        assert_eq!(f.window_bytes(), 8 * 100 * 43);
        // 4 + 4 + 1 + 1 + 3·2 + 32 = 48 numbers per sample.
        assert_eq!(f.history_bytes(), 8 * 200 * 48);
        let huge = ChannelFootprint {
            window: usize::MAX,
            history: usize::MAX,
            ..f
        };
        assert_eq!(huge.bytes(), u64::MAX);
        assert_eq!(human_bytes(1 << 30), "1.0 GiB");
        assert_eq!(human_bytes(800), "800 B");
    }
}
