//! A streaming MCAP reader that tolerates what crashes and disks do to files.
//!
//! The file is walked record by record (opcode, length, body) from the start, so memory
//! stays flat in the file size (one chunk at a time) and no footer or index is needed:
//! - a file cut short (`kill -9`, power loss) reads up to its last complete chunk and
//!   reports [`ReadEnd::Truncated`];
//! - a chunk whose data is corrupt (bad CRC, undecodable zstd) is skipped whole and
//!   reported as [`Damage`]; reading resumes at the next record, whose position the
//!   chunk's own length gives;
//! - a record length that runs past the end of the file ends the read, reported.

use std::collections::HashMap;
use std::io::{self, Read};
use std::sync::Arc;

use mcap::records::{Record as McapRecord, op};

use crate::schema::TopicKind;

/// The largest record accepted (chunks are about 1 MiB; a larger length is damage).
const MAX_RECORD_BYTES: u64 = 1 << 30;

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

/// A damaged part of a file that was skipped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// Byte offset of the damaged record.
    pub offset: u64,
    /// Its length in bytes.
    pub length: u64,
    /// What is wrong.
    pub reason: String,
}

impl std::fmt::Display for Damage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "bytes {}..{}: {}",
            self.offset,
            self.offset + self.length,
            self.reason
        )
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
    Truncated {
        /// Offset where the readable part ends.
        at: u64,
        /// Bytes of an incomplete record after it.
        partial: u64,
    },
    /// A record length runs past what can be read: the rest of the file is unreadable.
    Unreadable {
        /// Offset of the record.
        at: u64,
        /// Why.
        reason: String,
    },
}

/// Streams the events of an MCAP file; see the module documentation.
#[derive(Debug)]
pub struct McapReader<R> {
    input: R,
    offset: u64,
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
}

impl<R: Read> McapReader<R> {
    /// Checks the magic and prepares to read.
    ///
    /// # Errors
    /// [`ReadError::NotMcap`] or an I/O error.
    pub fn new(mut input: R) -> Result<Self, ReadError> {
        let mut magic = [0u8; 8];
        if read_full(&mut input, &mut magic)? < 8 || magic != mcap::MAGIC {
            return Err(ReadError::NotMcap);
        }
        Ok(Self {
            input,
            offset: 8,
            body: Vec::new(),
            topics: HashMap::new(),
            schemas: HashMap::new(),
            pending: std::collections::VecDeque::new(),
            chunk_data: Vec::new(),
            damage: Vec::new(),
            end: ReadEnd::Reading,
            chunks: 0,
            messages: 0,
        })
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
        if opcode == op::CHUNK && len == u64::MAX {
            // mcap's writer puts this placeholder while a chunk is open and writes the
            // length when the chunk is finished: the recorder stopped inside a chunk.
            let partial = io::copy(&mut self.input, &mut io::sink())?;
            self.end = ReadEnd::Truncated {
                at: start,
                partial: 9 + partial,
            };
            return Ok(());
        }
        if len > MAX_RECORD_BYTES {
            self.end = ReadEnd::Unreadable {
                at: start,
                reason: format!("record (opcode {opcode:#04x}) claims {len} bytes"),
            };
            return Ok(());
        }
        let len_usize = usize::try_from(len).unwrap_or(usize::MAX);
        self.body.clear();
        self.body.resize(len_usize, 0);
        let got = read_full(&mut self.input, &mut self.body)?;
        if got < len_usize {
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
            op::CHUNK => self.read_chunk(start, len),
            op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA => {
                match mcap::parse_record(opcode, &self.body) {
                    Ok(r) => {
                        let r = r.into_owned();
                        self.accept(r);
                    }
                    Err(e) => self.damage.push(Damage {
                        offset: start,
                        length: 9 + len,
                        reason: format!("record (opcode {opcode:#04x}) is invalid: {e}"),
                    }),
                }
            }
            // Header, indexes, statistics, summary offsets, data end, attachments:
            // nothing a replay needs.
            _ => {}
        }
        Ok(())
    }

