//! Payload decoders: a channel's raw payloads → samples, inside its pipeline.
//!
//! Each channel's [`ChannelPipeline`](crate::ChannelPipeline) owns the decoder its
//! configuration names (`[[channels]] payload`), built by [`decoder`]; the daemon's
//! workers hand it the payloads as received. A new format is a type implementing
//! [`PayloadDecoder`] in a module of its own here, one arm of [`decoder`] and one
//! variant of `glrmon_spec::PayloadFormat`.

use glrmon_spec::PayloadFormat;
use glrmon_wire::{DecodeError, DecodeLimits, Sample, decode_samples};

/// Turns one payload into the samples it carries.
pub trait PayloadDecoder: Send + std::fmt::Debug {
    /// The format's name, as the configuration writes it.
    fn format(&self) -> &'static str;

    /// Decodes `payload` for `channel` into `out` (cleared first; its samples'
    /// buffers are reused), within `limits`.
    ///
    /// # Errors
    /// [`DecodeError`] naming the channel, the field and the reason; `out` holds no
    /// sample of a payload that failed.
    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError>;
}

/// The JSON sample format of docs/WIRE.md: one object or an array of them.
#[derive(Debug, Clone, Copy, Default)]
pub struct JsonDecoder;

impl PayloadDecoder for JsonDecoder {
    fn format(&self) -> &'static str {
        PayloadFormat::Json.name()
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        decode_samples(channel, payload, limits, out)
    }
}

/// The decoder of a payload format: the one factory the runtime builds decoders with.
#[must_use]
pub fn decoder(format: PayloadFormat) -> Box<dyn PayloadDecoder> {
    match format {
        PayloadFormat::Json => Box::new(JsonDecoder),
    }
}
