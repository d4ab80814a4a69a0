//! Sinks that need nothing but the standard library; the Zenoh publisher, the MCAP
//! recorder and the HTML report live in their adapters' crates.

mod func;
mod jsonl;
mod memory;

pub use func::FnSink;
pub use jsonl::JsonLinesSink;
pub use memory::MemorySink;
