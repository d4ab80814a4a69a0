//! The fan-out of inputs and records to the sinks, with each sink's decimation of
//! `stat` records: the one copy used by the daemon's output stage and by replay.

use crate::sink::{InputOutput, Interest, Output, Sink, SinkError};

/// What the pipelines must produce for a set of sinks, worked out once from their
/// [`Interest`]s ([`Fanout::plan`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DeliveryPlan {
    /// Some sink wants every input (a recorder).
    pub inputs: bool,
    /// The distinct non-zero `stat` decimations of the sinks (empty: no sink wants
    /// `stat` records, so monitors need not build them).
    stat_every: Vec<u64>,
}

impl DeliveryPlan {
    /// Whether some sink keeps the `stat` record at this position of its channel's
    /// `stat` records.
    #[must_use]
    pub fn wants_stat(&self, stat_index: u64) -> bool {
        self.stat_every
            .iter()
            .any(|&e| stat_index.is_multiple_of(e))
    }

    /// Whether some sink keeps any `stat` record.
    #[must_use]
    pub fn wants_stats(&self) -> bool {
        !self.stat_every.is_empty()
    }
}

/// Sinks with their interests resolved: every input goes to the sinks that asked for
/// inputs, every alarm, alarm end, diagnosis and error record to every sink, a `stat`
/// record to each sink whose decimation keeps its position.
///
/// # Examples
///
/// ```
/// use glrmon_runtime::{Fanout, MemorySink, Sink};
///
/// let memory = MemorySink::default();
/// let records = memory.records();
/// let mut fanout = Fanout::new(vec![Box::new(memory) as Box<dyn Sink>], 1);
/// assert!(fanout.plan().wants_stats());
/// fanout.close(&mut |e| panic!("{e}"));
/// assert!(records.lock().unwrap().is_empty());
/// ```
pub struct Fanout {
    sinks: Vec<Box<dyn Sink>>,
    interests: Vec<Interest>,
    records: u64,
    /// A record buffer the sinks are done with, for the next record's encoding.
    spare: Vec<u8>,
}

impl std::fmt::Debug for Fanout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fanout")
            .field(
                "sinks",
                &self.sinks.iter().map(|s| s.name()).collect::<Vec<_>>(),
            )
            .field("interests", &self.interests)
            .finish_non_exhaustive()
    }
}

impl Fanout {
    /// Asks each sink its [`Interest`] once; `default_stat_every` stands for a sink
    /// that names no decimation.
    #[must_use]
    pub fn new(sinks: Vec<Box<dyn Sink>>, default_stat_every: u64) -> Self {
        let interests = sinks
            .iter()
            .map(|s| {
                let i = s.interest();
                Interest {
                    inputs: i.inputs,
                    stat_every: Some(i.stat_every.unwrap_or(default_stat_every)),
                }
            })
            .collect();
        Self {
            sinks,
            interests,
            records: 0,
            spare: Vec::new(),
        }
    }

    /// What the pipelines feeding these sinks must produce.
    #[must_use]
    pub fn plan(&self) -> DeliveryPlan {
        let mut stat_every: Vec<u64> = self
            .interests
            .iter()
            .filter_map(|i| i.stat_every)
            .filter(|&e| e > 0)
            .collect();
        stat_every.sort_unstable();
        stat_every.dedup();
        DeliveryPlan {
            inputs: self.interests.iter().any(|i| i.inputs),
            stat_every,
        }
    }

    /// Hands an input to every sink that asked for inputs; each failure goes to
    /// `on_error` and the other sinks still get the input.
    pub fn input(&mut self, input: &InputOutput, on_error: &mut dyn FnMut(SinkError)) {
        for (s, interest) in self.sinks.iter_mut().zip(&self.interests) {
            if interest.inputs
                && let Err(e) = s.write_input(input)
            {
                on_error(e);
            }
        }
    }

    /// Hands a record to every sink that keeps it; each failure goes to `on_error`
    /// and the other sinks still get the record.
    pub fn record(&mut self, output: &Output, on_error: &mut dyn FnMut(SinkError)) {
        self.records += 1;
        for (s, interest) in self.sinks.iter_mut().zip(&self.interests) {
            if let Some(index) = output.stat_index {
                let every = interest.stat_every.unwrap_or(0);
                if every == 0 || index % every != 0 {
                    continue;
                }
            }
            if let Err(e) = s.write(output) {
                on_error(e);
            }
        }
    }

    /// Flushes every sink.
    pub fn flush(&mut self, on_error: &mut dyn FnMut(SinkError)) {
        for s in &mut self.sinks {
            if let Err(e) = s.flush() {
                on_error(e);
            }
        }
    }

    /// Closes every sink ([`Sink::close`]) and gives them back.
    pub fn close(mut self, on_error: &mut dyn FnMut(SinkError)) -> Vec<Box<dyn Sink>> {
        for s in &mut self.sinks {
            if let Err(e) = s.close() {
                on_error(e);
            }
        }
        self.sinks
    }

    /// Keeps a record's buffer for [`Fanout::take_buffer`].
    pub(crate) fn give_back(&mut self, mut json: Vec<u8>) {
        json.clear();
        self.spare = json;
    }

    /// The kept buffer, or a new one of `capacity`.
    pub(crate) fn take_buffer(&mut self, capacity: usize) -> Vec<u8> {
        if self.spare.capacity() == 0 {
            Vec::with_capacity(capacity)
        } else {
            std::mem::take(&mut self.spare)
        }
    }

    /// Records handed to [`Fanout::record`] so far.
    #[must_use]
    pub fn records(&self) -> u64 {
        self.records
    }
}
