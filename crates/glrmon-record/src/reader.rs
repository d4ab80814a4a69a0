//! A streaming MCAP reader that tolerates what crashes and disks do to files.
//!
//! The file is walked record by record (opcode, length, body) from the start, so memory
//! stays flat in the file size (one chunk at a time); the footer and the summary are
//! read first when the file has them, and used only to salvage:
//! - a file cut short (`kill -9`, power loss) reads up to its last complete chunk and
//!   reports [`ReadEnd::Truncated`]: nothing was lost but the tail being written;
//! - a chunk whose data is corrupt (bad CRC, undecodable zstd) but whose framing is
//!   consistent is skipped whole and reported as [`Damage`]; reading resumes at the
//!   next record, whose position the chunk's own length gives;
//! - any other damaged record (an invalid opcode, a length beyond the end of the file
//!   or absurd, a chunk whose fields do not add up) is skipped by *resynchronising*:
//!   at the next chunk the summary's chunk indexes list after the damaged position when
//!   the file has a valid summary, otherwise at the next byte `0x06` that starts a
//!   plausible chunk record (length within the file, fields adding up to the length, a
//!   known compression) which decompresses to its recorded size and CRC. The skipped
//!   bytes are one [`Damage`] with the time range of the messages lost
//!   ([`Lost`]): exact from the index, else bounded by the neighbouring chunks.
//!
//! Only when nothing valid follows the damage and the file has no footer is the rest
//! taken for the unfinished tail of a killed recorder (a record running past the end,
//! mcap's open-chunk placeholder length, or zeroes to the end); otherwise the read ends
//! [`ReadEnd::Unreadable`] with the region reported as damage. No allocation follows a
//! length read from the file before it was checked against what remains of the file.

use std::collections::HashMap;
use std::io::{self, Read, Seek, SeekFrom};
use std::sync::Arc;

use mcap::records::{Record as McapRecord, op};

use crate::schema::TopicKind;

/// The largest record accepted (chunks are about 1 MiB; a larger length is damage).
const MAX_RECORD_BYTES: u64 = 1 << 30;

/// The largest summary section read (a day of 1 MiB chunks indexes in a few MiB).
const MAX_SUMMARY_BYTES: u64 = 256 << 20;

/// Bytes of a footer record: opcode, length, summary start, summary offset start, CRC.
const FOOTER_RECORD_BYTES: u64 = 1 + 8 + 8 + 8 + 4;

/// The longest compression name a plausible chunk has.
const MAX_COMPRESSION_NAME: usize = 16;

/// Bytes of a chunk record up to its records length, with the longest compression name.
const CHUNK_HEAD_BYTES: usize = 9 + 8 + 8 + 8 + 4 + 4 + MAX_COMPRESSION_NAME + 8;

/// The window the resynchronisation scan reads at a time.
const SCAN_WINDOW: usize = 1 << 20;

/// Errors that stop a read before any data: not an MCAP file, or unreadable.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file does not start with the MCAP magic.
    #[error("not an MCAP file: the first 8 bytes are not the MCAP magic")]
    NotMcap,
    /// An I/O error.
    #[error("cannot read: {0}")]
    Io(#[from] io::Error),
}

/// An MCAP channel: a topic and, for glrmon's topics, its channel and kind.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topic {
    /// The MCAP channel id.
    pub id: u16,
    /// The topic name.
    pub topic: String,
    /// The glrmon channel name (metadata `channel`).
    pub channel: Option<String>,
    /// The glrmon kind (metadata `kind`).
    pub kind: Option<TopicKind>,
    /// The schema name.
    pub schema: String,
    /// The schema encoding (`jsonschema` for glrmon's topics).
    pub schema_encoding: String,
    /// The schema itself (a JSON Schema for glrmon's topics).
    pub schema_data: Arc<[u8]>,
    /// The message encoding.
    pub message_encoding: String,
}

/// A message of the file.
#[derive(Debug, Clone)]
pub struct Message {
    /// Its topic.
    pub topic: Arc<Topic>,
    /// MCAP log time (ns since the Unix epoch; glrmon: receive time).
    pub log_time: u64,
    /// MCAP publish time (glrmon: the sample's own time where it has one).
    pub publish_time: u64,
    /// The message (JSON for glrmon topics).
    pub data: Vec<u8>,
}

/// What the reader meets, in file order.
#[derive(Debug, Clone)]
pub enum Event {
    /// A metadata record (glrmon writes `glrmon` with the configuration first).
    Metadata {
        /// Its name.
        name: String,
        /// Its entries.
        entries: std::collections::BTreeMap<String, String>,
    },
    /// A message.
    Message(Message),
}

/// What a damaged region cost, as far as the file tells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lost {
    /// From the summary's chunk indexes: the chunks that started in the region and the
    /// log times (ns) of their first and last messages (`None` when none of them held
    /// a message: no message was lost).
    Indexed {
        /// Indexed chunks lost.
        chunks: u64,
        /// First and last log time (ns) of their messages.
        time_range: Option<(u64, u64)>,
    },
    /// Without an index: the messages lost were logged after the last message read
    /// before the region and before the first one read after it (`None`: the start or
    /// the end of the file).
    Between {
        /// Log time (ns) of the last message of the chunk before the region.
        after: Option<u64>,
        /// Log time (ns) of the first message of the chunk after the region.
        before: Option<u64>,
    },
}

impl std::fmt::Display for Lost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let t = |t: Option<u64>, none: &str| t.map_or_else(|| none.to_owned(), |t| format!("{t}"));
        match self {
            Lost::Indexed {
                chunks: 0,
                time_range: _,
            } => write!(f, "no indexed chunk lost"),
            Lost::Indexed {
                chunks,
                time_range: Some((a, b)),
            } => write!(
                f,
                "{chunks} indexed chunk(s) lost: messages logged {a}..={b} ns"
            ),
            Lost::Indexed { chunks, .. } => {
                write!(f, "{chunks} indexed chunk(s) without messages lost")
            }
            Lost::Between { after, before } => write!(
                f,
                "messages lost logged between {} and {} ns",
                t(*after, "the start"),
                t(*before, "the end")
            ),
        }
    }
}

/// A damaged part of a file that was skipped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// Byte offset of the damaged record.
    pub offset: u64,
    /// Bytes skipped from it (to where reading resumed, or to the end of the file).
    pub length: u64,
    /// What is wrong.
    pub reason: String,
    /// What it cost (`None` for a damaged record outside any chunk, such as a bad
    /// channel record, which holds no message).
    pub lost: Option<Lost>,
}

impl std::fmt::Display for Damage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "bytes {}..{}: {}",
            self.offset,
            self.offset.saturating_add(self.length),
            self.reason
        )?;
        if let Some(lost) = &self.lost {
            write!(f, "; {lost}")?;
        }
        Ok(())
    }
}

