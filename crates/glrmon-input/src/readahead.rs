//! Reading ahead on a thread of its own: a replay's input side (file reads, zstd,
//! JSON or CSV decoding) runs beside the monitors instead of before each step.
//!
//! The reader hands over batches in order through a bounded queue (a few batches
//! ahead, so memory stays flat in the file size), and the consumer sends emptied
//! batches back to be refilled, so their storage is reused; items the consumer is done
//! with go back with them ([`ReadAhead::recycle`]) for the reader to decode into, so a
//! steady replay allocates nothing per item.

use std::collections::VecDeque;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// Items per batch handed over.
const BATCH: usize = 1024;
/// Batches queued ahead of the consumer.
const AHEAD: usize = 4;

/// Why [`ReadAhead`] could not go on.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadAheadError<E> {
    /// The source's own error, after every item read before it.
    #[error("{0}")]
    Source(E),
    /// The reader thread ended without reaching the end of the source (it panicked):
    /// the input would otherwise be cut short silently.
    #[error("the replay reader thread stopped before the end of the input")]
    Stopped,
    /// The reader thread panicked ([`ReadAhead::finish`]).
    #[error("the replay reader thread panicked")]
    Panicked,
}

/// A source read on another thread: [`ReadAhead::next`] yields its items in order,
/// [`ReadAhead::finish`] gives the source back (for its end-of-file report).
///
/// # Examples
///
/// ```
/// use glrmon_input::ReadAhead;
///
/// // A source of 10 000 numbers, then an error.
/// let mut ahead = ReadAhead::spawn(0_u32, |n, _spare: Option<u32>| {
///     *n += 1;
///     if *n > 10_000 { Err("no more") } else { Ok(Some(*n)) }
/// })?;
/// let mut sum = 0_u64;
/// let err = loop {
///     match ahead.next() {
///         Ok(Some(x)) => {
///             sum += u64::from(x);
///             ahead.recycle(x);
///         }
///         Ok(None) => unreachable!("the source ends with an error"),
///         Err(e) => break e,
///     }
/// };
/// assert_eq!(sum, 10_000 * 10_001 / 2);
/// assert_eq!(err.to_string(), "no more");
/// assert_eq!(ahead.finish().unwrap(), 10_001);
/// # Ok::<(), std::io::Error>(())
/// ```
pub struct ReadAhead<S, T, E> {
    /// Batches in order, then `Ok(None)` at a clean end or the source's error.
    full: Receiver<Result<Option<VecDeque<T>>, E>>,
    empty: SyncSender<VecDeque<T>>,
    batch: VecDeque<T>,
    /// Items handed back by the consumer, sent to the reader with the next empty batch.
    spent: VecDeque<T>,
    done: bool,
    reader: JoinHandle<S>,
}

impl<S, T, E> std::fmt::Debug for ReadAhead<S, T, E> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReadAhead")
            .field("buffered", &self.batch.len())
            .field("spent", &self.spent.len())
            .field("done", &self.done)
            .finish_non_exhaustive()
    }
}

