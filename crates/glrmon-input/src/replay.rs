//! Replaying a file through channel pipelines: the loops behind `glrmon replay`, the
//! input read and decoded ahead on a thread of its own ([`ReadAhead`]), every input and
//! record handed to a [`Fanout`] in order, as the daemon's workers do live.

use std::collections::{BTreeMap, HashMap};
use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::Ordering;

use glrmon_runtime::{ChannelPipeline, Fanout, InputItem, PipelineError};
use glrmon_wire::{IntakeEvent, Sample};

use crate::{CsvReader, InputError, McapInput, ReadAhead, ReadAheadError};

/// Inputs between two progress reports of [`replay_mcap`].
const PROGRESS_EVERY: u64 = 65_536;

/// Why a replay stopped before the end of its input.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReplayError {
    /// The input could not be read (the items before it were replayed).
    #[error(transparent)]
    Read(#[from] ReadAheadError<InputError>),
    /// The reader thread could not be started.
    #[error("starting the replay reader thread: {0}")]
    Spawn(#[source] std::io::Error),
    /// A record could not be encoded or a sink failed.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// The input cannot be read as the configuration says (a foreign recording).
    #[error(transparent)]
    Input(InputError),
}

/// What a CSV replay went through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CsvReplayed {
    /// Data rows read.
    pub rows: u64,
    /// Rows refused (each became an `error` record).
    pub rejected: u64,
    /// One past the largest sample index fed: where the next file of a multi-file
    /// replay starts ([`replay_csv_from`]).
    pub next_k: u64,
}

/// Feeds every row of `csv` to `pipeline`; a bad row becomes an `error` record and the
/// replay goes on. A row's log time is its `t` (0 without).
///
/// # Errors
/// [`ReplayError`] when a sink fails, a record cannot be encoded or the reader thread
/// cannot start or dies.
pub fn replay_csv<R: BufRead + Send + 'static>(
    csv: CsvReader<R>,
    pipeline: &mut ChannelPipeline,
    fanout: &mut Fanout,
) -> Result<CsvReplayed, ReplayError> {
    replay_csv_from(csv, 0, pipeline, fanout)
}

/// [`replay_csv`] with the file's sample indices moved up by `first_k`: the next file
/// of a replay of several gets indices after the previous one's ([`CsvReplayed::next_k`]),
/// so that its records follow them. A row's `k` becomes `first_k + k`; a file without a
/// `k` column numbers its samples `first_k`, `first_k + 1`, … in order of arrival, as
/// the monitor numbers them from 0. With `first_k` = 0 the samples are fed untouched.
///
/// # Errors
/// As [`replay_csv`].
pub fn replay_csv_from<R: BufRead + Send + 'static>(
    csv: CsvReader<R>,
    first_k: u64,
    pipeline: &mut ChannelPipeline,
    fanout: &mut Fanout,
) -> Result<CsvReplayed, ReplayError> {
    let mut arrivals = 0u64;
    let mut rows_ahead = ReadAhead::spawn(csv, |csv, spare| {
        let mut sample = match spare {
            Some(Ok(sample)) => sample,
            _ => Sample::default(),
        };
        // A bad row keeps the time it may have carried, for the record's log time.
        Ok::<_, std::convert::Infallible>(csv.next_into(&mut sample).map(|row| match row {
            Ok(()) => Ok(sample),
            Err(e) => Err((e, sample.t)),
        }))
    })
    .map_err(ReplayError::Spawn)?;
    let mut done = CsvReplayed::default();
    while let Some(row) = rows_ahead.next().map_err(never)? {
        done.rows += 1;
        match row {
            Ok(mut sample) => {
                let k = sample.k.unwrap_or(arrivals);
                arrivals += 1;
                done.next_k = done.next_k.max(first_k.saturating_add(k).saturating_add(1));
                if first_k > 0 {
                    sample.k = Some(first_k.saturating_add(k));
                }
                let log_time = glrmon_record::sample_time_ns(sample.t, 0);
                pipeline.sample(&sample, log_time, fanout)?;
                rows_ahead.recycle(Ok(sample));
            }
            Err((e, t)) => {
                done.rejected += 1;
                let log_time = glrmon_record::sample_time_ns(t, 0);
                let message = format!("channel \"{}\": {}", pipeline.name(), e.message);
                pipeline.rejected(e.code, message, e.k, None, log_time, fanout)?;
            }
        }
    }
    rows_ahead.finish().map_err(never)?;
    Ok(done)
}

