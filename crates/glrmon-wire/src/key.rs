//! Zenoh key expressions of the wire format.
//!
//! Results go to `glrmon/<channel>/<type>` (`type` as in [`RECORD_KINDS`](crate::RECORD_KINDS));
//! samples are read from a per-channel key expression in the config, by default
//! `plant/<channel>`. A channel name is therefore one key-expression chunk, which
//! [`validate_channel_name`] checks.

use crate::error::{ChannelNameError, ChannelNameErrorKind};

/// First chunk of every result key.
pub const RESULT_PREFIX: &str = "glrmon";

/// First chunk of the default input key.
pub const DEFAULT_INPUT_PREFIX: &str = "plant";

/// The key a record of `kind` for `channel` is published on: `glrmon/<channel>/<kind>`.
///
/// # Examples
///
/// ```
/// assert_eq!(glrmon_wire::result_key("pump3", "alarm"), "glrmon/pump3/alarm");
/// ```
#[must_use]
pub fn result_key(channel: &str, kind: &str) -> String {
    format!("{RESULT_PREFIX}/{channel}/{kind}")
}

/// The input key expression used when a channel's config names none: `plant/<channel>`.
///
/// # Examples
///
/// ```
/// assert_eq!(glrmon_wire::default_input_key("pump3"), "plant/pump3");
/// ```
#[must_use]
pub fn default_input_key(channel: &str) -> String {
    format!("{DEFAULT_INPUT_PREFIX}/{channel}")
}

/// Splits a result key `glrmon/<channel>/<type>` into `(channel, type)`; `None` if the
/// key does not have that shape. For `glrmon watch`, which subscribes to `glrmon/**`.
///
/// # Examples
///
/// ```
/// assert_eq!(glrmon_wire::parse_result_key("glrmon/pump3/alarm_end"), Some(("pump3", "alarm_end")));
/// assert_eq!(glrmon_wire::parse_result_key("plant/pump3"), None);
/// ```
#[must_use]
pub fn parse_result_key(key: &str) -> Option<(&str, &str)> {
    let rest = key.strip_prefix(RESULT_PREFIX)?.strip_prefix('/')?;
    let (channel, kind) = rest.split_once('/')?;
    (!channel.is_empty() && !kind.is_empty() && !kind.contains('/')).then_some((channel, kind))
}

/// Checks that `name` can be a channel: exactly one chunk of a Zenoh key expression that
/// wildcards match.
///
/// Rejected: the empty name; `/` (it would split the chunk); `*` and `$` (wildcard
/// syntax); `?` and `#` (selector syntax); whitespace and control characters (they break
/// logs and shell use of keys); a leading `@` (a verbatim chunk, which `*` and `**` never
/// match, so `glrmon/*/alarm` would miss the channel).
///
/// # Errors
///
/// A [`ChannelNameError`] saying which rule failed and, for a character, where.
///
/// # Examples
///
/// ```
/// use glrmon_wire::validate_channel_name;
///
/// assert!(validate_channel_name("pump-3.inlet_A").is_ok());
/// let err = validate_channel_name("pump 3").unwrap_err();
/// assert_eq!(err.to_string(), r#"channel name "pump 3" contains ' ' at byte 4, which breaks Zenoh key expressions"#);
/// ```
pub fn validate_channel_name(name: &str) -> Result<(), ChannelNameError> {
    let fail = |kind| {
        Err(ChannelNameError {
            name: name.to_owned(),
            kind,
        })
    };
    if name.is_empty() {
        return fail(ChannelNameErrorKind::Empty);
    }
    if let Some((byte_offset, ch)) = name.char_indices().find(|&(_, c)| {
        matches!(c, '/' | '*' | '$' | '?' | '#') || c.is_whitespace() || c.is_control()
    }) {
        return fail(ChannelNameErrorKind::ForbiddenChar { ch, byte_offset });
    }
    if name.starts_with('@') {
        return fail(ChannelNameErrorKind::LeadingAt);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_have_the_documented_shape() {
        assert_eq!(result_key("pump3", "stat"), "glrmon/pump3/stat");
        assert_eq!(default_input_key("pump3"), "plant/pump3");
        for kind in crate::RECORD_KINDS {
            assert_eq!(
                parse_result_key(&result_key("pump3", kind)),
                Some(("pump3", kind))
            );
        }
    }

    #[test]
    fn parse_result_key_rejects_other_shapes() {
        for key in [
            "glrmon",
            "glrmon/",
            "glrmon/pump3",
            "glrmon//stat",
            "glrmon/pump3/",
            "glrmon/a/b/c",
            "glrmonx/a/b",
            "plant/a/b",
        ] {
            assert_eq!(parse_result_key(key), None, "{key}");
        }
    }

    #[test]
    fn valid_channel_names() {
        for name in ["pump3", "pump-3", "a.b_c", "Ä", "x@y", "0"] {
            assert!(validate_channel_name(name).is_ok(), "{name}");
        }
    }

    #[test]
    fn invalid_channel_names_say_why() {
        assert_eq!(
            validate_channel_name("").unwrap_err().kind,
            ChannelNameErrorKind::Empty
        );
        for (name, ch, at) in [
            ("a/b", '/', 1),
            ("a*", '*', 1),
            ("$x", '$', 0),
            ("q?", '?', 1),
            ("h#", '#', 1),
            ("a b", ' ', 1),
            ("tab\t", '\t', 3),
            ("nl\n", '\n', 2),
            ("nul\0", '\0', 3),
            ("é/", '/', 2),
        ] {
            let err = validate_channel_name(name).unwrap_err();
            assert_eq!(
                err.kind,
                ChannelNameErrorKind::ForbiddenChar {
                    ch,
                    byte_offset: at
                },
                "{name:?}"
            );
            assert!(
                err.to_string().contains("breaks Zenoh key expressions"),
                "{err}"
            );
        }
        let err = validate_channel_name("@admin").unwrap_err();
        assert_eq!(err.kind, ChannelNameErrorKind::LeadingAt);
        assert_eq!(
            err.to_string(),
            r#"channel name "@admin" starts with '@', which Zenoh wildcards never match"#
        );
    }
}