/// How the read ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReadEnd {
    /// Not yet at the end.
    Reading,
    /// A footer and the closing magic: the file was finished.
    Finished,
    /// The data section ended without a footer: the recording was not finished
    /// (crash, `kill -9`); `partial` bytes of an incomplete last record were ignored.
    /// Nothing valid follows them: no data was lost but the tail being written.
    Truncated {
        /// Offset where the readable part ends.
        at: u64,
        /// Bytes of an incomplete record after it.
        partial: u64,
    },
    /// A damaged record with nothing valid after it (no chunk to resynchronise on):
    /// the rest of the file is unreadable, and reported as [`Damage`] too.
    Unreadable {
        /// Offset of the record.
        at: u64,
        /// Why.
        reason: String,
    },
}

/// The salvage totals of a read: the damage, what the file says it held, what was read.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Salvage {
    /// Damaged regions skipped.
    pub regions: usize,
    /// Bytes skipped in them.
    pub bytes_skipped: u64,
    /// Messages read.
    pub messages: u64,
    /// Messages the summary's statistics count (a finished file with a summary).
    pub messages_known: Option<u64>,
    /// Chunks read whole.
    pub chunks: u64,
    /// Chunks the summary indexes.
    pub chunks_known: Option<u64>,
    /// Whether a valid summary (chunk indexes) guided the resynchronisation.
    pub indexed: bool,
    /// Messages skipped because their MCAP channel record was lost.
    pub unknown_channel: u64,
    /// Why a summary the footer points to was not used (damaged), if so.
    pub summary_note: Option<String>,
}

impl Salvage {
    /// Whether data was lost or may have been: a damaged region, or messages of a lost
    /// channel. An unfinished file alone ([`ReadEnd::Truncated`]) is not.
    #[must_use]
    pub fn lost_data(&self) -> bool {
        self.regions > 0 || self.unknown_channel > 0
    }
}

impl std::fmt::Display for Salvage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} damaged region(s), {} bytes skipped; {} message(s) recovered",
            self.regions, self.bytes_skipped, self.messages
        )?;
        if let Some(known) = self.messages_known {
            write!(
                f,
                " of {known} (the summary's statistics), {} lost",
                known.saturating_sub(self.messages)
            )?;
        }
        write!(f, "; {} chunk(s) read", self.chunks)?;
        if let Some(known) = self.chunks_known {
            write!(f, " of {known} indexed")?;
        }
        if self.unknown_channel > 0 {
            write!(
                f,
                "; {} message(s) of a lost channel record skipped",
                self.unknown_channel
            )?;
        }
        if let Some(note) = &self.summary_note {
            write!(f, "; {note}")?;
        }
        Ok(())
    }
}

/// A chunk as the summary indexes it.
#[derive(Debug, Clone, Copy)]
struct IndexedChunk {
    start: u64,
    message_start_time: u64,
    message_end_time: u64,
    /// Whether it holds messages (it has message indexes).
    has_messages: bool,
}

/// What the footer and the summary tell, read before the data.
#[derive(Debug, Default)]
struct Summary {
    /// The file ends with a footer and the magic: it was finished.
    footer: bool,
    /// The summary's chunk indexes, by offset.
    chunks: Vec<IndexedChunk>,
    /// The statistics' message count.
    messages: Option<u64>,
    /// Where the summary starts (the end of the data section), when it is used.
    start: Option<u64>,
    /// Schema and channel records of the summary.
    records: Vec<McapRecord<'static>>,
    /// Why the summary was not used.
    note: Option<String>,
}

/// Streams the events of an MCAP file; see the module documentation.
#[derive(Debug)]
pub struct McapReader<R> {
    input: R,
    offset: u64,
    size: u64,
    body: Vec<u8>,
    topics: HashMap<u16, Arc<Topic>>,
    schemas: HashMap<u16, (String, String, Arc<[u8]>)>,
    pending: std::collections::VecDeque<Event>,
    /// The decompressed records of the current chunk (reused).
    chunk_data: Vec<u8>,
    damage: Vec<Damage>,
    end: ReadEnd,
    chunks: u64,
    messages: u64,
    summary: Summary,
    /// Log time of the last message of the last chunk read.
    last_time: Option<u64>,
    /// A damage without index whose `before` bound the next chunk read gives.
    awaiting_next: Option<usize>,
    unknown_channel: u64,
}

impl<R: Read + Seek> McapReader<R> {
    /// Checks the magic, reads the footer and the summary when the file has them, and
    /// prepares to read from the start.
    ///
    /// # Errors
    /// [`ReadError::NotMcap`] or an I/O error.
    pub fn new(mut input: R) -> Result<Self, ReadError> {
        let size = input.seek(SeekFrom::End(0))?;
        input.seek(SeekFrom::Start(0))?;
        let mut magic = [0u8; 8];
        if read_full(&mut input, &mut magic)? < 8 || magic != mcap::MAGIC {
            return Err(ReadError::NotMcap);
        }
        let summary = read_summary(&mut input, size)?;
        input.seek(SeekFrom::Start(8))?;
        let mut reader = Self {
            input,
            offset: 8,
            size,
            body: Vec::new(),
            topics: HashMap::new(),
            schemas: HashMap::new(),
            pending: std::collections::VecDeque::new(),
            chunk_data: Vec::new(),
            damage: Vec::new(),
            end: ReadEnd::Reading,
            chunks: 0,
            messages: 0,
            summary,
            last_time: None,
            awaiting_next: None,
            unknown_channel: 0,
        };
        // The summary repeats the schemas and channels: a message stays readable when
        // the chunk that defined its channel is lost.
        for r in std::mem::take(&mut reader.summary.records) {
            reader.accept(r);
        }
        Ok(reader)
    }

    /// The next event, `None` at the end (see [`McapReader::end`] for how it ended).
    ///
    /// # Errors
    /// An I/O error of the underlying reader (not damage: damage is skipped and
    /// reported by [`McapReader::damage`]).
    pub fn next_event(&mut self) -> Result<Option<Event>, io::Error> {
        loop {
            if let Some(e) = self.pending.pop_front() {
                if let Event::Message(_) = e {
                    self.messages += 1;
                }
                return Ok(Some(e));
            }
            if self.end != ReadEnd::Reading {
                return Ok(None);
            }
            self.read_record()?;
        }
    }

    /// The damaged parts skipped so far.
    #[must_use]
    pub fn damage(&self) -> &[Damage] {
        &self.damage
    }

    /// How the read ended ([`ReadEnd::Reading`] before the end).
    #[must_use]
    pub fn end(&self) -> &ReadEnd {
        &self.end
    }

    /// Chunks read whole so far.
    #[must_use]
    pub fn chunks(&self) -> u64 {
        self.chunks
    }

    /// Messages returned so far.
    #[must_use]
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// The salvage totals so far (complete once [`McapReader::next_event`] returned
    /// `None`).
    #[must_use]
    pub fn salvage(&self) -> Salvage {
        Salvage {
            regions: self.damage.iter().filter(|d| d.length > 0).count(),
            bytes_skipped: self.damage.iter().map(|d| d.length).sum(),
            messages: self.messages,
            messages_known: self.summary.messages,
            chunks: self.chunks,
            chunks_known: (!self.summary.chunks.is_empty())
                .then_some(self.summary.chunks.len() as u64),
            indexed: !self.summary.chunks.is_empty(),
            unknown_channel: self.unknown_channel,
            summary_note: self.summary.note.clone(),
        }
    }

