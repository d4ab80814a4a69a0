//! Reading recorded inputs from MCAP: the configuration from the `glrmon` metadata,
//! then each channel's samples and intake events in the order the monitors saw them.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use glrmon_record::{Event, FileHeader, METADATA_NAME, McapReader, ReadEnd, TopicKind};
use glrmon_runtime::InputItem;
use glrmon_wire::{DecodeLimits, Sample, decode_intake, decode_samples};

use crate::InvalidInput;

/// Counts the bytes read, for the progress bar.
pub(crate) struct Counting<R> {
    inner: R,
    read: Arc<AtomicU64>,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// One recorded input: its channel, what the monitor was fed, and its receive time.
pub(crate) struct RecordedInput {
    pub(crate) channel: Arc<str>,
    pub(crate) item: InputItem,
    /// The recorded receive time (ns since the Unix epoch).
    pub(crate) log_time_ns: u64,
}

/// Spare samples kept for decoding into.
const SPARE_SAMPLES: usize = 64;

/// A recording opened for its inputs.
pub(crate) struct McapInput {
    reader: McapReader<Counting<BufReader<File>>>,
    /// The recorded configuration and channels (absent in a file without them).
    pub(crate) header: Option<FileHeader>,
    /// Bytes read so far and the file's size.
    pub(crate) progress: (Arc<AtomicU64>, u64),
    pending: VecDeque<Event>,
    samples: Vec<Sample>,
    /// Samples the consumer handed back ([`McapInput::next_input`]), decoded into again.
    spare_samples: Vec<Sample>,
    queued: VecDeque<RecordedInput>,
    limits: DecodeLimits,
    /// Recorded result messages met (not replayed).
    pub(crate) results: u64,
    /// Input messages that could not be decoded.
    pub(crate) bad_inputs: Vec<String>,
    /// The shared name of each channel met (one allocation per channel, and consumers
    /// can compare pointers), and the last one used.
    channel_names: std::collections::HashMap<String, Arc<str>>,
    last_channel: Option<Arc<str>>,
}

/// Whether a path names an MCAP file.
pub(crate) fn is_mcap(path: &Path) -> bool {
    path.extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("mcap"))
        || path
            .to_string_lossy()
            .ends_with(glrmon_record::PARTIAL_SUFFIX)
}

impl McapInput {
    /// Opens a recording and reads up to its `glrmon` metadata (written first).
    pub(crate) fn open(path: &Path) -> anyhow::Result<Self> {
        let file = File::open(path)
            .map_err(|e| InvalidInput(format!("{}: cannot open: {e}", path.display())))?;
        let size = file.metadata().map_or(0, |m| m.len());
        let read = Arc::new(AtomicU64::new(0));
        let counting = Counting {
            inner: BufReader::with_capacity(1 << 16, file),
            read: read.clone(),
        };
        let mut reader = McapReader::new(counting)
            .map_err(|e| InvalidInput(format!("{}: {e}", path.display())))?;
        let mut pending = VecDeque::new();
        let mut header = None;
        while let Some(event) = reader.next_event()? {
            if let Event::Metadata { name, entries } = &event {
                if name == METADATA_NAME {
                    header = Some(glrmon_record::header_from_metadata(entries));
                    break;
                }
            }
            let is_message = matches!(event, Event::Message(_));
            pending.push_back(event);
            if is_message {
                break;
            }
        }
        Ok(Self {
            reader,
            header,
            progress: (read, size),
            pending,
            samples: Vec::new(),
            spare_samples: Vec::new(),
            queued: VecDeque::new(),
            limits: DecodeLimits::default(),
            results: 0,
            bad_inputs: Vec::new(),
            channel_names: std::collections::HashMap::new(),
            last_channel: None,
        })
    }

    /// Decoding limits for the recorded samples (the live run's).
    pub(crate) fn set_limits(&mut self, limits: DecodeLimits) {
        self.limits = limits;
    }

