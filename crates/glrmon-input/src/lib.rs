#![doc = include_str!("../README.md")]

mod csv;
mod error;
mod foreign;
mod format;
mod mcap;
mod play;
mod readahead;
mod replay;
mod samples;
mod table;

pub use csv::{
    CsvReader, HeaderError, RowError, parse_value, separator_of, write_header, write_header_named,
    write_row,
};
pub use error::{InputError, InputErrorKind};
pub use foreign::{
    ForeignReplayed, ForeignSamples, foreign_message_json, replay_foreign_mcap, topics_decoder,
};
pub use format::{InputFormat, OutputFormat, embedded_config};
pub use mcap::{McapInput, RecordedInput};
pub use play::{Playback, PlayedSample, due};
pub use readahead::{ReadAhead, ReadAheadError};
pub use replay::{
    CsvReplayed, McapReplayed, ReplayError, replay_csv, replay_csv_from, replay_mcap,
};
pub use samples::{Samples, Skipped};
pub use table::{Table, read_table, read_table_for_channel};
