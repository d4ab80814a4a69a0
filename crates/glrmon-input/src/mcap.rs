//! Reading recorded inputs from MCAP: the configuration from the `glrmon` metadata,
//! then each channel's samples and intake events in the order the monitors saw them.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use glrmon_record::{Event, FileHeader, METADATA_NAME, McapReader, ReadEnd, TopicKind};
use glrmon_runtime::InputItem;
use glrmon_wire::text::Escaped;
use glrmon_wire::{DecodeLimits, Sample, decode_intake, decode_samples};

use crate::{InputError, InputErrorKind};

/// Counts the bytes read, for a progress bar ([`McapInput::progress`]).
#[derive(Debug)]
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

impl<R: Seek> Seek for Counting<R> {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        // The counter shows the position (the reader reads the summary first, and
        // skips damaged parts).
        let at = self.inner.seek(pos)?;
        self.read.store(at, Ordering::Relaxed);
        Ok(at)
    }
}

/// One recorded input: its channel, what the monitor was fed, and its receive time.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedInput {
    /// The channel's name, shared by all inputs of the channel (one allocation per
    /// channel; consumers can compare pointers).
    pub channel: Arc<str>,
    /// The decoded sample, or what the intake did instead (a drop, a refusal).
    pub item: InputItem,
    /// The recorded receive time (ns since the Unix epoch).
    pub log_time_ns: u64,
}

/// Spare samples kept for decoding into.
const SPARE_SAMPLES: usize = 64;

/// A recording opened for its inputs: every channel's samples and intake events in
/// the order the monitors saw them, read with [`McapReader`] (a missing footer and
/// corrupt chunks are tolerated and reported by [`McapInput::damage_report`]).
///
/// # Examples
///
/// ```no_run
/// use glrmon_input::McapInput;
/// use glrmon_runtime::InputItem;
///
/// let mut input = McapInput::open("run.mcap".as_ref())?;
/// let config = input.recorded_config()?;
/// let mut samples = 0;
/// let mut spare = None;
/// while let Some(recorded) = input.next_input(spare.take())? {
///     if let InputItem::Sample(_) = &recorded.item {
///         samples += 1;
///     }
///     spare = Some(recorded);
/// }
/// let (lines, damaged) = input.damage_report();
/// println!("{samples} samples of {} channels", config.channels.len());
/// for line in lines {
///     eprintln!("{line}");
/// }
/// # let _ = damaged;
/// # Ok::<(), glrmon_input::InputError>(())
/// ```
pub struct McapInput {
    path: PathBuf,
    reader: McapReader<Counting<BufReader<File>>>,
    /// The recorded configuration and channels (absent in a file without them).
    pub header: Option<FileHeader>,
    /// Bytes read so far and the file's size, for a progress bar: the counter is
    /// shared, so another thread can read it while this one decodes.
    pub progress: (Arc<AtomicU64>, u64),
    pending: VecDeque<Event>,
    samples: Vec<Sample>,
    /// Samples the consumer handed back ([`McapInput::next_input`]), decoded into again.
    spare_samples: Vec<Sample>,
    queued: VecDeque<RecordedInput>,
    limits: DecodeLimits,
    /// Recorded result messages met (not inputs: skipped).
    pub results: u64,
    /// Input messages that could not be decoded (the first 100), as `topic: why`.
    pub bad_inputs: Vec<String>,
    /// The shared name of each channel met (one allocation per channel, and consumers
    /// can compare pointers), and the last one used.
    channel_names: std::collections::HashMap<String, Arc<str>>,
    last_channel: Option<Arc<str>>,
}

impl std::fmt::Debug for McapInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapInput")
            .field("path", &self.path)
            .field("header", &self.header)
            .field("messages", &self.reader.messages())
            .field("results", &self.results)
            .field("bad_inputs", &self.bad_inputs.len())
            .finish_non_exhaustive()
    }
}