    /// The next recorded input of any channel, in file order. `spare` is an input the
    /// consumer is done with: its sample is decoded into again (no allocation per
    /// sample, and the memory is freed by the thread that allocated it).
    pub(crate) fn next_input(
        &mut self,
        spare: Option<RecordedInput>,
    ) -> anyhow::Result<Option<RecordedInput>> {
        if let Some(RecordedInput {
            item: InputItem::Sample(s),
            ..
        }) = spare
        {
            if self.spare_samples.len() < SPARE_SAMPLES {
                self.spare_samples.push(s);
            }
        }
        loop {
            if let Some(i) = self.queued.pop_front() {
                return Ok(Some(i));
            }
            let event = match self.pending.pop_front() {
                Some(e) => e,
                None => match self.reader.next_event()? {
                    Some(e) => e,
                    None => return Ok(None),
                },
            };
            let Event::Message(m) = event else { continue };
            let (Some(channel), Some(kind)) = (&m.topic.channel, m.topic.kind) else {
                continue;
            };
            match kind {
                TopicKind::Inputs => {
                    if self.samples.is_empty() {
                        self.samples.extend(self.spare_samples.pop());
                    }
                    match decode_samples(channel, &m.data, &self.limits, &mut self.samples) {
                        Ok(()) => {
                            let name = self.channel_name(channel);
                            for s in self.samples.drain(..) {
                                self.queued.push_back(RecordedInput {
                                    channel: name.clone(),
                                    item: InputItem::Sample(s),
                                    log_time_ns: m.log_time,
                                });
                            }
                        }
                        Err(e) => self.note_bad(format!("{}: {e}", m.topic.topic)),
                    }
                }
                TopicKind::Intake => match decode_intake(&m.data) {
                    Ok(event) => {
                        let name = self.channel_name(channel);
                        self.queued.push_back(RecordedInput {
                            channel: name,
                            item: InputItem::Intake(event),
                            log_time_ns: m.log_time,
                        });
                    }
                    Err(e) => self.note_bad(format!("{}: {e}", m.topic.topic)),
                },
                _ => self.results += 1,
            }
        }
    }

    /// The shared name of `channel`.
    fn channel_name(&mut self, channel: &str) -> Arc<str> {
        match &self.last_channel {
            Some(name) if **name == *channel => name.clone(),
            _ => {
                let name = match self.channel_names.get(channel) {
                    Some(name) => name.clone(),
                    None => {
                        let name: Arc<str> = Arc::from(channel);
                        self.channel_names.insert(channel.to_owned(), name.clone());
                        name
                    }
                };
                self.last_channel = Some(name.clone());
                name
            }
        }
    }

    fn note_bad(&mut self, message: String) {
        if self.bad_inputs.len() < 100 {
            self.bad_inputs.push(message);
        }
    }

    /// Damaged parts and how the file ended, as lines for the operator; `true` when
    /// data was lost to damage (not merely an unfinished file).
    pub(crate) fn damage_report(&self) -> (Vec<String>, bool) {
        let mut lines: Vec<String> = self
            .reader
            .damage()
            .iter()
            .map(|d| format!("damaged: {d}"))
            .collect();
        let mut damaged = !lines.is_empty() || !self.bad_inputs.is_empty();
        lines.extend(
            self.bad_inputs
                .iter()
                .map(|b| format!("bad input message: {b}")),
        );
        match self.reader.end() {
            ReadEnd::Finished | ReadEnd::Reading => {}
            ReadEnd::Truncated { at, partial } => lines.push(format!(
                "the file is unfinished (no footer: the recorder was killed?): read up to byte \
                 {at}{}; `glrmon recover` rewrites it as a finished file",
                if *partial > 0 {
                    format!(", {partial} bytes of an incomplete last record ignored")
                } else {
                    String::new()
                }
            )),
            ReadEnd::Unreadable { at, reason } => {
                damaged = true;
                lines.push(format!("unreadable from byte {at}: {reason}"));
            }
        }
        (lines, damaged)
    }

    /// Messages read so far.
    pub(crate) fn messages(&self) -> u64 {
        self.reader.messages()
    }
}