impl<S: Send + 'static, T: Send + 'static, E: Send + 'static> ReadAhead<S, T, E> {
    /// Starts reading `source` with `next` (`Ok(None)` at the end; an error ends the
    /// reading and is returned by [`ReadAhead::next`] after the items before it). `next`
    /// gets a recycled item when there is one, to decode into instead of allocating.
    ///
    /// # Errors
    /// When the reader thread cannot be started.
    pub fn spawn(
        mut source: S,
        mut next: impl FnMut(&mut S, Option<T>) -> Result<Option<T>, E> + Send + 'static,
    ) -> std::io::Result<Self> {
        let (full_tx, full) = sync_channel::<Result<Option<VecDeque<T>>, E>>(AHEAD);
        let (empty, empty_rx) = sync_channel::<VecDeque<T>>(AHEAD + 2);
        let reader = std::thread::Builder::new()
            .name("replay-reader".into())
            .spawn(move || {
                let mut spares = VecDeque::new();
                loop {
                    let mut batch = match empty_rx.try_recv() {
                        Ok(mut returned) => {
                            spares.extend(returned.drain(..));
                            returned
                        }
                        Err(_) => VecDeque::with_capacity(BATCH),
                    };
                    let mut end = None;
                    while batch.len() < BATCH {
                        match next(&mut source, spares.pop_front()) {
                            Ok(Some(item)) => batch.push_back(item),
                            Ok(None) => {
                                end = Some(Ok(()));
                                break;
                            }
                            Err(e) => {
                                end = Some(Err(e));
                                break;
                            }
                        }
                    }
                    // A consumer that stopped listening ends the reading too.
                    if !batch.is_empty() && full_tx.send(Ok(Some(batch))).is_err() {
                        break;
                    }
                    match end {
                        None => {}
                        Some(end) => {
                            let _ = full_tx.send(end.map(|()| None));
                            break;
                        }
                    }
                }
                source
            })?;
        Ok(Self {
            full,
            empty,
            batch: VecDeque::new(),
            spent: VecDeque::new(),
            done: false,
            reader,
        })
    }

    /// The next item in source order; `Ok(None)` at the end.
    ///
    /// # Errors
    /// [`ReadAheadError::Source`] with the source's error, after every item read before
    /// it; [`ReadAheadError::Stopped`] when the reader stopped without reaching the end
    /// (it panicked), so that input is never cut short silently. After an error, `next`
    /// returns `Ok(None)`.
    #[allow(
        clippy::should_implement_trait,
        reason = "not an Iterator: the end after an error is part of the contract"
    )]
    pub fn next(&mut self) -> Result<Option<T>, ReadAheadError<E>> {
        loop {
            if let Some(item) = self.batch.pop_front() {
                return Ok(Some(item));
            }
            if self.done {
                return Ok(None);
            }
            match self.full.recv() {
                Ok(Ok(Some(batch))) => {
                    let used = std::mem::replace(&mut self.batch, batch);
                    let spent = std::mem::replace(&mut self.spent, used);
                    let _ = self.empty.try_send(spent);
                }
                Ok(Ok(None)) => self.done = true,
                Ok(Err(e)) => {
                    self.done = true;
                    return Err(ReadAheadError::Source(e));
                }
                Err(_) => {
                    self.done = true;
                    return Err(ReadAheadError::Stopped);
                }
            }
        }
    }

    /// Hands an item back for the reader to decode a later one into (its allocations
    /// are reused; at most a batch is kept).
    pub fn recycle(&mut self, item: T) {
        if self.spent.len() < BATCH {
            self.spent.push_back(item);
        }
    }

    /// Waits for the reader and returns the source. Items not yet taken are dropped
    /// and a reader still reading stops at its next batch.
    ///
    /// # Errors
    /// [`ReadAheadError::Panicked`] when the reader thread panicked.
    pub fn finish(self) -> Result<S, ReadAheadError<E>> {
        let Self { full, reader, .. } = self;
        // Unblock a reader still waiting to hand over a batch.
        drop(full);
        reader.join().map_err(|_| ReadAheadError::Panicked)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every item arrives once and in order across many batches, the source comes
    /// back, and an error arrives after the items read before it.
    #[test]
    fn items_in_order_then_the_error() {
        let mut ahead = ReadAhead::spawn(0_u64, |n, _| {
            *n += 1;
            match *n {
                n if n <= 5000 => Ok(Some(n)),
                _ => Err("bad record after 5000"),
            }
        })
        .unwrap();
        let mut expected = 1;
        let err = loop {
            match ahead.next() {
                Ok(Some(x)) => {
                    assert_eq!(x, expected);
                    expected += 1;
                }
                Ok(None) => panic!("end before the error"),
                Err(e) => break e,
            }
        };
        assert_eq!(expected, 5001);
        assert!(err.to_string().contains("after 5000"));
        assert!(ahead.next().unwrap().is_none());
        assert_eq!(ahead.finish().unwrap(), 5001);
    }

    /// A reader that panics mid-way is an error after the items before it, never a
    /// clean (shortened) end.
    #[test]
    fn a_panicking_reader_is_an_error_not_an_end() {
        let mut ahead = ReadAhead::spawn(0_u64, |n, _| {
            *n += 1;
            assert!(*n <= 3000, "reader fails at item 3001");
            Ok::<_, &str>(Some(*n))
        })
        .unwrap();
        let mut seen = 0;
        let err = loop {
            match ahead.next() {
                Ok(Some(_)) => seen += 1,
                Ok(None) => panic!("a clean end after {seen} items"),
                Err(e) => break e,
            }
        };
        // The batch being filled when the reader failed is lost with it; the error says so.
        assert_eq!(seen, 2 * BATCH);
        assert!(err.to_string().contains("stopped before the end"), "{err}");
        assert!(ahead.finish().is_err());
    }

    /// Items handed back come back to the reader as spares, with their storage: over
    /// 20 batches of items that each own a buffer, almost every item after the first
    /// batches is decoded into a recycled one.
    #[test]
    fn recycled_items_are_decoded_into_again() {
        // The source counts (items read, spares received with their capacity kept).
        let mut ahead =
            ReadAhead::spawn((0_usize, 0_usize), |(n, reused), spare: Option<Vec<u8>>| {
                if *n == 20 * BATCH {
                    return Ok::<_, &str>(None);
                }
                *n += 1;
                let mut item = match spare {
                    Some(v) if v.capacity() >= 64 => {
                        *reused += 1;
                        v
                    }
                    _ => Vec::with_capacity(64),
                };
                item.clear();
                item.push((*n % 251) as u8);
                Ok(Some(item))
            })
            .unwrap();
        let mut count = 0;
        while let Some(item) = ahead.next().unwrap() {
            count += 1;
            assert_eq!(item[0], (count % 251) as u8);
            ahead.recycle(item);
        }
        assert_eq!(count, 20 * BATCH);
        let (_, reused) = ahead.finish().unwrap();
        assert!(reused >= 10 * BATCH, "{reused} of {count} items reused");
    }

    /// A consumer that stops early does not leave the reader blocked.
    #[test]
    fn finishing_early_stops_the_reader() {
        let mut ahead = ReadAhead::spawn(0_u64, |n, _| {
            *n += 1;
            Ok::<_, &str>(Some(*n))
        })
        .unwrap();
        assert_eq!(ahead.next().unwrap(), Some(1));
        let read = ahead.finish().unwrap();
        assert!(read >= 1 && read <= (BATCH * (AHEAD + 3)) as u64, "{read}");
    }
}