impl McapInput {
    /// Opens a recording and reads up to its `glrmon` metadata (written first), which
    /// gives [`McapInput::header`].
    ///
    /// # Errors
    /// [`InputErrorKind::OpenRecording`] when the file cannot be opened,
    /// [`InputErrorKind::NotRecording`] when it is not an MCAP file,
    /// [`InputErrorKind::Read`] on an I/O error after its start.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_input::{InputErrorKind, McapInput};
    ///
    /// let err = McapInput::open("no/such/file.mcap".as_ref()).unwrap_err();
    /// assert!(matches!(err.kind(), InputErrorKind::OpenRecording(_)));
    /// assert!(err.is_invalid_input());
    /// assert!(err.to_string().starts_with("no/such/file.mcap: cannot open: "));
    /// ```
    pub fn open(path: &Path) -> Result<Self, InputError> {
        let file = File::open(path)
            .map_err(|e| InputError::new(path, InputErrorKind::OpenRecording(e)))?;
        let size = file.metadata().map_or(0, |m| m.len());
        let read = Arc::new(AtomicU64::new(0));
        let counting = Counting {
            inner: BufReader::with_capacity(1 << 16, file),
            read: read.clone(),
        };
        let mut reader = McapReader::new(counting)
            .map_err(|e| InputError::new(path, InputErrorKind::NotRecording(e)))?;
        let mut pending = VecDeque::new();
        let mut header = None;
        while let Some(event) = reader
            .next_event()
            .map_err(|e| InputError::new(path, InputErrorKind::Read(e)))?
        {
            if let Event::Metadata { name, entries } = &event
                && name == METADATA_NAME
            {
                header = Some(glrmon_record::header_from_metadata(entries));
                break;
            }
            let is_message = matches!(event, Event::Message(_));
            pending.push_back(event);
            if is_message {
                break;
            }
        }
        Ok(Self {
            path: path.to_owned(),
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

    /// The configuration recorded in the file, parsed and validated.
    ///
    /// # Errors
    /// [`InputErrorKind::NoRecordedConfig`] when the file carries none,
    /// [`InputErrorKind::RecordedConfig`] when it is invalid.
    pub fn recorded_config(&self) -> Result<glrmon_spec::Config, InputError> {
        match &self.header {
            Some(h) if !h.config.is_empty() => glrmon_spec::parse(&h.config)
                .map_err(|e| InputError::new(&self.path, InputErrorKind::RecordedConfig(e))),
            _ => Err(InputError::new(
                &self.path,
                InputErrorKind::NoRecordedConfig,
            )),
        }
    }

    /// The file's path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Sets the decoding limits for the recorded samples: the live run's
    /// (`[daemon] max_payload_bytes`), so that a replay refuses what the run refused.
    pub fn set_limits(&mut self, limits: DecodeLimits) {
        self.limits = limits;
    }

    /// The next recorded input of any channel, in file order; `None` at the end of
    /// what is readable (see [`McapInput::damage_report`] for how the file ended).
    /// `spare` is an input the consumer is done with: its sample is decoded into again
    /// (no allocation per sample, and the memory is freed by the thread that
    /// allocated it). Result messages are counted in [`McapInput::results`]; input
    /// messages that cannot be decoded are noted in [`McapInput::bad_inputs`] and
    /// skipped.
    ///
    /// # Errors
    /// [`InputErrorKind::Read`] on an I/O error (damage is not an error: it is skipped
    /// and reported).
    ///
    /// # Examples
    ///
    /// ```no_run
    /// use glrmon_input::McapInput;
    ///
    /// let mut input = McapInput::open("run.mcap".as_ref())?;
    /// let mut spare = None;
    /// while let Some(recorded) = input.next_input(spare.take())? {
    ///     println!("{} at {} ns: {:?}", recorded.channel, recorded.log_time_ns, recorded.item);
    ///     spare = Some(recorded);
    /// }
    /// # Ok::<(), glrmon_input::InputError>(())
    /// ```
    pub fn next_input(
        &mut self,
        spare: Option<RecordedInput>,
    ) -> Result<Option<RecordedInput>, InputError> {
        if let Some(RecordedInput {
            item: InputItem::Sample(s),
            ..
        }) = spare
            && self.spare_samples.len() < SPARE_SAMPLES
        {
            self.spare_samples.push(s);
        }
        loop {
            if let Some(i) = self.queued.pop_front() {
                return Ok(Some(i));
            }
            let event = match self.pending.pop_front() {
                Some(e) => e,
                None => match self
                    .reader
                    .next_event()
                    .map_err(|e| InputError::new(&self.path, InputErrorKind::Read(e)))?
                {
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

    /// Damaged parts and how the file ended, as lines for the operator (what they quote
    /// from the file escaped, [`glrmon_wire::text`]); `true` when
    /// data was lost to damage (not merely an unfinished file). Complete once
    /// [`McapInput::next_input`] returned `None`.
    #[must_use]
    pub fn damage_report(&self) -> (Vec<String>, bool) {
        let mut lines: Vec<String> = self
            .reader
            .damage()
            .iter()
            .map(|d| format!("damaged: {}", Escaped(&d.to_string())))
            .collect();
        let salvage = self.reader.salvage();
        let mut damaged = !lines.is_empty() || !self.bad_inputs.is_empty() || salvage.lost_data();
        lines.extend(
            self.bad_inputs
                .iter()
                .map(|b| format!("bad input message: {}", Escaped(b))),
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
                lines.push(format!(
                    "unreadable from byte {at}: {}; no valid chunk follows",
                    Escaped(reason)
                ));
            }
        }
        if salvage.lost_data() || salvage.summary_note.is_some() {
            lines.push(format!("salvage: {salvage}"));
        }
        (lines, damaged)
    }

    /// Messages read so far (inputs and results).
    #[must_use]
    pub fn messages(&self) -> u64 {
        self.reader.messages()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_record::{FileOptions, McapFile};
    use glrmon_wire::{IntakeEvent, encode_intake, encode_sample};
    use proptest::prelude::*;

    const CONFIG: &str = include_str!("../../../config/examples/paper2014-unstable.toml");

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("glrmon-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    /// A finished recording of `n` samples of channel `a`, an intake event after the
    /// 10th and samples of channel `b` interleaved every 7th.
    fn recording(name: &str, n: u64) -> PathBuf {
        let path = temp(name);
        let header = FileHeader {
            config: CONFIG.to_owned(),
            channels: vec!["a".into(), "b".into()],
            extra: Default::default(),
        };
        let mut file = McapFile::create(&path, FileOptions::default(), &header).unwrap();
        let mut json = Vec::new();
        for k in 0..n {
            let (channel, y) = if k % 7 == 6 {
                ("b", -1.0)
            } else {
                ("a", k as f64)
            };
            let sample = Sample {
                k: Some(k),
                t: None,
                u: vec![],
                y: vec![y, 0.5],
                p: vec![],
            };
            json.clear();
            encode_sample(channel, &sample, &mut json).unwrap();
            file.write(channel, TopicKind::Inputs, k, k, &json).unwrap();
            if k == 10 {
                json.clear();
                encode_intake("a", &IntakeEvent::Dropped { count: 3 }, &mut json).unwrap();
                file.write("a", TopicKind::Intake, k, k, &json).unwrap();
            }
        }
        file.finish().unwrap()
    }

    fn read_all(path: &Path) -> (Vec<RecordedInput>, McapInput) {
        let mut input = McapInput::open(path).unwrap();
        let mut all = Vec::new();
        while let Some(i) = input.next_input(None).unwrap() {
            all.push(i);
        }
        (all, input)
    }

    /// Every input comes back in file order with its channel and time; the recorded
    /// configuration is parsed; a finished file reports nothing.
    #[test]
    fn inputs_in_order_and_the_config() {
        let path = recording("order.mcap", 500);
        let (all, input) = read_all(&path);
        assert_eq!(all.len(), 501);
        assert_eq!(
            input.recorded_config().unwrap().channels[0].name,
            "unstable"
        );
        assert_eq!(input.damage_report(), (vec![], false));
        let mut k = 0;
        for i in &all {
            match &i.item {
                InputItem::Sample(s) => {
                    assert_eq!(s.k, Some(k));
                    assert_eq!(i.log_time_ns, k);
                    assert_eq!(&*i.channel, if k % 7 == 6 { "b" } else { "a" });
                    k += 1;
                }
                InputItem::Intake(e) => {
                    assert_eq!(*e, IntakeEvent::Dropped { count: 3 });
                    assert_eq!(k, 11);
                }
            }
        }
        // One shared name per channel.
        let a: Vec<_> = all.iter().filter(|i| &*i.channel == "a").collect();
        assert!(a.iter().all(|i| Arc::ptr_eq(&i.channel, &a[0].channel)));
        std::fs::remove_file(path).unwrap();
    }

    /// Spare inputs handed back are decoded into (same values as without).
    #[test]
    fn spares_are_reused() {
        let path = recording("spares.mcap", 300);
        let (plain, _) = read_all(&path);
        let mut input = McapInput::open(&path).unwrap();
        let mut spare = None;
        let mut again = Vec::new();
        while let Some(i) = input.next_input(spare.take()).unwrap() {
            again.push(i.clone());
            spare = Some(i);
        }
        assert_eq!(plain, again);
        std::fs::remove_file(path).unwrap();
    }

    /// A file cut short reads up to the cut and says it is unfinished, not damaged; a
    /// file without the recorded configuration, or not MCAP, is the user's error.
    #[test]
    fn truncated_and_foreign_files() {
        let path = recording("whole.mcap", 2000);
        let bytes = std::fs::read(&path).unwrap();
        let cut = temp("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() / 3]).unwrap();
        let (all, input) = read_all(&cut);
        assert!(all.len() < 2001);
        let (lines, damaged) = input.damage_report();
        assert!(!damaged);
        assert!(lines[0].starts_with("the file is unfinished"), "{lines:?}");

        let text = temp("text.mcap");
        std::fs::write(&text, "k,y0\n0,1\n").unwrap();
        let err = McapInput::open(&text).unwrap_err();
        assert!(matches!(err.kind(), InputErrorKind::NotRecording(_)));
        assert!(err.is_invalid_input());

        let bare = temp("bare.mcap");
        let file = McapFile::create(
            &bare,
            FileOptions::default(),
            &FileHeader {
                config: String::new(),
                channels: vec![],
                extra: Default::default(),
            },
        )
        .unwrap();
        file.finish().unwrap();
        let err = McapInput::open(&bare)
            .unwrap()
            .recorded_config()
            .unwrap_err();
        assert!(matches!(err.kind(), InputErrorKind::NoRecordedConfig));
        assert_eq!(
            err.to_string(),
            format!(
                "{}: no glrmon configuration is recorded in this file: give --config",
                bare.display()
            )
        );
        for p in [path, cut, text, bare] {
            std::fs::remove_file(p).unwrap();
        }
    }

    /// `.mcap` in any case and a recording being written are MCAP; the rest is CSV.
    #[test]
    fn mcap_names() {}

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// A recording with arbitrary bytes overwritten, or cut anywhere, never panics:
        /// the reading ends with inputs that decode, and what was lost is reported.
        #[test]
        fn damaged_recordings_never_panic(
            at in 0.0..1.0f64,
            noise in proptest::collection::vec(any::<u8>(), 1..512),
            cut in any::<bool>(),
        ) {
            static WHOLE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
            let whole = WHOLE.get_or_init(|| std::fs::read(recording("fuzz-src.mcap", 3000)).unwrap());
            let mut bytes = whole.clone();
            let start = ((bytes.len() as f64) * at) as usize;
            if cut {
                bytes.truncate(start);
            } else {
                for (b, n) in bytes[start..].iter_mut().zip(&noise) {
                    *b ^= n;
                }
            }
            let path = temp(&format!("fuzz-{}.mcap", std::thread::current().name().unwrap_or("t").replace(':', "_")));
            std::fs::write(&path, &bytes).unwrap();
            match McapInput::open(&path) {
                Err(e) => prop_assert!(e.is_invalid_input() || matches!(e.kind(), InputErrorKind::Read(_))),
                Ok(mut input) => {
                    let mut n = 0;
                    while let Some(i) = input.next_input(None).unwrap() {
                        n += 1;
                        if let InputItem::Sample(s) = &i.item {
                            prop_assert_eq!(s.y.len(), 2);
                        }
                    }
                    prop_assert!(n <= 3001);
                    let _ = input.damage_report();
                }
            }
            std::fs::remove_file(&path).unwrap();
        }
    }
}