    fn read_chunk(&mut self, start: u64, len: u64) {
        let body = std::mem::take(&mut self.body);
        let result = parse_chunk(&body, &mut self.chunk_data);
        self.body = body;
        match result {
            Ok(records) => {
                self.chunks += 1;
                for r in records {
                    self.accept(r);
                }
            }
            Err(reason) => self.damage.push(Damage {
                offset: start,
                length: 9 + len,
                reason: format!("chunk skipped: {reason}"),
            }),
        }
    }

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
                    self.damage.push(Damage {
                        offset: self.offset,
                        length: 0,
                        reason: format!(
                            "a message of unknown MCAP channel {} skipped",
                            header.channel_id
                        ),
                    });
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

/// The records of a chunk, all or nothing: the data is decompressed with its declared
/// size as a bound, checked against its CRC, and every record's length is checked
/// against what remains before mcap parses it (a corrupt length must not become an
/// allocation of exabytes).
fn parse_chunk(body: &[u8], scratch: &mut Vec<u8>) -> Result<Vec<McapRecord<'static>>, String> {
    let McapRecord::Chunk { header, data } =
        mcap::parse_record(op::CHUNK, body).map_err(|e| e.to_string())?
    else {
        return Err("not a chunk".into());
    };
    if header.uncompressed_size > MAX_RECORD_BYTES {
        return Err(format!(
            "declares {} uncompressed bytes",
            header.uncompressed_size
        ));
    }
    let size = usize::try_from(header.uncompressed_size).map_err(|e| e.to_string())?;
    let records: &[u8] = match header.compression.as_str() {
        "" => &data,
        "zstd" => {
            scratch.clear();
            scratch.reserve(size);
            let mut decoder =
                zstd::stream::read::Decoder::with_buffer(&data[..]).map_err(|e| e.to_string())?;
            let got = std::io::Read::read_to_end(
                &mut std::io::Read::take(&mut decoder, header.uncompressed_size + 1),
                scratch,
            )
            .map_err(|e| format!("zstd: {e}"))?;
            if got != size {
                return Err(format!(
                    "decompresses to {got} bytes, the header says {size}"
                ));
            }
            scratch
        }
        other => return Err(format!("unsupported compression \"{other}\"")),
    };
    if records.len() != size {
        return Err(format!(
            "holds {} bytes, the header says {size}",
            records.len()
        ));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(records);
        if crc != header.uncompressed_crc {
            return Err(format!(
                "CRC {crc:#010x} differs from the recorded {:#010x}",
                header.uncompressed_crc
            ));
        }
    }
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < records.len() {
        let Some(head) = records.get(at..at + 9) else {
            return Err(format!("a record header is cut at byte {at}"));
        };
        let opcode = head[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(len);
        let end = usize::try_from(len)
            .ok()
            .and_then(|l| (at + 9).checked_add(l))
            .filter(|&e| e <= records.len())
            .ok_or_else(|| format!("a record at byte {at} claims {len} bytes"))?;
        let record = mcap::parse_record(opcode, &records[at + 9..end])
            .map_err(|e| format!("record at byte {at}: {e}"))?;
        out.push(record.into_owned());
        at = end;
    }
    Ok(out)
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

#[cfg(test)]
mod tests {
    use super::*;
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
        let mut r = McapReader::new(bytes).ok()?;
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

    /// Fuzz-style robustness (issue 6, "bad input never costs data"): every truncation
    /// point and 1000 random corruptions of a real recording are read without a panic,
    /// an abort or a corrupt message; a truncated file gives a prefix of its messages.
    #[test]
    fn truncated_and_corrupted_files_never_panic_and_yield_only_sound_messages() {
        let (bytes, n) = sample_file();
        let mut last = 0;
        for cut in (0..bytes.len()).step_by(97) {
            if let Some((got, damage, end)) = read(&bytes[..cut]) {
                assert_eq!(damage, 0, "cut at {cut}");
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
}
