//! Detector kinds side by side (`glrmon evaluate --detector glr,chi2,parity`): the
//! same injected faults, the same noise (the same seeds) and the same false-alarm
//! probability per sample for every kind, each at its own statistic's threshold.

use glrmon_report::FaultEvaluation;
use glrmon_spec::DetectorKind;

use crate::{EvalError, Protocol, evaluate, outcome_columns, summarize};

/// One kind's evaluation.
#[derive(Debug, Clone)]
pub struct KindEvaluation {
    /// The kind.
    pub kind: DetectorKind,
    /// One line naming the method and its settings.
    pub describe: String,
    /// Its threshold at the common false-alarm probability.
    pub threshold: f64,
    /// Whether its alarms name the faults (the kinds with minmax isolation, and the
    /// kernel kind with its exclusion).
    pub isolates: bool,
    /// The outcome columns of `faults`' confusion rows.
    pub columns: Vec<String>,
    /// Per injected fault.
    pub faults: Vec<FaultEvaluation>,
}

/// What [`compare`] ran.
#[derive(Debug, Clone)]
pub struct Compared {
    /// The protocol every kind ran.
    pub protocol: Protocol,
    /// The kinds that ran, in the order asked.
    pub kinds: Vec<KindEvaluation>,
    /// The kinds the channel cannot run, with why.
    pub skipped: Vec<(DetectorKind, String)>,
}

impl KindEvaluation {
    /// False alarms (before the onset) per 10⁴ fault-free samples, over every fault's
    /// runs.
    #[must_use]
    pub fn false_alarms_per_10k(&self, onset: u64) -> f64 {
        let alarms: u64 = self.faults.iter().map(|f| f.false_alarms).sum();
        let samples: u64 = self.faults.iter().map(|f| f.runs * onset).sum();
        1e4 * alarms as f64 / samples.max(1) as f64
    }

    /// The share of `fault`'s runs whose isolation named it alone; `None` for kinds
    /// that do not isolate.
    #[must_use]
    pub fn isolated_correctly(&self, fault: &FaultEvaluation) -> Option<f64> {
        if !self.isolates {
            return None;
        }
        let column = self.columns.iter().position(|c| *c == fault.fault)?;
        Some(fault.isolated.get(column).copied().unwrap_or(0) as f64 / fault.runs.max(1) as f64)
    }
}

/// Runs `injected` through channel `channel` of the configuration `text` once per kind
/// of `kinds` (the configuration edited by [`glrmon_spec::edit::set_detector`]), with
/// the same protocol: the onset and length given, else those of the configuration as
/// written, and the fault gone from `end` on if given; every kind at `false_alarm` per
/// sample if given, else at the configuration's.
///
/// A kind the channel cannot run (a `cusum` on ramp faults, a `uio` without `model.E`)
/// is left out and named with the reason in the second list, so that the others still
/// compare.
///
/// # Errors
/// [`EvalError::Protocol`] when the protocol is invalid or no kind can run (naming
/// each and why); as [`evaluate`].
pub fn compare(
    text: &str,
    channel: &str,
    kinds: &[DetectorKind],
    injected: &[(String, f64)],
    (onset, samples, runs, seed): (Option<u64>, Option<u64>, u64, u64),
    end: Option<u64>,
    false_alarm: Option<f64>,
) -> Result<Compared, EvalError> {
    let base = glrmon_spec::parse(text).map_err(|e| EvalError::Protocol(e.to_string()))?;
    let base = base
        .pick_channel(Some(channel))
        .map_err(|e| EvalError::Protocol(e.to_string()))?;
    let protocol = Protocol::for_channel(base, onset, samples, runs, seed)?.with_end(end)?;
    // A CUSUM without configured magnitudes is tuned for the injected ones (1 for a
    // fault not injected).
    let cusum: Vec<f64> = base
        .fault_names
        .iter()
        .map(|name| {
            injected
                .iter()
                .find(|(n, _)| n == name)
                .map_or(1.0, |(_, m)| *m)
        })
        .collect();
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    for &kind in kinds {
        let edited =
            glrmon_spec::edit::set_detector(text, channel, kind, false_alarm, Some(&cusum))
                .map_err(|e| e.to_string())
                .and_then(|t| glrmon_spec::parse(&t).map_err(|e| e.to_string()));
        let cfg = match edited {
            Ok(cfg) => cfg,
            Err(why) => {
                skipped.push((kind, why));
                continue;
            }
        };
        let ch = cfg
            .pick_channel(Some(channel))
            .map_err(|e| EvalError::Protocol(e.to_string()))?;
        let results = evaluate(ch, injected, protocol)?;
        let columns = outcome_columns(&ch.fault_names, &results);
        let faults = results
            .iter()
            .map(|r| summarize(r, protocol.onset, &columns))
            .collect();
        out.push(KindEvaluation {
            kind,
            describe: ch.detector()?.describe(),
            threshold: ch.alarm.threshold,
            isolates: kind.runs_kalman_filter() || kind == DetectorKind::Kernel,
            columns,
            faults,
        });
    }
    if out.is_empty() {
        let why: Vec<String> = skipped
            .iter()
            .map(|(k, why)| format!("detector `{}`: {why}", k.name()))
            .collect();
        return Err(EvalError::Protocol(why.join("\n")));
    }
    Ok(Compared {
        protocol,
        kinds: out,
        skipped,
    })
}