    /// The topics seen so far, by MCAP channel id.
    #[must_use]
    pub fn topics(&self) -> Vec<Arc<Topic>> {
        let mut t: Vec<_> = self.topics.values().cloned().collect();
        t.sort_by_key(|t| t.id);
        t
    }

    fn read_record(&mut self) -> Result<(), io::Error> {
        let start = self.offset;
        let mut head = [0u8; 9];
        let got = read_full(&mut self.input, &mut head)?;
        if got < 9 {
            if self.summary.footer && got > 0 {
                return self.resync(
                    start,
                    "a record header is cut by the end of the file".into(),
                    true,
                );
            }
            self.end = ReadEnd::Truncated {
                at: start,
                partial: got as u64,
            };
            return Ok(());
        }
        let opcode = head[0];
        let mut len_bytes = [0u8; 8];
        len_bytes.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(len_bytes);
        let remaining = self.size.saturating_sub(start + 9);
        if opcode == op::CHUNK && len == u64::MAX {
            // mcap's writer puts this placeholder while a chunk is open and writes the
            // length when the chunk is finished: the recorder stopped inside a chunk
            // (unless a valid chunk follows: then it is damage).
            return self.resync(
                start,
                "a chunk without its length (placeholder)".into(),
                true,
            );
        }
        if opcode == 0 || opcode > op::DATA_END {
            return self.resync(start, format!("invalid opcode {opcode:#04x}"), false);
        }
        if opcode != op::CHUNK
            && self
                .summary
                .chunks
                .binary_search_by_key(&start, |c| c.start)
                .is_ok()
        {
            return self.resync(
                start,
                format!("a record of opcode {opcode:#04x} where the index lists a chunk"),
                false,
            );
        }
        if len > MAX_RECORD_BYTES || len > remaining {
            return self.resync(
                start,
                format!(
                    "record (opcode {opcode:#04x}) claims {len} bytes, {remaining} remain in \
                     the file"
                ),
                len <= MAX_RECORD_BYTES,
            );
        }
        if opcode == op::FOOTER && !(len == 20 && start + 9 + 20 + 8 == self.size) {
            // A footer ends the read: one that is not the file's own is damage (a
            // chunk's opcode 0x06 with a bit flipped, say), not the end.
            return self.resync(
                start,
                "a footer record that is not at the end of the file".into(),
                false,
            );
        }
        let len_usize = usize::try_from(len).unwrap_or(usize::MAX);
        self.body.clear();
        self.body.resize(len_usize, 0);
        let got = read_full(&mut self.input, &mut self.body)?;
        if got < len_usize {
            // The file shrank while being read.
            self.end = ReadEnd::Truncated {
                at: start,
                partial: 9 + got as u64,
            };
            return Ok(());
        }
        self.offset = start + 9 + len;
        match opcode {
            op::FOOTER => {
                self.end = ReadEnd::Finished;
            }
            op::CHUNK => return self.read_chunk(start, len),
            op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA => {
                match parse_record(opcode, &self.body) {
                    Ok(r) => {
                        let r = r.into_owned();
                        self.accept(r);
                    }
                    Err(e) => self.invalid_record(start, len, opcode, &e.to_string()),
                }
            }
            // Header, indexes, statistics, summary offsets, data end, attachments:
            // nothing a replay needs, but parsed: a chunk whose opcode was damaged into
            // one of these must not vanish unreported.
            _ => {
                if let Err(e) = parse_record(opcode, &self.body) {
                    self.invalid_record(start, len, opcode, &e.to_string());
                } else if let Some(why) = misframed(opcode, &self.body) {
                    self.invalid_record(start, len, opcode, &why);
                }
            }
        }
        Ok(())
    }

    /// Reports a record whose framing is sound but whose body does not parse; reading
    /// goes on after it.
    fn invalid_record(&mut self, start: u64, len: u64, opcode: u8, e: &str) {
        let lost = self.lost_in(start, start + 9 + len);
        self.damage.push(Damage {
            offset: start,
            length: 9 + len,
            reason: format!("record (opcode {opcode:#04x}) is invalid: {e}"),
            lost: Some(lost),
        });
        self.note_awaiting();
    }

    fn read_chunk(&mut self, start: u64, len: u64) -> Result<(), io::Error> {
        let body = std::mem::take(&mut self.body);
        let result = parse_chunk(&body, &mut self.chunk_data);
        self.body = body;
        match result {
            Ok((times, records)) => {
                self.chunks += 1;
                if let Some(i) = self.awaiting_next.take()
                    && let Some(Lost::Between { before, .. }) = &mut self.damage[i].lost
                {
                    *before = Some(times.0);
                }
                self.last_time = Some(times.1);
                for r in records {
                    self.accept(r);
                }
                Ok(())
            }
            Err(ChunkError::Data(reason)) => {
                // The framing adds up: the chunk's own length gives the next record.
                let lost = self.lost_in(start, start + 9 + len);
                self.damage.push(Damage {
                    offset: start,
                    length: 9 + len,
                    reason: format!("chunk skipped: {reason}"),
                    lost: Some(lost),
                });
                self.note_awaiting();
                Ok(())
            }
            Err(ChunkError::Framing(reason)) => {
                self.resync(start, format!("chunk skipped: {reason}"), false)
            }
        }
    }

    /// Remembers the last damage as awaiting its `before` bound from the next chunk.
    fn note_awaiting(&mut self) {
        if let Some(Damage {
            lost: Some(Lost::Between { .. }),
            ..
        }) = self.damage.last()
        {
            self.awaiting_next = Some(self.damage.len() - 1);
        }
    }

    /// What the region `from..to` cost: the indexed chunks starting in it, or the
    /// bounds the neighbouring chunks give.
    fn lost_in(&self, from: u64, to: u64) -> Lost {
        if self.summary.chunks.is_empty() {
            return Lost::Between {
                after: self.last_time,
                before: None,
            };
        }
        let lost: Vec<&IndexedChunk> = self
            .summary
            .chunks
            .iter()
            .filter(|c| c.start >= from && c.start < to)
            .collect();
        let with_messages = || lost.iter().filter(|c| c.has_messages);
        Lost::Indexed {
            chunks: lost.len() as u64,
            time_range: with_messages()
                .map(|c| c.message_start_time)
                .min()
                .zip(with_messages().map(|c| c.message_end_time).max()),
        }
    }