/// The reader of a CSV file has no error of its own: only its thread can fail.
fn never(e: ReadAheadError<std::convert::Infallible>) -> ReadAheadError<InputError> {
    match e {
        ReadAheadError::Source(never) => match never {},
        ReadAheadError::Stopped => ReadAheadError::Stopped,
        ReadAheadError::Panicked => ReadAheadError::Panicked,
    }
}

/// What an MCAP replay went through.
#[derive(Debug)]
pub struct McapReplayed {
    /// The input, for its end-of-file report ([`McapInput::damage_report`]).
    pub input: McapInput,
    /// Inputs read (of every channel).
    pub inputs: u64,
    /// Inputs of channels that have no pipeline, by channel (counted only when
    /// `count_unknown` was set).
    pub unknown: BTreeMap<Arc<str>, u64>,
    /// Refused payloads replayed, by channel.
    pub rejected: HashMap<Arc<str>, u64>,
}

/// Feeds every recorded input of `input` to the pipeline of its channel (found by
/// [`ChannelPipeline::name`]), in the recorded order; inputs of other channels are
/// skipped, and counted if `count_unknown`. `progress` hears the bytes read every
/// 65 536 inputs.
///
/// # Errors
/// [`ReplayError`] when the file cannot be read past a point, a sink fails, a record
/// cannot be encoded or the reader thread cannot start or dies.
pub fn replay_mcap(
    input: McapInput,
    pipelines: &mut [ChannelPipeline],
    count_unknown: bool,
    fanout: &mut Fanout,
    progress: &mut dyn FnMut(u64),
) -> Result<McapReplayed, ReplayError> {
    let index: HashMap<Arc<str>, usize> = pipelines
        .iter()
        .enumerate()
        .map(|(i, p)| (p.name().clone(), i))
        .collect();
    // Consecutive inputs of a channel share its name's allocation: the last one looked
    // up is remembered and compared by pointer.
    let mut last: Option<(Arc<str>, usize)> = None;
    let mut unknown = BTreeMap::new();
    let mut rejected = HashMap::new();
    let mut inputs = 0u64;
    let bytes_read = input.progress.0.clone();
    let mut inputs_ahead = ReadAhead::spawn(input, |input, spare| input.next_input(spare))
        .map_err(ReplayError::Spawn)?;
    while let Some(recorded) = inputs_ahead.next()? {
        inputs += 1;
        if inputs.is_multiple_of(PROGRESS_EVERY) {
            progress(bytes_read.load(Ordering::Relaxed));
        }
        let found = match &last {
            Some((name, i)) if Arc::ptr_eq(name, &recorded.channel) => Some(*i),
            _ => index.get(&recorded.channel).copied().inspect(|i| {
                last = Some((recorded.channel.clone(), *i));
            }),
        };
        let Some(pipeline) = found.and_then(|i| pipelines.get_mut(i)) else {
            if count_unknown {
                *unknown.entry(recorded.channel.clone()).or_insert(0) += 1;
            }
            inputs_ahead.recycle(recorded);
            continue;
        };
        if matches!(
            recorded.item,
            InputItem::Intake(IntakeEvent::Rejected { .. })
        ) {
            *rejected.entry(recorded.channel.clone()).or_insert(0) += 1;
        }
        pipeline.feed(&recorded.item, recorded.log_time_ns, fanout)?;
        inputs_ahead.recycle(recorded);
    }
    let input = inputs_ahead.finish()?;
    Ok(McapReplayed {
        input,
        inputs,
        unknown,
        rejected,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_runtime::{MemorySink, Sink};
    use glrmon_wire::Record;

    /// A bad row becomes an `error` record naming its row's k, after the `stat` of the
    /// row before, and the replay goes on to the next row.
    #[test]
    fn csv_replay_reports_a_bad_row_and_goes_on() {
        let cfg = glrmon_spec::parse(include_str!(
            "../../../config/examples/paper2014-unstable.toml"
        ))
        .unwrap();
        let channel = &cfg.channels[0];
        let text = "k,t,u0,y0\n0,0.0,0.1,1.0\n1,1.0,nan,1.0\n2,2.0,0.1,1.1\n";
        let csv =
            CsvReader::new(std::io::Cursor::new(text.as_bytes().to_vec()), channel.dims).unwrap();
        let memory = MemorySink::default();
        let records = memory.records();
        let mut fanout = Fanout::new(vec![Box::new(memory) as Box<dyn Sink>], 1);
        let monitor = glrmon_monitor::Monitor::from_channel(channel).unwrap();
        let mut pipeline = ChannelPipeline::new(0, monitor, fanout.plan());
        let done = replay_csv(csv, &mut pipeline, &mut fanout).unwrap();
        assert_eq!(
            done,
            CsvReplayed {
                rows: 3,
                rejected: 1,
                next_k: 3
            }
        );
        fanout.close(&mut |e| panic!("{e}"));
        let kinds: Vec<(&str, Option<u64>)> = records
            .lock()
            .unwrap()
            .iter()
            .map(|o| match &o.record {
                Record::Stat(s) => ("stat", Some(s.k)),
                Record::Error(e) => (e.code.as_str(), e.k),
                other => panic!("unexpected {other:?}"),
            })
            .collect();
        assert_eq!(kinds[0], ("stat", Some(0)));
        assert_eq!(kinds[1], ("non_finite", Some(1)));
        assert_eq!(kinds.last(), Some(&("stat", Some(2))));
        let errors = pipeline.stats().errors.lock().unwrap().clone();
        assert_eq!(errors.get("non_finite"), Some(&1));
    }

    #[test]
    fn a_second_file_follows_the_first_in_k_from_a_fresh_monitor() {
        let cfg = glrmon_spec::parse(include_str!(
            "../../../config/examples/paper2014-unstable.toml"
        ))
        .unwrap();
        let channel = &cfg.channels[0];
        let memory = MemorySink::default();
        let records = memory.records();
        let mut fanout = Fanout::new(vec![Box::new(memory) as Box<dyn Sink>], 1);
        let mut first_k = 0;
        for text in [
            "u0,y0\n0.1,1.0\n0.1,1.1\n0.1,0.9\n",
            "k,u0,y0\n0,0.1,1.0\n1,0.1,1.2\n",
        ] {
            let csv = CsvReader::new(std::io::Cursor::new(text.as_bytes().to_vec()), channel.dims)
                .unwrap();
            let monitor = glrmon_monitor::Monitor::from_channel(channel).unwrap();
            let mut pipeline = ChannelPipeline::new(0, monitor, fanout.plan());
            first_k = replay_csv_from(csv, first_k, &mut pipeline, &mut fanout)
                .unwrap()
                .next_k;
            assert_eq!(
                pipeline.error_total(),
                0,
                "no sequence reset: a fresh monitor"
            );
        }
        assert_eq!(first_k, 5);
        fanout.close(&mut |e| panic!("{e}"));
        let ks: Vec<u64> = records
            .lock()
            .unwrap()
            .iter()
            .filter_map(|o| match &o.record {
                Record::Stat(s) => Some(s.k),
                _ => None,
            })
            .collect();
        assert_eq!(ks, [0, 1, 2, 3, 4]);
    }
}
