//! A closure called for each record.

use crate::sink::{Interest, Output, Sink, SinkError};

/// A sink calling a closure for each record (e.g. print alarms). Its interest is the
/// default (the driver's `stat` decimation) unless set with [`FnSink::with_interest`].
pub struct FnSink<F> {
    name: &'static str,
    f: F,
    interest: Interest,
}

impl<F> FnSink<F> {
    /// A sink named `name` calling `f`.
    pub fn new(name: &'static str, f: F) -> Self {
        Self {
            name,
            f,
            interest: Interest::default(),
        }
    }

    /// The same sink asking for `interest` (e.g. `stat_every: Some(0)` for alarms,
    /// diagnoses and errors only).
    #[must_use]
    pub fn with_interest(mut self, interest: Interest) -> Self {
        self.interest = interest;
        self
    }
}

impl<F> std::fmt::Debug for FnSink<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FnSink").field("name", &self.name).finish()
    }
}

impl<F: FnMut(&Output) + Send + 'static> Sink for FnSink<F> {
    fn name(&self) -> &str {
        self.name
    }
    fn interest(&self) -> Interest {
        self.interest
    }
    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        (self.f)(output);
        Ok(())
    }
}
