//! Text from outside made safe to show: every character that could drive a terminal,
//! forge a log line or reorder what a reader sees becomes a visible escape.
//!
//! Payload field names, key expressions, the channel names and messages of records
//! received from a peer, recording metadata and file names can hold any character. Shown
//! raw, `ESC ] 0 ; … BEL` retitles a terminal window, `ESC [ 2 J` clears the screen, a
//! newline starts a forged log line and U+202E RIGHT-TO-LEFT OVERRIDE makes `lmx.exe`
//! read as `exe.xml`. Such text passes through [`escape_control`] or [`Escaped`] where
//! it enters a human-readable message (a decode error quoting a field name) and again
//! where a printer shows text it received (a record's channel in `glrmon watch`).
//!
//! Escaped are: the C0 controls (U+0000–U+001F, among them TAB, LF, CR, BEL and ESC),
//! DEL (U+007F), the C1 controls (U+0080–U+009F) and the invisible format characters that
//! change how text around them is laid out ([`needs_escape`]). ASCII ones are written
//! `\t`, `\n`, `\r` or `\xNN` (`\x1b`), the others `\u{…}` in hex (`\u{9b}`,
//! `\u{202e}`), as Rust writes them. Backslashes are left alone, so escaping twice
//! changes nothing: a message escaped where it was made may safely be escaped again where
//! it is printed. The escape is for reading, not reversible: text that already held a
//! backslash sequence looks the same as an escaped character.
//!
//! JSON output is different: serde_json escapes only U+0000–U+001F, and a record passed
//! on verbatim may hold raw line breaks between its values. [`escape_json`] gives such
//! text the same protection and keeps it the same JSON value.

use std::borrow::Cow;
use std::fmt::{self, Write as _};

/// Whether `c` is shown as an escape rather than itself: a C0 control, DEL, a C1
/// control, or an invisible format character that can spoof what a reader sees.
///
/// The format characters are the bidirectional controls (U+061C ARABIC LETTER MARK,
/// U+200E/U+200F LRM/RLM, U+202A–U+202E embeddings and overrides, U+2066–U+2069
/// isolates), the line and paragraph separators U+2028/U+2029 (line breaks to some
/// viewers), the zero-width space U+200B, word joiner and invisible operators
/// U+2060–U+2064, the deprecated shaping controls U+206A–U+206F, the byte order mark
/// U+FEFF and the interlinear annotation marks U+FFF9–U+FFFB. Zero-width (non-)joiners
/// U+200C/U+200D are kept: emoji sequences and Persian words need them.
///
/// # Examples
///
/// ```
/// use glrmon_wire::text::needs_escape;
///
/// assert!(needs_escape('\u{1b}'));
/// assert!(needs_escape('\u{202e}'));
/// assert!(!needs_escape('μ'));
/// assert!(!needs_escape('\\'));
/// ```
#[must_use]
pub const fn needs_escape(c: char) -> bool {
    matches!(
        c,
        '\u{0}'..='\u{1f}'
            | '\u{7f}'..='\u{9f}'
            | '\u{61c}'
            | '\u{200b}'
            | '\u{200e}'
            | '\u{200f}'
            | '\u{2028}'..='\u{202e}'
            | '\u{2060}'..='\u{2064}'
            | '\u{2066}'..='\u{206f}'
            | '\u{feff}'
            | '\u{fff9}'..='\u{fffb}'
    )
}

/// `s` with every character of [`needs_escape`] written as a visible escape (`\x1b`,
/// `\n`, `\u{202e}`); borrowed when there is none, which is the common case.
///
/// # Examples
///
/// ```
/// use std::borrow::Cow;
/// use glrmon_wire::text::escape_control;
///
/// assert_eq!(escape_control("\u{1b}]0;pwned\u{7}"), r"\x1b]0;pwned\x07");
/// assert_eq!(escape_control("a\nb\u{202e}"), r"a\nb\u{202e}");
/// assert!(matches!(escape_control("T1 °C"), Cow::Borrowed("T1 °C")));
/// ```
#[must_use]
pub fn escape_control(s: &str) -> Cow<'_, str> {
    if s.chars().any(needs_escape) {
        Cow::Owned(Escaped(s).to_string())
    } else {
        Cow::Borrowed(s)
    }
}