    /// Skips the damaged record at `start`: reading resumes at the next indexed chunk
    /// after it, or the next valid chunk a scan finds; with neither, the read ends.
    fn resync(&mut self, start: u64, reason: String, past_end: bool) -> Result<(), io::Error> {
        // After the last indexed chunk the summary's own start (data end, summary,
        // footer) is the next sound record.
        let indexed = self
            .summary
            .chunks
            .iter()
            .map(|c| c.start)
            .chain(self.summary.start)
            .find(|&c| c > start && c < self.size);
        let target = match indexed {
            Some(t) => Some(t),
            None => self.scan(start + 1)?,
        };
        match target {
            Some(t) => {
                let lost = self.lost_in(start, t);
                self.damage.push(Damage {
                    offset: start,
                    length: t - start,
                    reason,
                    lost: Some(lost),
                });
                self.note_awaiting();
                self.input.seek(SeekFrom::Start(t))?;
                self.offset = t;
            }
            None if !self.summary.footer && (past_end || self.zeroes_from(start)?) => {
                self.end = ReadEnd::Truncated {
                    at: start,
                    partial: self.size.saturating_sub(start),
                };
            }
            None => {
                let lost = self.lost_in(start, self.size);
                self.damage.push(Damage {
                    offset: start,
                    length: self.size.saturating_sub(start),
                    reason: reason.clone(),
                    lost: Some(lost),
                });
                self.end = ReadEnd::Unreadable { at: start, reason };
            }
        }
        Ok(())
    }

    /// Whether the bytes from `start` to the end are zeroes (a file system's
    /// preallocated tail after a crash).
    fn zeroes_from(&mut self, start: u64) -> Result<bool, io::Error> {
        self.input.seek(SeekFrom::Start(start))?;
        let mut buf = vec![0u8; SCAN_WINDOW];
        loop {
            let got = read_full(&mut self.input, &mut buf)?;
            if got == 0 {
                return Ok(true);
            }
            if buf[..got].iter().any(|&b| b != 0) {
                return Ok(false);
            }
        }
    }

    /// The offset of the next valid chunk record at or after `from`: a byte `0x06`
    /// starting a plausible chunk header ([`plausible_chunk`]) whose data decompresses
    /// to its recorded size and CRC. Reads the file once, a window at a time.
    fn scan(&mut self, from: u64) -> Result<Option<u64>, io::Error> {
        let mut buf = vec![0u8; SCAN_WINDOW];
        let mut pos = from;
        while pos + 9 < self.size {
            self.input.seek(SeekFrom::Start(pos))?;
            let got = read_full(&mut self.input, &mut buf)?;
            if got == 0 {
                break;
            }
            let window_end = pos + got as u64;
            let mut next = window_end;
            let mut i = 0;
            while let Some(j) = buf[i..got].iter().position(|&b| b == op::CHUNK) {
                let c = i + j;
                let at = pos + c as u64;
                if got - c < CHUNK_HEAD_BYTES && window_end < self.size && c > 0 {
                    next = at; // read a window starting here for the whole header
                    break;
                }
                if plausible_chunk(&buf[c..got], at, self.size) && self.valid_chunk_at(at)? {
                    return Ok(Some(at));
                }
                i = c + 1;
            }
            pos = next;
        }
        Ok(None)
    }

    /// Whether a whole valid chunk record starts at `at` (its length already checked
    /// against the file by [`plausible_chunk`]).
    fn valid_chunk_at(&mut self, at: u64) -> Result<bool, io::Error> {
        self.input.seek(SeekFrom::Start(at + 1))?;
        let mut len = [0u8; 8];
        if read_full(&mut self.input, &mut len)? < 8 {
            return Ok(false);
        }
        let len = u64::from_le_bytes(len);
        let Ok(len) = usize::try_from(len) else {
            return Ok(false);
        };
        let mut body = std::mem::take(&mut self.body);
        body.clear();
        body.resize(len, 0);
        let ok = read_full(&mut self.input, &mut body)? == len
            && parse_chunk(&body, &mut self.chunk_data).is_ok();
        self.body = body;
        Ok(ok)
    }
}

impl<R> McapReader<R> {
    fn accept(&mut self, record: McapRecord<'static>) {
        match record {
            McapRecord::Schema { header, data } => {
                self.schemas
                    .insert(header.id, (header.name, header.encoding, Arc::from(&*data)));
            }
            McapRecord::Channel(c) => {
                let (schema, schema_encoding, schema_data) =
                    self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                let topic = Topic {
                    id: c.id,
                    channel: c.metadata.get("channel").cloned(),
                    kind: c.metadata.get("kind").and_then(|k| TopicKind::parse(k)),
                    schema,
                    schema_encoding,
                    schema_data,
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                };
                self.topics.insert(c.id, Arc::new(topic));
            }
            McapRecord::Message { header, data } => {
                let Some(topic) = self.topics.get(&header.channel_id) else {
                    self.unknown_channel += 1;
                    return;
                };
                self.pending.push_back(Event::Message(Message {
                    topic: topic.clone(),
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: data.into_owned(),
                }));
            }
            McapRecord::Metadata(m) => self.pending.push_back(Event::Metadata {
                name: m.name,
                entries: m.metadata,
            }),
            _ => {}
        }
    }
}

/// The footer and the summary of a file, when it has them and they are sound: the
/// summary's CRC (when recorded) is checked, every record's length is checked against
/// what remains before mcap parses it, and chunk indexes pointing outside the data
/// section are dropped.
fn read_summary(input: &mut (impl Read + Seek), size: u64) -> Result<Summary, io::Error> {
    let mut s = Summary::default();
    let Some(footer_at) = size.checked_sub(FOOTER_RECORD_BYTES + 8) else {
        return Ok(s);
    };
    if footer_at < 8 {
        return Ok(s);
    }
    input.seek(SeekFrom::Start(footer_at))?;
    let mut tail = [0u8; FOOTER_RECORD_BYTES as usize + 8];
    if read_full(input, &mut tail)? < tail.len()
        || tail[0] != op::FOOTER
        || tail[1..9] != 20u64.to_le_bytes()
        || tail[29..] != mcap::MAGIC[..]
    {
        return Ok(s);
    }
    s.footer = true;
    let u64_at = |i: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&tail[i..i + 8]);
        u64::from_le_bytes(b)
    };
    let summary_start = u64_at(9);
    let crc = u32::from_le_bytes([tail[25], tail[26], tail[27], tail[28]]);
    if summary_start == 0 {
        return Ok(s);
    }
    if summary_start < 8
        || summary_start > footer_at
        || footer_at - summary_start > MAX_SUMMARY_BYTES
    {
        s.note = Some(format!(
            "the footer's summary start {summary_start} is outside the file: index not used"
        ));
        return Ok(s);
    }
    input.seek(SeekFrom::Start(summary_start))?;
    let mut bytes = vec![0u8; usize::try_from(footer_at - summary_start).unwrap_or(0)];
    if read_full(input, &mut bytes)? < bytes.len() {
        return Ok(s);
    }
    if crc != 0 {
        let mut h = crc32fast::Hasher::new();
        h.update(&bytes);
        h.update(&tail[..25]);
        if h.finalize() != crc {
            s.note = Some("the summary is damaged (CRC): index not used".into());
            return Ok(s);
        }
    }
    let mut at = 0usize;
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        let mut len = [0u8; 8];
        len.copy_from_slice(&bytes[at + 1..at + 9]);
        let Some(end) = usize::try_from(u64::from_le_bytes(len))
            .ok()
            .and_then(|l| (at + 9).checked_add(l))
            .filter(|&e| e <= bytes.len())
        else {
            break;
        };
        match parse_record(opcode, &bytes[at + 9..end]).map(McapRecord::into_owned) {
            Ok(McapRecord::ChunkIndex(c)) => {
                if c.chunk_start_offset >= 8
                    && c.chunk_start_offset < summary_start
                    && c.message_start_time <= c.message_end_time
                {
                    s.chunks.push(IndexedChunk {
                        start: c.chunk_start_offset,
                        message_start_time: c.message_start_time,
                        message_end_time: c.message_end_time,
                        has_messages: !c.message_index_offsets.is_empty(),
                    });
                }
            }
            Ok(McapRecord::Statistics(st)) => s.messages = Some(st.message_count),
            Ok(r @ (McapRecord::Schema { .. } | McapRecord::Channel(_))) => s.records.push(r),
            Ok(_) => {}
            Err(_) => break,
        }
        at = end;
    }
    s.start = Some(summary_start);
    s.chunks.sort_by_key(|c| c.start);
    s.chunks.dedup_by_key(|c| c.start);
    Ok(s)
}