/// Displays its text as [`escape_control`] returns it, without allocating: for format
/// strings, `format!("field {}", Escaped(name))`.
///
/// # Examples
///
/// ```
/// use glrmon_wire::text::Escaped;
///
/// assert_eq!(format!("key {}", Escaped("plant/\u{1b}[2J")), r"key plant/\x1b[2J");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Escaped<'a>(pub &'a str);

impl fmt::Display for Escaped<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut rest = self.0;
        while let Some((at, c)) = rest.char_indices().find(|&(_, c)| needs_escape(c)) {
            f.write_str(&rest[..at])?;
            match c {
                '\t' => f.write_str("\\t")?,
                '\n' => f.write_str("\\n")?,
                '\r' => f.write_str("\\r")?,
                c if c.is_ascii() => write!(f, "\\x{:02x}", u32::from(c))?,
                c => write!(f, "\\u{{{:x}}}", u32::from(c))?,
            }
            rest = &rest[at + c.len_utf8()..];
        }
        f.write_str(rest)
    }
}

/// JSON text with the characters of [`needs_escape`] made harmless, keeping its value:
/// U+0000–U+001F (in valid JSON only whitespace between tokens) become spaces, the others
/// (in valid JSON only inside strings) JSON escapes `\uNNNN`. Borrowed when there is none.
///
/// Meant for valid JSON, such as a record passed on verbatim; any other text is still
/// made harmless, though it may then read differently.
///
/// # Examples
///
/// ```
/// use glrmon_wire::text::escape_json;
///
/// let json = "{\"channel\":\"a\u{202e}b\",\r\n\"k\":1}";
/// assert_eq!(escape_json(json), r#"{"channel":"a\u202eb",  "k":1}"#);
/// ```
#[must_use]
pub fn escape_json(s: &str) -> Cow<'_, str> {
    if !s.chars().any(needs_escape) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '\u{0}'..='\u{1f}' => out.push(' '),
            c if needs_escape(c) => {
                let _ = write!(out, "\\u{:04x}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn escaped(s: &str) -> String {
        let cow = escape_control(s);
        assert_eq!(
            Escaped(s).to_string(),
            cow,
            "the two forms differ for {s:?}"
        );
        cow.into_owned()
    }

    #[test]
    fn plain_and_ordinary_non_ascii_text_is_borrowed_unchanged() {
        for s in [
            "",
            "pump3",
            "glrmon/pump3/alarm",
            "field y[2] has 3 values",
            r"C:\data\run.mcap",
            "μ",
            "°C",
            "Ä",
            "Tank 1 füllstand 20 °C, σ = 0.5 μm",
            "東京 ポンプ",
            "עברית",
            "👨\u{200d}👩\u{200d}👧",
        ] {
            assert!(
                matches!(escape_control(s), Cow::Borrowed(b) if b == s),
                "{s:?} was changed"
            );
            assert_eq!(Escaped(s).to_string(), s);
            assert!(matches!(escape_json(s), Cow::Borrowed(b) if b == s));
        }
    }

    #[test]
    fn every_c0_control_and_del_is_a_visible_ascii_escape() {
        assert_eq!(escaped("a\tb"), r"a\tb");
        assert_eq!(escaped("a\nb"), r"a\nb");
        assert_eq!(escaped("a\rb"), r"a\rb");
        assert_eq!(escaped("\u{0}"), r"\x00");
        assert_eq!(escaped("\u{7}"), r"\x07");
        assert_eq!(escaped("\u{8}"), r"\x08");
        assert_eq!(escaped("\u{1b}"), r"\x1b");
        assert_eq!(escaped("\u{1f}"), r"\x1f");
        assert_eq!(escaped("\u{7f}"), r"\x7f");
        for b in (0u8..0x20).chain([0x7f]) {
            let out = escaped(&char::from(b).to_string());
            assert!(out.starts_with('\\'), "{b:#x} → {out:?}");
            assert!(
                out.chars().all(|c| c.is_ascii_graphic()),
                "{b:#x} → {out:?}"
            );
        }
    }

    #[test]
    fn every_c1_control_is_a_visible_unicode_escape() {
        assert_eq!(escaped("\u{80}"), r"\u{80}");
        assert_eq!(escaped("\u{85}"), r"\u{85}");
        assert_eq!(escaped("\u{9b}2J"), r"\u{9b}2J");
        assert_eq!(escaped("\u{9f}"), r"\u{9f}");
        for c in '\u{80}'..='\u{9f}' {
            assert_eq!(
                escaped(&c.to_string()),
                format!("\\u{{{:x}}}", u32::from(c))
            );
        }
        assert_eq!(
            escaped("\u{a0}"),
            "\u{a0}",
            "NO-BREAK SPACE is ordinary text"
        );
    }

    #[test]
    fn bidi_controls_and_spoofing_format_characters_are_escaped() {
        for (c, text) in [
            ('\u{61c}', r"\u{61c}"),
            ('\u{200b}', r"\u{200b}"),
            ('\u{200e}', r"\u{200e}"),
            ('\u{200f}', r"\u{200f}"),
            ('\u{2028}', r"\u{2028}"),
            ('\u{2029}', r"\u{2029}"),
            ('\u{202a}', r"\u{202a}"),
            ('\u{202b}', r"\u{202b}"),
            ('\u{202c}', r"\u{202c}"),
            ('\u{202d}', r"\u{202d}"),
            ('\u{202e}', r"\u{202e}"),
            ('\u{2060}', r"\u{2060}"),
            ('\u{2066}', r"\u{2066}"),
            ('\u{2067}', r"\u{2067}"),
            ('\u{2068}', r"\u{2068}"),
            ('\u{2069}', r"\u{2069}"),
            ('\u{206f}', r"\u{206f}"),
            ('\u{feff}', r"\u{feff}"),
            ('\u{fffb}', r"\u{fffb}"),
        ] {
            assert!(needs_escape(c), "{c:?}");
            assert_eq!(escaped(&c.to_string()), text);
        }
        assert_eq!(escaped("lmx\u{202e}exe.txt"), r"lmx\u{202e}exe.txt");
    }

    #[test]
    fn terminal_attacks_come_out_as_one_printable_line() {
        let cases = [
            ("\u{1b}]0;pwned\u{7}", r"\x1b]0;pwned\x07"),
            ("\u{1b}[2J\u{1b}[H", r"\x1b[2J\x1b[H"),
            (
                "y\n2026-12-03T10:00:00.000Z  INFO ALARM pump3",
                r"y\n2026-12-03T10:00:00.000Z  INFO ALARM pump3",
            ),
            ("ok\rALARM", r"ok\rALARM"),
            ("°C\u{1b}[31mμ", r"°C\x1b[31mμ"),
        ];
        for (raw, text) in cases {
            let out = escaped(raw);
            assert_eq!(out, text);
            assert!(!out.chars().any(needs_escape), "{out:?}");
        }
    }

    #[test]
    fn escaping_twice_changes_nothing() {
        let once = escaped("a\u{1b}[2J\n\u{202e}\\x1b");
        assert_eq!(escaped(&once), once);
        assert!(matches!(escape_control(&once), Cow::Borrowed(_)));
    }

    #[test]
    fn json_text_keeps_its_value_without_raw_controls() {
        let raw = "{\"channel\":\"a\u{202e}\u{9b}2J\u{2028}\",\n\t\"k\":1}\r\n";
        let safe = escape_json(raw);
        assert!(!safe.chars().any(needs_escape), "{safe}");
        let a: serde_json::Value = serde_json::from_str(raw).unwrap();
        let b: serde_json::Value = serde_json::from_str(&safe).unwrap();
        assert_eq!(a, b);
        assert_eq!(safe, r#"{"channel":"a\u202e\u009b2J\u2028",  "k":1}  "#);
    }
}