/// Why a record between chunks that mcap parsed does not fill its length, if it does
/// not: mcap ignores trailing bytes, so a chunk whose opcode was damaged into a message
/// index, a summary offset or a data end would otherwise be skipped unreported.
fn misframed(opcode: u8, body: &[u8]) -> Option<String> {
    let expected = match opcode {
        op::MESSAGE_INDEX => body
            .get(2..6)
            .map(|n| 6 + u64::from(u32::from_le_bytes([n[0], n[1], n[2], n[3]]))),
        op::SUMMARY_OFFSET => Some(1 + 8 + 8),
        op::DATA_END => Some(4),
        _ => return None,
    };
    (expected != Some(body.len() as u64)).then(|| {
        format!(
            "its fields take {} bytes, its length says {}",
            expected.map_or_else(|| "?".to_owned(), |e| e.to_string()),
            body.len()
        )
    })
}

/// Whether `h` (from a byte `0x06` at file offset `at`) starts a plausible chunk
/// record: its length within the file and the limit, its fields adding up to that
/// length, a known compression, ordered message times, a bounded uncompressed size.
fn plausible_chunk(h: &[u8], at: u64, size: u64) -> bool {
    let u64_at = |i: usize| -> Option<u64> {
        h.get(i..i + 8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
    };
    let (Some(len), Some(t0), Some(t1), Some(usize_), Some(clen)) = (
        u64_at(1),
        u64_at(9),
        u64_at(17),
        u64_at(25),
        h.get(37..41)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap_or([0; 4]))),
    ) else {
        return false;
    };
    let clen = clen as usize;
    if len > MAX_RECORD_BYTES
        || at.saturating_add(9).saturating_add(len) > size
        || t0 > t1
        || usize_ > MAX_RECORD_BYTES
        || clen > MAX_COMPRESSION_NAME
    {
        return false;
    }
    let Some(compression) = h.get(41..41 + clen) else {
        return false;
    };
    if compression != b"zstd" && !compression.is_empty() {
        return false;
    }
    let Some(records_len) = u64_at(41 + clen) else {
        return false;
    };
    (8 + 8 + 8 + 4 + 4 + clen as u64 + 8).checked_add(records_len) == Some(len)
        && (!compression.is_empty() || records_len == usize_)
}

/// Why a chunk could not be read.
enum ChunkError {
    /// Its fields do not add up: its length cannot be trusted.
    Framing(String),
    /// Its framing is sound but its data is not (CRC, zstd, records).
    Data(String),
}

/// The message times and the records of a chunk, all or nothing: the data is
/// decompressed with its declared size as a bound, checked against its CRC, and every
/// record's length is checked against what remains before mcap parses it (a corrupt
/// length must not become an allocation of exabytes).
fn parse_chunk(
    body: &[u8],
    scratch: &mut Vec<u8>,
) -> Result<((u64, u64), Vec<McapRecord<'static>>), ChunkError> {
    let McapRecord::Chunk { header, data } =
        parse_record(op::CHUNK, body).map_err(|e| ChunkError::Framing(e.to_string()))?
    else {
        return Err(ChunkError::Framing("not a chunk".into()));
    };
    // mcap ignores bytes after the data: here they mean a length that does not add up.
    let framed = 8 + 8 + 8 + 4 + 4 + header.compression.len() as u64 + 8 + data.len() as u64;
    if framed != body.len() as u64 {
        return Err(ChunkError::Framing(format!(
            "its fields take {framed} bytes, its length says {}",
            body.len()
        )));
    }
    let bad = ChunkError::Data;
    if header.uncompressed_size > MAX_RECORD_BYTES {
        return Err(bad(format!(
            "declares {} uncompressed bytes",
            header.uncompressed_size
        )));
    }
    let size = usize::try_from(header.uncompressed_size).map_err(|e| bad(e.to_string()))?;
    let records: &[u8] = match header.compression.as_str() {
        "" => &data,
        "zstd" => {
            scratch.clear();
            scratch.reserve(size);
            let mut decoder = zstd::stream::read::Decoder::with_buffer(&data[..])
                .map_err(|e| bad(e.to_string()))?;
            let got = std::io::Read::read_to_end(
                &mut std::io::Read::take(&mut decoder, header.uncompressed_size + 1),
                scratch,
            )
            .map_err(|e| bad(format!("zstd: {e}")))?;
            if got != size {
                return Err(bad(format!(
                    "decompresses to {got} bytes, the header says {size}"
                )));
            }
            scratch
        }
        other => return Err(bad(format!("unsupported compression \"{other}\""))),
    };
    if records.len() != size {
        return Err(bad(format!(
            "holds {} bytes, the header says {size}",
            records.len()
        )));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(records);
        if crc != header.uncompressed_crc {
            return Err(bad(format!(
                "CRC {crc:#010x} differs from the recorded {:#010x}",
                header.uncompressed_crc
            )));
        }
    }
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < records.len() {
        let Some(head) = records.get(at..at + 9) else {
            return Err(bad(format!("a record header is cut at byte {at}")));
        };
        let opcode = head[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(len);
        let end = usize::try_from(len)
            .ok()
            .and_then(|l| (at + 9).checked_add(l))
            .filter(|&e| e <= records.len())
            .ok_or_else(|| bad(format!("a record at byte {at} claims {len} bytes")))?;
        let record = parse_record(opcode, &records[at + 9..end])
            .map_err(|e| bad(format!("record at byte {at}: {e}")))?;
        out.push(record.into_owned());
        at = end;
    }
    Ok(((header.message_start_time, header.message_end_time), out))
}

/// Reads until `buf` is full or the input ends; returns the bytes read.
fn read_full(input: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match input.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// `mcap::parse_record` of a record body whose length prefixes have first been checked
/// to fit in it. The mcap crate reserves a string's or byte array's claimed length
/// before reading it, so a damaged prefix in a 100-byte record asked for 4 GiB (found
/// by `make fuzz FUZZ_TARGET=mcap`, fuzz/regressions/mcap/).
fn parse_record(opcode: u8, body: &[u8]) -> Result<McapRecord<'_>, String> {
    lengths_fit(opcode, body)?;
    mcap::parse_record(opcode, body).map_err(|e| e.to_string())
}

/// A field of a record's layout (MCAP specification, "Records").
#[derive(Clone, Copy)]
enum Field {
    /// So many fixed bytes.
    Fixed(usize),
    /// A u32 length, then that many bytes (string, byte array, map or array).
    Prefixed32,
    /// A map of strings to strings: a u32 byte length, then (string, string) pairs.
    StringMap,
    /// A u32 byte length, then entries of this fixed size (an integer map or an array of
    /// fixed records): mcap reads whole entries until the length is used up, so a length
    /// that is not a multiple would make it read past the field and misread the rest.
    Entries(usize),
    /// A u64 length, then that many bytes.
    Prefixed64,
}

/// Checks that every length prefix of the record's layout fits in `body`.
fn lengths_fit(opcode: u8, body: &[u8]) -> Result<(), String> {
    use Field::{Entries, Fixed, Prefixed32, Prefixed64, StringMap};
    let layout: &[Field] = match opcode {
        op::HEADER => &[Prefixed32, Prefixed32],
        op::SCHEMA => &[Fixed(2), Prefixed32, Prefixed32, Prefixed32],
        op::CHANNEL => &[Fixed(4), Prefixed32, Prefixed32, StringMap],
        op::CHUNK => &[Fixed(28), Prefixed32, Prefixed64],
        op::MESSAGE_INDEX => &[Fixed(2), Entries(16)],
        op::CHUNK_INDEX => &[Fixed(32), Entries(10), Fixed(8), Prefixed32, Fixed(16)],
        op::ATTACHMENT => &[Fixed(16), Prefixed32, Prefixed32, Prefixed64, Fixed(4)],
        op::ATTACHMENT_INDEX => &[Fixed(40), Prefixed32, Prefixed32],
        op::STATISTICS => &[Fixed(42), Entries(10)],
        op::METADATA => &[Prefixed32, StringMap],
        op::METADATA_INDEX => &[Fixed(16), Prefixed32],
        _ => &[],
    };
    let mut at = 0usize;
    let short = |what: &str, at: usize| {
        format!(
            "a {what} at byte {at} runs past the record's {} bytes",
            body.len()
        )
    };
    let prefixed = |at: usize, width: usize| -> Result<usize, String> {
        let head = body
            .get(at..at + width)
            .ok_or_else(|| short("length", at))?;
        let mut bytes = [0u8; 8];
        bytes[..width].copy_from_slice(head);
        let len = usize::try_from(u64::from_le_bytes(bytes)).unwrap_or(usize::MAX);
        let end = (at + width)
            .checked_add(len)
            .filter(|&e| e <= body.len())
            .ok_or_else(|| short("length-prefixed field", at))?;
        Ok(end)
    };
    for field in layout {
        at = match *field {
            Fixed(n) => {
                let end = at.checked_add(n).filter(|&e| e <= body.len());
                end.ok_or_else(|| short("fixed field", at))?
            }
            Prefixed32 => prefixed(at, 4)?,
            Prefixed64 => prefixed(at, 8)?,
            Entries(size) => {
                let end = prefixed(at, 4)?;
                if !(end - at - 4).is_multiple_of(size) {
                    return Err(format!(
                        "a field at byte {at} holds {} bytes, not a whole number of {size}-byte \
                         entries",
                        end - at - 4
                    ));
                }
                end
            }
            StringMap => {
                let end = prefixed(at, 4)?;
                let mut entry = at + 4;
                while entry < end {
                    entry = prefixed(entry, 4)?;
                    entry = prefixed(entry, 4)?;
                    if entry > end {
                        return Err(short("map entry", entry));
                    }
                }
                end
            }
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fuzzer's out-of-memory input (fuzz/regressions/mcap/): an attachment whose
    /// name claims 4 GiB inside a 100-byte record is refused before mcap reserves it.
    #[test]
    fn length_prefixes_beyond_the_record_are_refused_before_parsing() {
        let mut body = vec![0u8; 16];
        body.extend_from_slice(&u32::MAX.to_le_bytes());
        body.extend_from_slice(b"abc");
        let e = super::lengths_fit(op::ATTACHMENT, &body).unwrap_err();
        assert!(e.contains("runs past the record's 23 bytes"), "{e}");
        let mut good = vec![0u8; 16];
        for s in [&b"name"[..], b"text/plain"] {
            good.extend_from_slice(&(s.len() as u32).to_le_bytes());
            good.extend_from_slice(s);
        }
        good.extend_from_slice(&3u64.to_le_bytes());
        good.extend_from_slice(b"xyz");
        good.extend_from_slice(&0u32.to_le_bytes());
        assert_eq!(super::lengths_fit(op::ATTACHMENT, &good), Ok(()));
        assert!(super::parse_record(op::ATTACHMENT, &good).is_ok());
        // A channel whose metadata map holds a string claiming more than the map.
        let mut channel = vec![0u8; 4];
        for s in [&b"t"[..], b"json"] {
            channel.extend_from_slice(&(s.len() as u32).to_le_bytes());
            channel.extend_from_slice(s);
        }
        channel.extend_from_slice(&8u32.to_le_bytes());
        channel.extend_from_slice(&1000u32.to_le_bytes());
        channel.extend_from_slice(&[0u8; 4]);
        assert!(super::lengths_fit(op::CHANNEL, &channel).is_err());
        // The fuzzer's second find: a chunk index whose offset map holds 6 bytes, not a
        // multiple of its 10-byte entries; mcap read on into the compression string.
        let mut index = vec![0u8; 32];
        index.extend_from_slice(&6u32.to_le_bytes());
        index.extend_from_slice(&[0u8; 6 + 8]);
        index.extend_from_slice(&0u32.to_le_bytes());
        index.extend_from_slice(&[0u8; 16]);
        let e = super::lengths_fit(op::CHUNK_INDEX, &index).unwrap_err();
        assert!(e.contains("not a whole number of 10-byte entries"), "{e}");
    }
    use crate::{FileHeader, FileOptions, McapFile};

    fn sample_file() -> (Vec<u8>, usize) {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let unique = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!(
            "glrmon-reader-{}-{unique}.mcap",
            std::process::id()
        ));
        let header = FileHeader {
            config: "x = 1".into(),
            channels: vec!["a".into(), "b".into()],
            extra: std::collections::BTreeMap::new(),
        };
        let options = FileOptions {
            chunk_bytes: 2048,
            zstd: true,
        };
        let mut f = McapFile::create(&path, options, &header).unwrap();
        let n = 3000;
        for k in 0..n {
            let json = format!("{{\"k\":{k},\"y\":[{}]}}", k as f64 * 0.25);
            let channel = if k % 3 == 0 { "b" } else { "a" };
            f.write(channel, TopicKind::Inputs, k, k, json.as_bytes())
                .unwrap();
        }
        f.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        (bytes, n as usize)
    }

    fn read(bytes: &[u8]) -> Option<(usize, usize, ReadEnd)> {
        let mut r = McapReader::new(std::io::Cursor::new(bytes)).ok()?;
        let mut n = 0;
        while let Some(e) = r.next_event().unwrap() {
            if let Event::Message(m) = e {
                assert!(
                    m.data.starts_with(b"{\"k\":"),
                    "a corrupt message got through"
                );
                n += 1;
            }
        }
        Some((n, r.damage().len(), r.end().clone()))
    }

    #[test]
    fn an_intact_file_reads_whole_and_finished() {
        let (bytes, n) = sample_file();
        assert_eq!(read(&bytes), Some((n, 0, ReadEnd::Finished)));
    }

    /// Fuzz-style robustness (bad input must never cost data): every truncation
    /// point and 1000 random corruptions of a real recording are read without a panic,
    /// an abort or a corrupt message; a truncated file gives a prefix of its messages.
    #[test]
    fn truncated_and_corrupted_files_never_panic_and_yield_only_sound_messages() {
        let (bytes, n) = sample_file();
        let mut last = 0;
        for cut in (0..bytes.len()).step_by(97) {
            if let Some((got, damage, end)) = read(&bytes[..cut]) {
                if damage != 0 {
                    let mut r = McapReader::new(std::io::Cursor::new(&bytes[..cut])).unwrap();
                    while r.next_event().unwrap().is_some() {}
                    panic!("cut at {cut} of {}: {:?}", bytes.len(), r.damage());
                }
                assert!(got >= last && got <= n, "cut at {cut}: {got} messages");
                assert!(
                    matches!(end, ReadEnd::Truncated { .. }),
                    "cut at {cut}: {end:?}"
                );
                last = got;
            }
        }
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..1000 {
            let mut b = bytes.clone();
            let at = (next() % b.len() as u64) as usize;
            let len = 1 + (next() % 16) as usize;
            for i in at..(at + len).min(b.len()) {
                b[i] ^= (next() % 255 + 1) as u8;
            }
            if let Some((got, _, _)) = read(&b) {
                assert!(got <= n);
            }
        }
    }

    /// The recording the salvage tests damage: a first chunk with the
    /// schemas and channels, then 3000 inputs in 10 chunks of 300 (one flush every
    /// 300), logged at 1 ms + k µs; and its messages.
    fn ten_chunks() -> Recording {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let unique = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!(
            "glrmon-salvage-{}-{unique}.mcap",
            std::process::id()
        ));
        let header = FileHeader {
            config: "x = 1".into(),
            channels: vec!["a".into(), "b".into()],
            extra: std::collections::BTreeMap::new(),
        };
        let options = FileOptions {
            chunk_bytes: 1 << 20,
            zstd: true,
        };
        let mut f = McapFile::create(&path, options, &header).unwrap();
        for channel in ["a", "b"] {
            f.declare(channel, TopicKind::Inputs).unwrap();
        }
        f.flush().unwrap();
        let mut messages = Vec::new();
        for k in 0..3000u64 {
            let json = format!("{{\"k\":{k},\"y\":[{}]}}", k as f64 * 0.25);
            let channel = if k % 3 == 0 { "b" } else { "a" };
            let t = time(k);
            f.write(channel, TopicKind::Inputs, t, t, json.as_bytes())
                .unwrap();
            messages.push((t, json.into_bytes()));
            if k % 300 == 299 {
                f.flush().unwrap();
            }
        }
        f.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(chunk_offsets(&bytes).len(), 11);
        (bytes, messages)
    }

    /// The log time of input `k` of [`ten_chunks`].
    fn time(k: u64) -> u64 {
        1_000_000 + 1000 * k
    }

    /// Offsets and lengths (with opcode and length) of the chunk records.
    fn chunk_offsets(bytes: &[u8]) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut at = 8;
        while at + 9 <= bytes.len() {
            let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
            if bytes[at] == op::CHUNK {
                out.push((at, 9 + len));
            }
            if bytes[at] == op::DATA_END {
                break;
            }
            at += 9 + len;
        }
        out
    }

    /// The file without its summary and footer: the data section alone, as a recorder
    /// killed before closing leaves it.
    fn without_summary(bytes: &[u8]) -> Vec<u8> {
        let f = bytes.len() - 8 - FOOTER_RECORD_BYTES as usize;
        let start = u64::from_le_bytes(bytes[f + 9..f + 17].try_into().unwrap()) as usize;
        bytes[..start].to_vec()
    }

    struct Salvaged {
        messages: Vec<(u64, Vec<u8>)>,
        damage: Vec<Damage>,
        end: ReadEnd,
        salvage: Salvage,
    }

    fn salvage(bytes: &[u8]) -> Option<Salvaged> {
        let mut r = McapReader::new(std::io::Cursor::new(bytes)).ok()?;
        let mut messages = Vec::new();
        while let Some(e) = r.next_event().unwrap() {
            if let Event::Message(m) = e {
                messages.push((m.log_time, m.data));
            }
        }
        Some(Salvaged {
            messages,
            damage: r.damage().to_vec(),
            end: r.end().clone(),
            salvage: r.salvage(),
        })
    }

    /// Chunk 5 of 10 (inputs 1200..1500) damaged by `damage`, read with the summary and
    /// without: 2700 of 3000 recovered, every other chunk's messages whole, one damaged
    /// region whose lost time range is exact from the index and bounded by the
    /// neighbouring chunks without it.
    fn middle_chunk_lost(damage: impl Fn(&mut [u8], usize, usize)) -> Vec<Salvaged> {
        let (bytes, original) = ten_chunks();
        let (at, len) = chunk_offsets(&bytes)[5];
        let mut b = bytes.clone();
        damage(&mut b, at, len);
        let expected: Vec<_> = original
            .iter()
            .enumerate()
            .filter(|(k, _)| !(1200..1500).contains(k))
            .map(|(_, m)| m.clone())
            .collect();
        let mut out = Vec::new();
        for (indexed, file) in [(true, b.clone()), (false, without_summary(&b))] {
            let s = salvage(&file).unwrap();
            assert_eq!(s.messages.len(), 2700, "indexed {indexed}: {:?}", s.damage);
            assert!(s.messages == expected, "indexed {indexed}");
            assert_eq!(s.salvage.regions, 1, "indexed {indexed}: {:?}", s.damage);
            assert_eq!(s.damage[0].offset, at as u64);
            assert!(s.salvage.lost_data());
            if indexed {
                assert_eq!(s.end, ReadEnd::Finished);
                assert_eq!(
                    s.damage[0].lost,
                    Some(Lost::Indexed {
                        chunks: 1,
                        time_range: Some((time(1200), time(1499)))
                    })
                );
                assert_eq!(s.salvage.messages_known, Some(3000));
                assert_eq!(s.salvage.chunks_known, Some(11));
                assert_eq!((s.salvage.messages, s.salvage.chunks), (2700, 10));
            } else {
                assert!(matches!(s.end, ReadEnd::Truncated { .. }), "{:?}", s.end);
                assert_eq!(
                    s.damage[0].lost,
                    Some(Lost::Between {
                        after: Some(time(1199)),
                        before: Some(time(1500))
                    })
                );
                assert_eq!(s.salvage.messages_known, None);
            }
            eprintln!(
                "indexed {indexed}: {} of 3000; {}; {}",
                s.messages.len(),
                s.damage[0],
                s.salvage
            );
            out.push(s);
        }
        out
    }

    /// A zeroed chunk header (salvage once recovered 0 of 3000 inputs, "unfinished").
    #[test]
    fn salvage_resynchronises_after_a_zeroed_chunk_header() {
        let s = middle_chunk_lost(|b, at, _| b[at..at + 9].fill(0));
        // Resumes at the next chunk: the region is the lost chunk and its message
        // indexes (the index path) or the same bytes found by the scan.
        assert_eq!(s[0].damage[0].length, s[1].damage[0].length);
    }

    /// A chunk length of 2^63 (salvage once recovered 1200 of 3000, "unreadable").
    #[test]
    fn salvage_resynchronises_after_an_absurd_chunk_length() {
        middle_chunk_lost(|b, at, _| {
            b[at + 1..at + 9].copy_from_slice(&(1u64 << 63).to_le_bytes())
        });
    }

    /// A byte flipped inside a chunk's compressed data: that chunk fails its CRC (or
    /// zstd) and is skipped by its own length, the rest is read.
    #[test]
    fn salvage_skips_a_chunk_with_corrupt_data() {
        let s = middle_chunk_lost(|b, at, len| b[at + len / 2] ^= 0x5a);
        for s in &s {
            assert!(
                s.damage[0].reason.starts_with("chunk skipped: "),
                "{}",
                s.damage[0]
            );
        }
    }

    /// A chunk's opcode with one bit flipped (0x06 to 0x07, a message index; to 0x02, a
    /// footer; to 0x04, a channel): the chunk is reported lost, not skipped silently
    /// (was: 2700 silently, 1200 and "finished", 2700), and reading goes on.
    #[test]
    fn salvage_reports_a_chunk_whose_opcode_was_flipped() {
        for flip in [0x01u8, 0x04, 0x02] {
            middle_chunk_lost(|b, at, _| b[at] ^= flip);
        }
    }

    /// A length field made shorter than the chunk: its fields no longer add up, and
    /// reading resynchronises instead of parsing the chunk's data as records.
    #[test]
    fn salvage_resynchronises_after_a_short_chunk_length() {
        middle_chunk_lost(|b, at, len| {
            b[at + 1..at + 9].copy_from_slice(&(len as u64 / 2).to_le_bytes());
        });
    }

    /// The first chunk (which defines the channels, and holds no message) zeroed: with
    /// the summary, its schemas and channels make every message readable (3000 of
    /// 3000, the damage reported without a time range); without it, every message is
    /// of an unknown channel and counted as such.
    #[test]
    fn salvage_reads_channels_from_the_summary_when_their_chunk_is_lost() {
        let (mut bytes, _) = ten_chunks();
        let (at, _) = chunk_offsets(&bytes)[0];
        bytes[at..at + 9].fill(0);
        let s = salvage(&bytes).unwrap();
        assert_eq!(s.messages.len(), 3000, "{:?} {}", s.damage, s.salvage);
        assert_eq!(s.salvage.regions, 1);
        assert_eq!(
            s.damage[0].lost,
            Some(Lost::Indexed {
                chunks: 1,
                time_range: None
            })
        );
        assert_eq!(s.salvage.unknown_channel, 0);
        let s = salvage(&without_summary(&bytes)).unwrap();
        assert_eq!(s.messages.len(), 0);
        assert_eq!(s.salvage.unknown_channel, 3000);
        assert!(s.salvage.lost_data());
    }

    /// A damaged summary (its CRC fails) is not used: the scan salvages the data.
    #[test]
    fn a_damaged_summary_is_not_trusted() {
        let (mut bytes, _) = ten_chunks();
        let (at, _) = chunk_offsets(&bytes)[5];
        bytes[at..at + 9].fill(0);
        let f = bytes.len() - 8 - FOOTER_RECORD_BYTES as usize;
        let start = u64::from_le_bytes(bytes[f + 9..f + 17].try_into().unwrap()) as usize;
        bytes[start + 20] ^= 0xff;
        let s = salvage(&bytes).unwrap();
        assert_eq!(s.messages.len(), 2700);
        assert!(!s.salvage.indexed);
        assert!(s.salvage.summary_note.is_some());
    }

    /// An unfinished file (no summary) whose tail is zeroes or a cut record lost
    /// nothing but that tail: truncated, not damaged.
    #[test]
    fn an_unfinished_tail_is_not_damage() {
        let (bytes, _) = ten_chunks();
        let data = without_summary(&bytes);
        let mut zeroed = data.clone();
        zeroed.extend(std::iter::repeat_n(0u8, 5000));
        let (at, len) = chunk_offsets(&bytes)[10];
        for file in [zeroed, data[..at + len / 2].to_vec()] {
            let s = salvage(&file).unwrap();
            assert!(matches!(s.end, ReadEnd::Truncated { .. }), "{:?}", s.end);
            assert!(!s.salvage.lost_data(), "{:?}", s.damage);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        /// Random corruption (runs zeroed or flipped at random offsets, with and
        /// without the summary) never panics, and every message read is one of the
        /// file's own: no garbage gets through.
        #[test]
        fn random_corruption_yields_a_subset_of_the_messages(
            hits in proptest::collection::vec((0.0f64..1.0, 1usize..64, proptest::prelude::any::<bool>()), 1..6),
            summary in proptest::prelude::any::<bool>(),
        ) {
            let (bytes, original) = &*TEN_CHUNKS;
            let mut b = if summary { bytes.clone() } else { without_summary(bytes) };
            let n = b.len();
            for (pos, len, zero) in hits {
                let at = 8 + ((n - 8) as f64 * pos) as usize;
                for x in &mut b[at..(at + len).min(n)] {
                    *x = if zero { 0 } else { *x ^ 0xa5 };
                }
            }
            if let Some(s) = salvage(&b) {
                let known: std::collections::HashSet<&(u64, Vec<u8>)> = original.iter().collect();
                for m in &s.messages {
                    proptest::prop_assert!(known.contains(m), "a garbage message {:?}", m);
                }
                let bytes_skipped: u64 = s.damage.iter().map(|d| d.length).sum();
                proptest::prop_assert!(bytes_skipped <= n as u64);
            }
        }
    }

    /// A recording and its messages (log time, data).
    type Recording = (Vec<u8>, Vec<(u64, Vec<u8>)>);

    static TEN_CHUNKS: std::sync::LazyLock<Recording> = std::sync::LazyLock::new(ten_chunks);
}
